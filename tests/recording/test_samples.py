"""The sample recordings in recordings/: exact replay, their checked-in programs, program contents."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from dlovr.model.program import program_schema, remove_chatter
from dlovr.model.transitions import kept_classes
from dlovr.recording import Recording, compile_recording, kept_states, replay
from dlovr.recording.compile import compile_inputs

ROOT = Path(__file__).resolve().parents[2] / "recordings"
SAMPLES = sorted(ROOT.glob("*.mcap"))


def test_there_are_samples_of_the_built_in_demonstrations():
    names = {p.stem for p in SAMPLES}
    assert {"table", "edges", "peg_in_hole", "l_block", "corners"} <= names
    for p in SAMPLES:
        assert p.stat().st_size < 8_000_000, f"{p.name} is too large for a sample"


def test_compile_warns_of_a_drag_that_stops_where_its_instability_comes(tmp_path, monkeypatch):
    """dlovr compile (its compile_one) warns where no force shows the end of a drag of the tip into
    an instability and the demonstration went on less than the objects' placement tolerance past it
    (dlovr.model.margins): the peg-in-hole script drags 10.2 mm on past the groove's corner (macro 6),
    enough for 5 mm, not for 2 cm. Not for a trembling hand's program, whose run drags on."""
    from dlovr.model import margins
    from dlovr.recording.compile import compile_one

    assert compile_one(str(ROOT / "peg_in_hole.mcap"), str(tmp_path)).warning is None
    monkeypatch.setattr(margins, "PLACEMENT_M", 0.02)
    got = compile_one(str(ROOT / "peg_in_hole.mcap"), str(tmp_path), force=True).warning
    assert got is not None and "macro 6 (10.2 mm)" in got and "drag on" in got, got
    # a trembling hand's program is run with its drag going on DRAG_PAST_M past: nothing to warn of
    from dataclasses import replace

    from dlovr.recording.compile import margin_note

    rec = Recording(ROOT / "peg_in_hole.mcap")
    steps, pos, _ = rec.commands()
    followed = (steps * rec.dt, pos)
    prog = compile_recording(ROOT / "peg_in_hole.mcap")
    assert margin_note(prog, followed) is not None
    assert margin_note(replace(prog, smoothing_s=0.1), followed) is None


@pytest.mark.slow
@pytest.mark.parametrize("path", SAMPLES, ids=[p.stem for p in SAMPLES])
def test_sample_replays_bit_exact(path):
    res = replay(path, verify=True)
    assert res.divergence is None, res.divergence
    assert not res.warnings


@pytest.mark.parametrize("path", SAMPLES, ids=[p.stem for p in SAMPLES])
def test_checked_in_program_equals_a_fresh_compile(path):
    prog = compile_recording(path)
    js = ROOT / "programs" / f"{path.stem}.program.json"
    txt = ROOT / "programs" / f"{path.stem}.program.txt"
    assert js.read_text() == prog.dumps(), (
        f"{js} is stale: recompile with dlovr compile recordings -o recordings/programs"
    )
    assert txt.read_text() == prog.listing()
    import jsonschema

    jsonschema.validate(json.loads(js.read_text()), program_schema())


@pytest.mark.parametrize("path", SAMPLES, ids=[p.stem for p in SAMPLES])
def test_program_holds_the_demonstrations_transitions_in_order(path):
    """One macro per classed transition of the kept situations, chatter removed (docs/model.md,
    section 6)."""
    rec = Recording(path)
    kept = remove_chatter(kept_states(rec), compile_inputs(rec)[0])
    expected = []
    for i, classes in enumerate(kept_classes(kept)):
        if classes:
            expected.append((classes, kept[i - 1].situation.format(), kept[i].situation.format()))
    prog = compile_recording(path)
    *transitions, final = prog.macros
    assert [(m.classes, m.from_situation, m.to_situation) for m in transitions] == expected
    assert final.kind == "final" and final.to_situation == kept[-1].situation.format()
    assert prog.summary["risky"] == sum(1 for c, _, _ in expected if {"S", "I"} & set(c))
    assert prog.summary["caution"] == sum(1 for c, _, _ in expected if "T" in c and not {"S", "I"} & set(c))


def test_peg_in_hole_program_tells_the_fig11_story_with_the_right_classes():
    """Paper Fig. 11, steps 2-10: one macro per classed transition, exactly these, then the final one."""
    prog = compile_recording(ROOT / "peg_in_hole.mcap")
    steps = [(m.label, m.to_situation.removeprefix("V/G & E/N & ")) for m in prog.macros]
    assert steps == [
        ("E", "V/F[block.F1]"),  # first contact with the block's top face: establishing
        ("C", "E/F[block.F1] & V/N"),  # laid down on it (the shallow tip stays a contact)
        ("C", "E/E^P[block.F1,block.F3] & E/N & V/N"),  # turned about the block's edge: stable transition
        ("C", "E/E^P[block.F1,block.F3] & E/F[block.F3] & E/N & V/N"),  # hanging down along the side face
        ("E", "V/E^LS[block.F3,holeblock.F2]"),  # slid down into the groove with the hole block
        ("I", "V/VI[block.F3,block.F5,holeblock.F2,holeblock.F11]"),  # onto the corner at the groove's end
        ("S,E", "V/E^LS[holeblock.F1,holeblock.F6]"),  # slips off: a flight into the hole
        ("E", "V/VS[block.F5,holeblock.F1,holeblock.F6]"),  # slid into the hole's corner
        ("end", "V/VS[block.F5,holeblock.F1,holeblock.F6]"),
    ], steps
    # the risky macros are exactly the corner: entering the instable corner and the flight off it
    assert [m.label for m in prog.macros if m.risky] == ["I", "S,E"]
