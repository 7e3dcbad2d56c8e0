"""`dlovr transitions FILE [--json] [--facts F] [--hold S] [--flight S]`, untimed and timed input."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import pytest
from click.testing import CliRunner

from dlovr.cli import main

FIG11 = Path(__file__).parent / "data" / "fig11.txt"
FIG11_CLASSES = ["-", "E", "C", "-", "C", "C", "E", "I", "S,E", "E"]


def invoke(*args):
    return CliRunner().invoke(main, list(args))


def test_fig11_through_the_cli_table():
    r = invoke("transitions", str(FIG11))
    assert r.exit_code == 0, r.output
    rows = r.output.splitlines()[1:]
    assert [row.split()[1] for row in rows] == FIG11_CLASSES
    assert "V/VS[block.F2,holeB.F5,holeC.F7]" in rows[-1]


def test_fig11_through_the_cli_json():
    r = invoke("transitions", str(FIG11), "--json")
    assert r.exit_code == 0, r.output
    data = json.loads(r.output)
    assert [d["label"] for d in data] == FIG11_CLASSES
    assert data[8]["classes"] == ["S", "E"] and data[0]["classes"] == []
    assert data[1]["line"] == 3  # line numbers in the file (line 1 is a comment)


def test_malformed_line_names_the_line_and_exits_2_without_traceback(tmp_path):
    f = tmp_path / "bad.txt"
    f.write_text("# header\nV/G & E/N & V/N\n\nV/G & E/Q & V/N\n")
    r = subprocess.run([sys.executable, "-m", "dlovr", "transitions", str(f)], capture_output=True, text=True)
    assert r.returncode == 2
    assert f"{f}:4:" in r.stderr and "E/Q" in r.stderr
    assert "Traceback" not in r.stderr
    assert len(r.stderr.strip().splitlines()) == 1


def test_missing_and_empty_files(tmp_path):
    r = invoke("transitions", str(tmp_path / "nope.txt"))
    assert r.exit_code == 2 and "nope.txt: no such sequence file" in r.output
    f = tmp_path / "empty.txt"
    f.write_text("# nothing\n\n")
    r = invoke("transitions", str(f))
    assert r.exit_code == 2 and "no situations" in r.output


def test_topological_lines_need_facts_and_are_classified_with_them(tmp_path):
    seq = tmp_path / "topo.txt"
    seq.write_text(
        "VS/G & E5/N & VE/N\n"
        "VS/G & E5/N & E12/box.F1 & VE/N   # cable lies on the box\n"
        "VS/G & E5/N & E12/box.F1 & E15/(box.F1,box.F2) & VE/N\n"
        "VS/G & E5/N & E15/(box.F1,box.F2) & VE/N\n"
    )
    r = invoke("transitions", str(seq))
    assert r.exit_code == 2 and f"{seq}:1:" in r.output and "--facts" in r.output
    facts = tmp_path / "facts.json"
    facts.write_text(
        json.dumps(
            {
                "faces": {"box.F1": {"normal": [0, 0, 1]}, "box.F2": {"normal": [1, 0, 0]}},
                "pairs": [{"a": "box.F1", "b": "box.F2", "concave": False, "opening_deg": 270}],
                "dlo_vectors": {"15": [1, 0, 0]},
            }
        )
    )
    r = invoke("transitions", str(seq), "--facts", str(facts), "--json")
    assert r.exit_code == 0, r.output
    data = json.loads(r.output)
    assert [d["label"] for d in data] == ["-", "E", "-", "C"]
    assert data[3]["discrete"] == "V/G & E/N & E/E^P[box.F1,box.F2] & V/N"
    assert data[3]["topological"] == "VS/G & E5/N & E15/(box.F1,box.F2) & VE/N"


def test_bad_facts_file(tmp_path):
    seq = tmp_path / "topo.txt"
    seq.write_text("VS/G & E5/N & E15/(box.F1,box.F2) & VE/N\n")
    facts = tmp_path / "facts.json"
    facts.write_text("{not json")
    r = invoke("transitions", str(seq), "--facts", str(facts))
    assert r.exit_code == 2 and "not valid JSON" in r.output
    facts.write_text(json.dumps({"faces": {"box.F1": {"normal": [0, 0, 1]}}}))
    r = invoke("transitions", str(seq), "--facts", str(facts))
    assert r.exit_code == 2 and "box.F2" in r.output and f"{seq}:1:" in r.output


@pytest.mark.slow
def test_wrong_face_counts_and_situation_structure_are_refused(tmp_path):
    """One face for an edge, two for a vertex, no E contact between the ends: one line each, exit 2.
    (Five faces of two objects are a vertex on an edge, which simulations give: accepted; so are the
    states the model defines with several faces of one object, test_states_with_many_faces_of_one_object.)"""
    for line, message in (
        ("V/G & E/N & V/E^LS[a.F1]", "names at least 2 faces, got 1"),
        ("V/G & E/N & V/VS[a.F1,a.F2]", "names at least 3 faces, got 2"),
        ("V/G & V/N", "at least one E contact"),
    ):
        f = tmp_path / "seq.txt"
        f.write_text(f"V/G & E/N & V/N\n{line}\n")
        r = subprocess.run(
            [sys.executable, "-m", "dlovr", "transitions", str(f)], capture_output=True, text=True
        )
        assert r.returncode == 2, (line, r.stdout)
        assert f"{f}:2:" in r.stderr and message in r.stderr and "Traceback" not in r.stderr
        assert len(r.stderr.strip().splitlines()) == 1
    f = tmp_path / "seq.txt"
    f.write_text("V/G & E/N & V/N\nV/G & E/N & V/VI[block.F3,block.F5,hb.F2,hb.F11,hb.F4]\n")
    r = subprocess.run([sys.executable, "-m", "dlovr", "transitions", str(f)], capture_output=True, text=True)
    assert r.returncode == 0, r.stderr


@pytest.mark.slow
def test_wrong_typed_facts_files_give_one_line_naming_the_key(tmp_path):
    seq = tmp_path / "topo.txt"
    seq.write_text("VS/G & E5/N & E15/(box.F1,box.F2) & VE/N\n")
    facts = tmp_path / "facts.json"
    good_faces = {"box.F1": {"normal": [0, 0, 1]}, "box.F2": {"normal": [1, 0, 0]}}
    pair = {"a": "box.F1", "b": "box.F2", "concave": "no", "opening_deg": 270}
    for raw, where in (
        ([1, 2], "must be a JSON object"),
        ({"faces": ["box.F1"]}, "faces:"),
        ({"faces": {"box.F1": {"normal": "up"}}}, "faces.box.F1.normal"),
        ({"faces": {"box.F1": {"normal": [0, 0]}}}, "faces.box.F1.normal"),
        ({"faces": good_faces, "pairs": {"a": "box.F1"}}, "pairs:"),
        ({"faces": good_faces, "pairs": [pair]}, "pairs[0].concave"),
        ({"faces": good_faces, "dlo_vectors": {"x": [1, 0, 0]}}, "dlo_vectors"),
    ):
        facts.write_text(json.dumps(raw))
        r = subprocess.run(
            [sys.executable, "-m", "dlovr", "transitions", str(seq), "--facts", str(facts)],
            capture_output=True,
            text=True,
        )
        assert r.returncode == 2, (raw, r.stdout)
        assert f"{facts}: {where}" in r.stderr, (raw, r.stderr)
        assert "Error(" not in r.stderr and "Traceback" not in r.stderr
        assert len(r.stderr.strip().splitlines()) == 1


# --------------------------------------------------------------------------------------------------
# Timed input: debounced before it is classified
# --------------------------------------------------------------------------------------------------

RIDGE = "V/G & E/N & V/E^LI[a.F1,a.F2]"
FREE = "V/G & E/N & V/N"
LANDED = "V/G & E/N & V/F[a.F2]"
LYING = "V/G & E/N & E/F[a.F1] & V/N"


def timed(tmp_path, rows):
    f = tmp_path / "timed.txt"
    f.write_text("# time  situation\n" + "".join(f"{t}  {s}\n" for t, s in rows))
    return f


def test_timed_lines_are_debounced_and_show_when_each_kept_situation_began(tmp_path):
    f = timed(
        tmp_path,
        [
            (0.0, FREE),
            (0.5, LYING),
            (0.6, LYING),
            (0.602, "V/G & E/N & E/E^LI[a.F1,a.F2] & V/N"),  # a 4 ms excursion through two states
            (0.604, "V/G & E/N & E/E^P[a.F1,a.F2] & V/N"),
            (0.606, LYING),
            (1.0, RIDGE),
            (1.2, FREE),  # a 0.1 s flight
            (1.3, LANDED),
            (2.0, LANDED),
        ],
    )
    r = invoke("transitions", str(f))
    assert r.exit_code == 0, r.output
    rows = [row.split() for row in r.output.splitlines()[1:]]
    expected = [("0.000", "-"), ("0.500", "E"), ("1.000", "I"), ("1.300", "S,E")]
    assert [(row[1], row[2]) for row in rows] == expected
    assert r.output.splitlines()[0].split()[:4] == ["step", "t", "[s]", "class"]
    data = json.loads(invoke("transitions", str(f), "--json").output)
    assert [(d["line"], d["t"], d["label"]) for d in data] == [
        (2, 0.0, "-"), (3, 0.5, "E"), (8, 1.0, "I"), (10, 1.3, "S,E"),
    ]
    assert data[3]["through_free"] and data[3]["duration"] == 0.7 and data[1]["duration"] == 0.5
    # with the hold and flight times given: the 2 ms excursion is kept, the flight is not one
    r = invoke("transitions", str(f), "--json", "--hold", "0.001", "--flight", "0.05")
    labels = [d["label"] for d in json.loads(r.output)]
    assert labels == ["-", "E", "I", "S", "C", "I", "S", "E"]


def test_timed_and_untimed_lines_do_not_mix_and_times_do_not_go_back(tmp_path):
    f = tmp_path / "mixed.txt"
    f.write_text(f"0.0  {FREE}\n{LYING}\n")
    r = invoke("transitions", str(f))
    assert r.exit_code == 2 and f"{f}:2:" in r.output and "every line starts with a time" in r.output
    f.write_text(f"{FREE}\n0.5  {LYING}\n")
    r = invoke("transitions", str(f))
    assert r.exit_code == 2 and f"{f}:2:" in r.output
    f.write_text(f"0.5  {FREE}\n0.2  {LYING}\n")
    r = invoke("transitions", str(f))
    assert r.exit_code == 2 and f"{f}:2:" in r.output and "before the previous" in r.output
    f.write_text(f"0.5  {FREE}\n1e999  {LYING}\n")
    assert invoke("transitions", str(f)).exit_code == 2
    f.write_text(f"{FREE}\n{LYING}\n")
    r = invoke("transitions", str(f), "--hold", "0.02")
    assert r.exit_code == 2 and "timed input" in r.output
    assert invoke("transitions", str(timed(tmp_path, [(0, FREE)])), "--hold", "-1").exit_code == 2


def test_untimed_input_is_not_debounced(tmp_path):
    f = tmp_path / "untimed.txt"
    f.write_text(f"{LYING}\nV/G & E/N & E/E^LI[a.F1,a.F2] & V/N\n{LYING}\n")
    r = invoke("transitions", str(f), "--json")
    assert [d["label"] for d in json.loads(r.output)] == ["-", "I", "S"]
    assert "t" not in json.loads(r.output)[0]


def classes_of(tmp_path, text, *args):
    """The class labels ``dlovr transitions`` prints for ``text`` (one situation a line)."""
    f = tmp_path / "seq.txt"
    f.write_text(text)
    r = invoke("transitions", str(f), "--json", *args)
    assert r.exit_code == 0, r.output
    return [d["label"] for d in json.loads(r.output)]


@pytest.mark.parametrize(
    "lines",
    [
        # a run that splits in two (an equal-state run appears), then merges again (one leaves)
        ["V/G & E/N & E/F[table.F1] & V/N",
         "V/G & E/N & E/F[table.F1] & E/N & E/F[table.F1] & V/N",
         "V/G & E/N & E/F[table.F1] & V/N"],
        # the same without face names
        ["V/G & E/N & E/F & V/N", "V/G & E/N & E/F & E/N & E/F & V/N", "V/G & E/N & E/F & V/N"],
    ],
)  # fmt: skip
def test_a_run_that_splits_or_merges_is_E(tmp_path, lines):
    """docs/model.md 4.2: a successional contact without a partner is matched with N, whatever the other
    runs hold (issue 27, item 1)."""
    assert classes_of(tmp_path, "\n".join(lines) + "\n") == ["-", "E", "E"]


def test_the_fallback_looks_at_the_whole_new_situation(tmp_path):
    """Without object names, E/F -> E/VS is E when the new situation holds E/E^LI anywhere, not only in
    the new successional contact (docs/model.md 4.1, the paper's own rule; issue 27, item 2)."""
    assert classes_of(
        tmp_path, "V/G & E/N & E/F & E/N & E/E^LI & V/N\nV/G & E/N & E/VS & E/N & E/E^LI & V/N\n"
    ) == ["-", "E"]
    assert classes_of(
        tmp_path, "V/G & E/N & E/F & E/N & E/F & V/N\nV/G & E/N & E/VS & E/N & E/F & V/N\n"
    ) == ["-", "C"]


def test_the_flight_flag_belongs_to_the_run_that_flew(tmp_path):
    """At a landing, another run's instable -> instable change is I, not S,E (issue 27, item 3)."""
    text = (
        "0.000  V/G & E/N & E/E^LI[box.F1,box.F2] & E/N & V/E^LI[crate.F1,crate.F2]\n"
        "0.100  V/G & E/N & E/E^LI[box.F1,box.F2] & E/N & V/N\n"
        "0.150  V/G & E/N & E/E^LI[box.F2,box.F3] & E/N & V/F[table.F1]\n"
        "0.400  V/G & E/N & E/E^LI[box.F2,box.F3] & E/N & V/F[table.F1]\n"
    )
    assert classes_of(tmp_path, text) == ["-", "S,I,E"]
    # the run that flew and landed on the same object, beside a ridge that did not change: S,E
    text = (
        "0.000  V/G & E/N & E/E^LI[box.F1,box.F2] & E/N & V/E^LI[crate.F1,crate.F2]\n"
        "0.100  V/G & E/N & E/E^LI[box.F1,box.F2] & E/N & V/N\n"
        "0.150  V/G & E/N & E/E^LI[box.F1,box.F2] & E/N & V/F[crate.F2]\n"
    )
    assert classes_of(tmp_path, text) == ["-", "S,E"]


def test_states_with_many_faces_of_one_object(tmp_path):
    """A pinch between two faces of one object, which the command prints itself from a topological
    line, and a vertex of five faces of one object are read (docs/model.md 3.1; issue 27, item 6)."""
    labels = classes_of(
        tmp_path,
        "V/G & E/N & V/N\n"
        "V/G & E/N & E/F[slot.F1,slot.F3] & V/N\n"
        "V/G & E/N & V/VI[pyr.F1,pyr.F2,pyr.F3,pyr.F4,pyr.F5]\n"
        "V/G & E/N & V/VS[pit.F1,pit.F2,pit.F3,pit.F4,pit.F5]\n"
        "V/G & E/N & E/E^LS[chan.F1,chan.F2,chan.F3] & V/N\n",
    )
    assert labels == ["-", "E", "E", "S,E", "E"]  # each on another object; the ridge's tip snaps off
    # what the command prints from a topological pinch reads back
    facts = tmp_path / "facts.json"
    facts.write_text(
        json.dumps({"faces": {"slot.F1": {"normal": [0, 0, 1]}, "slot.F3": {"normal": [0, 0, -1]}}})
    )
    f = tmp_path / "topo.txt"
    f.write_text("VS/G & E3/N & E8/slot.F1 + E8/slot.F3 & VE/N\n")
    r = invoke("transitions", str(f), "--facts", str(facts), "--json")
    assert r.exit_code == 0, r.output
    printed = json.loads(r.output)[0]["discrete"]
    assert printed == "V/G & E/N & E/F[slot.F1,slot.F3] & V/N"
    f.write_text(printed + "\n")
    assert invoke("transitions", str(f)).exit_code == 0


def test_internal_faces_are_dropped_then_neighbours_contracted(tmp_path):
    """A contact whose faces are all internal is N, and an N beside it is one contact with it
    (issue 27, item 7); an internal face beside a real one leaves the real one."""
    facts = tmp_path / "facts.json"
    facts.write_text(json.dumps({"faces": {
        "box.F1": {"normal": [0, 0, 1]}, "box.F9": {"normal": [1, 0, 0], "internal": True}
    }}))  # fmt: skip
    f = tmp_path / "topo.txt"
    f.write_text(
        "VS/G & E3/N & E8/box.F9 & VE/N\n"
        "VS/G & E3/N & E8/box.F1 & E10/box.F9 & VE/N\n"
        "VS/G & E3/N & E8/box.F1 + E8/box.F9 & E10/box.F1 & E12/N & VE/N\n"
    )
    r = invoke("transitions", str(f), "--facts", str(facts), "--json")
    assert r.exit_code == 0, r.output
    got = [(d["discrete"], d["label"]) for d in json.loads(r.output)]
    assert got == [
        ("V/G & E/N & V/N", "-"),
        ("V/G & E/N & E/F[box.F1] & E/N & V/N", "E"),
        ("V/G & E/N & E/F[box.F1] & E/N & V/N", "-"),
    ]


def test_fig11_step6_tip_on_the_side_face_is_one_more_C(tmp_path):
    """docs/model.md 4.4: after E/F on the side face, leaning further until the tip points into it gives
    Fig. 11's V/F, one more C step (the topological lines show the end-vertex rule deciding)."""
    facts = tmp_path / "facts.json"
    facts.write_text(
        json.dumps(
            {
                "faces": {"block.F1": {"normal": [0, 0, 1]}, "block.F3": {"normal": [1, 0, 0]}},
                "pairs": [{"a": "block.F1", "b": "block.F3", "concave": False, "opening_deg": 270}],
                "dlo_vectors": {"9": [1, 0, -1]},
            }
        )
    )
    f = tmp_path / "lean.txt"
    f.write_text(
        "VS/G & E4/N & E9/(block.F1,block.F3) & VE/N\n"  # turned about the edge
        "VS/G & E4/N & E12/block.F3 & VE/N\n"  # hanging along the side face, the last segment on it
        "VS/G & E4/N & VE/block.F3\n"  # leaning further: the tip points into the face
    )
    r = invoke("transitions", str(f), "--facts", str(facts), "--json")
    assert r.exit_code == 0, r.output
    got = [(d["discrete"], d["label"]) for d in json.loads(r.output)]
    assert got == [
        ("V/G & E/N & E/E^P[block.F1,block.F3] & V/N", "-"),
        ("V/G & E/N & E/F[block.F3] & V/N", "C"),
        ("V/G & E/N & V/F[block.F3]", "C"),
    ]
