"""Shared fixtures of the execution tests."""

from __future__ import annotations

from pathlib import Path

import pytest

from dlovr.execution.run import load_track
from dlovr.model.program import Program

SCRIPT = Path(__file__).resolve().parents[1] / "data" / "touch_press.script.toml"


@pytest.fixture(scope="session")
def touch(tmp_path_factory):
    """A demonstration that lowers the cable onto the table (V/F), recorded and compiled once:
    (program, scene, recorded command track, convex pieces)."""
    from dlovr.recording import DemoRecorder, compile_recording
    from dlovr.scene import load_scene
    from dlovr.script import load_script
    from dlovr.sim import Simulator

    d = tmp_path_factory.mktemp("touch")
    scene = load_scene("table")
    sim = Simulator(scene, track=True)
    with DemoRecorder(d / "touch.mcap", scene, sim, sim.tracker) as rec:
        for r in sim.run(load_script(SCRIPT)):
            rec.step(r)
    prog = compile_recording(d / "touch.mcap")
    path = d / "touch.program.json"
    path.write_text(prog.dumps())
    program = Program.load(path)
    assert [m.label for m in program.classed] == ["E"] and program.goal == ("V/F[table.F1]",)
    return program, scene, load_track(d / "touch.mcap"), sim.pieces
