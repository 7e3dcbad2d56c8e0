"""`dlovr transitions FILE [--json] [--facts F]`."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

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
    assert r.exit_code == 2 and "cannot read" in r.output
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


def test_wrong_face_counts_and_situation_structure_are_refused(tmp_path):
    """One face for an edge, five for a vertex, no E contact between the ends: one line each, exit 2."""
    for line, message in (
        ("V/G & E/N & V/E^LS[a.F1]", "names 2 to 4 faces, got 1"),
        ("V/G & E/N & V/VS[a.F1,a.F2,a.F3,a.F4,a.F5]", "names 3 to 4 faces, got 5"),
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
    ):  # fmt: skip
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
