"""The execution engine stepped by its caller (the browser UI's way) takes the same steps as a run to
its end, with no thread: the same events, the same outcome."""

from __future__ import annotations

from pathlib import Path

import pytest

from dlovr.execution.engine import Engine, execute
from dlovr.execution.run import demo_track, resolve_scene
from dlovr.model.program import Program
from dlovr.sim import Simulator

ROOT = Path(__file__).resolve().parents[2]


@pytest.mark.slow
def test_stepped_execution_equals_the_blocking_one():
    program = Program.load(ROOT / "recordings/programs/table.program.json")
    scene = resolve_scene(program, None)
    track = demo_track(program)
    plain = execute(program, Simulator(scene, track=True), track=track)
    sim = Simulator(scene, track=True)
    signals: list[float] = []
    run = Engine(program, sim, track=track, scene=scene)
    run.start()
    assert run.advance(0) == 0 and not run.done
    steps, chunks = 0, 0
    while not run.done:
        steps += run.advance(7)
        signals.append(run.signal)
        chunks += 1
    assert run.error is None and run.execution is not None
    got = run.execution
    assert steps == plain.events[-1].step == got.events[-1].step
    assert [e.payload() for e in got.events] == [e.payload() for e in plain.events]
    assert [(r.ended, r.detected_at) for r in got.runs] == [(r.ended, r.detected_at) for r in plain.runs]
    assert chunks >= steps // 7
    assert max(signals) > 0.0  # the running macro's detectors show a signal
    detected = [r for r in got.runs if r.ended == "detected"]
    assert detected and all(r.peak_signal >= 1.0 for r in detected)
    assert run.result().success == plain_success(plain, scene.name)


def plain_success(ex, scene_name: str) -> bool:
    from dlovr.execution.scoring import score

    return score(ex, scene_name).success


def test_a_cancelled_run_ends_without_a_result():
    program = Program.load(ROOT / "recordings/programs/table.program.json")
    sim = Simulator(resolve_scene(program, None), track=True)
    run = Engine(program, sim)
    assert run.advance(20) == 20
    run.cancel()
    assert run.done and run.error == "cancelled" and run.execution is None
    assert run.advance(5) == 0
