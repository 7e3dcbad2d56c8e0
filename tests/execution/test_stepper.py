"""The stepped execution (the browser UI's) takes the same steps as the blocking one."""

from __future__ import annotations

from pathlib import Path

import pytest

from dlovr.execution.executor import execute
from dlovr.execution.programs import load_program
from dlovr.execution.run import demo_track, resolve_scene
from dlovr.execution.stepper import SteppedExecution
from dlovr.sim import Simulator

ROOT = Path(__file__).resolve().parents[2]


@pytest.mark.slow
def test_stepped_execution_equals_the_blocking_one():
    program = load_program(ROOT / "recordings/programs/table.program.json")
    scene = resolve_scene(program, None)
    track = demo_track(program)
    plain = execute(program, Simulator(scene, track=True), track=track)
    sim = Simulator(scene, track=True)
    signals: list[float] = []
    run = SteppedExecution(program, sim, track=track)
    run.advance(0)
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
    assert max(signals) > 0.0  # the mirrored detectors show a signal
    detected = [r for r in got.runs if r.ended == "detected"]
    assert detected and all(r.peak_signal >= 1.0 for r in detected)


def test_a_cancelled_run_ends_without_a_result():
    program = load_program(ROOT / "recordings/programs/table.program.json")
    sim = Simulator(resolve_scene(program, None), track=True)
    run = SteppedExecution(program, sim)
    assert run.advance(20) == 20
    run.cancel()
    assert run.done and run.error == "cancelled" and run.execution is None
    assert run.advance(5) == 0
