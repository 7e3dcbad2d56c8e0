"""Calibrating a program's detectors in simulation (dlovr.execution.calibration, docs/programs.md
"Calibrated detection")."""

from __future__ import annotations

import json
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

from dlovr.execution.calibration import (
    RunLog,
    Seen,
    calibrate,
    calibrated_macro,
    fires_at,
)
from dlovr.execution.executor import ExecOptions
from dlovr.model.margins import blind
from dlovr.model.program import Program


def _weak(program: Program) -> Program:
    """``program`` with its first macro's detection left without force signal (as a demonstration
    whose new situation held too briefly leaves it: ``step_n`` 0)."""
    m = program.classed[0]
    d = m.detection[0]
    texts = {**d.derivation, "step_n": "derived: none"}
    weak = replace(d, params={**d.params, "step_n": 0.0}, derivation=texts)
    return replace(program, macros=(replace(m, detection=(weak,)), *program.macros[1:]))


def _log(label: str, t_step: float, size: float, noise: float = 0.0, seen: bool = True) -> RunLog:
    """A run's log whose force steps by ``size`` N along +z (the table taking the cable's weight) at
    ``t_step`` (s), the macro having started at 0 with a 1 s stretch, the tracker seeing the
    transition at ``t_step``."""
    t = np.arange(0.0, 2.0, 0.002)
    rng = np.random.default_rng(0)
    f = np.zeros((len(t), 3))
    f[:, 2] = np.where(t >= t_step, size, 0.0) + noise * rng.standard_normal(len(t))
    s = Seen(0.0, 1.0, None, t_step, t_step + 0.5)
    return RunLog(label, list(t), list(f), list(np.zeros_like(f)), s if seen else None, "", s)


def test_a_macro_needs_calibration_only_without_force_signal(touch):
    program = touch[0]
    m = program.classed[0]
    assert not blind(m, ExecOptions().min_snr)
    assert blind(_weak(program).classed[0], ExecOptions().min_snr)
    assert not blind(program.macros[-1], ExecOptions().min_snr)  # the final motion


def test_calibration_combines_the_runs_and_says_so_per_parameter(touch):
    m = _weak(touch[0]).classed[0]
    logs = [_log("a", 0.8, 0.3), _log("b", 0.85, 0.2), _log("c", 0.9, 0.4)]
    new, why = calibrated_macro(m, logs, ExecOptions(), None, "three cables")
    assert new is not None, why
    p = new.detection[0].params
    assert p["step_n"] == pytest.approx(0.2, rel=0.05)  # the smallest step of the runs
    assert p["force_threshold_n"] == pytest.approx(0.08, rel=0.05)  # 40 % of it
    assert all(text.startswith("calibrated: ") for k, text in new.detection[0].derivation.items()
               if k in ("force_threshold_n", "step_n", "noise_n"))
    assert "3 runs in the demonstration's scene (three cables)" in new.detection[0].derivation["step_n"]


def test_calibration_keeps_the_demonstrations_detection_where_a_run_gives_no_usable_signal(touch):
    m = _weak(touch[0]).classed[0]
    unseen = [_log("a", 0.8, 0.3), _log("b", 0.8, 0.3, seen=False)]
    new, why = calibrated_macro(m, unseen, ExecOptions(), None, "")
    assert new is None and "saw the transition in 1 of 2 runs" in why
    noisy = [_log("a", 0.8, 0.3), _log("b", 0.8, 0.02, noise=0.01)]
    new, why = calibrated_macro(m, noisy, ExecOptions(), None, "")
    assert new is None and "no usable signal" in why


def test_a_calibrated_detector_is_replayed_on_each_runs_wrench(touch):
    m = _weak(touch[0]).classed[0]
    new, why = calibrated_macro(m, [_log("a", 0.8, 0.3), _log("b", 0.7, 0.3)], ExecOptions(), None, "")
    assert new is not None, why
    assert fires_at(new, _log("a", 0.8, 0.3), ExecOptions(), None) == pytest.approx(0.8, abs=0.02)
    # a run whose force steps 0.25 s before the tracker sees the transition: it fires there, early
    early = _log("early", 0.55, 0.3)
    assert early.seen is not None
    early = replace(early, seen=replace(early.seen, t=0.8))
    assert fires_at(new, early, ExecOptions(), None) == pytest.approx(0.55, abs=0.02)


def test_the_calibration_field_is_written_and_read_and_old_programs_load(touch):
    program = touch[0]
    assert "calibration" not in program.to_json()
    cal = replace(program, calibration="5 runs: none to calibrate")
    back = Program.from_json(json.loads(cal.dumps()))
    assert back.calibration == "5 runs: none to calibrate"
    assert "calibration: 5 runs" in cal.listing()


#: The cable held still (its start rings out), then lowered slowly onto the table (the ringing of
#: the set-off decays before the detector is armed) and pressed: one ``E``.
_HOLD_THEN_TOUCH = """scene = "table"

[[waypoints]]
pos = [0.0, 0.0, 0.7]
duration = 0.5

[[waypoints]]
pos = [0.0, 0.0, 0.607]
duration = 2.0
hold = 0.3
"""


@pytest.mark.slow
def test_a_macro_without_force_signal_is_calibrated_in_its_demonstrations_scene(tmp_path):
    from dlovr.execution.run import load_track
    from dlovr.recording import DemoRecorder, compile_recording
    from dlovr.scene import load_scene
    from dlovr.script import load_script
    from dlovr.sim import Simulator

    (tmp_path / "s.script.toml").write_text(_HOLD_THEN_TOUCH)
    scene = load_scene("table")
    sim = Simulator(scene, track=True)
    with DemoRecorder(tmp_path / "d.mcap", scene, sim, sim.tracker) as rec:
        for r in sim.run(load_script(tmp_path / "s.script.toml")):
            rec.step(r)
    weak = _weak(compile_recording(tmp_path / "d.mcap"))
    out = calibrate(weak, scene, load_track(tmp_path / "d.mcap"), sim.pieces,
                    variants=(("length", 0.95), ("length", 1.05)))
    assert out.calibration.startswith("3 runs per macro without force signal"), out.calibration
    assert "macro 1 E: E: steps" in out.calibration and out.calibration.endswith(": calibrated")
    d = out.classed[0].detection[0]
    assert d.params["step_n"] > d.params["force_threshold_n"] > 0
    assert d.derivation["force_threshold_n"].startswith("calibrated: 3 runs")
    assert not blind(out.classed[0], ExecOptions().min_snr)


def test_compile_calibrate_calibrates_each_program_before_it_is_written(tmp_path, monkeypatch):
    from click.testing import CliRunner

    import dlovr.execution.calibration as calibration
    from dlovr.cli import main

    seen = []

    def fake(program, recording):
        seen.append(recording.name)
        return replace(program, calibration="0 runs: none to calibrate")

    monkeypatch.setattr(calibration, "calibrate_recording", fake)
    sample = Path(__file__).resolve().parents[2] / "recordings" / "l_block.mcap"
    r = CliRunner().invoke(main, ["compile", str(sample), "-o", str(tmp_path), "--calibrate"])
    assert r.exit_code == 0, r.output
    assert seen == ["l_block.mcap"]
    prog = Program.load(tmp_path / "l_block.program.json")
    assert prog.calibration == "0 runs: none to calibrate"
    assert "calibration: 0 runs" in (tmp_path / "l_block.program.txt").read_text()
    # a calibrated program is not the plain one: compiling without --calibrate compiles again
    r = CliRunner().invoke(main, ["compile", str(sample), "-o", str(tmp_path)])
    assert r.exit_code == 0 and "skipped" not in r.output, r.output
    assert Program.load(tmp_path / "l_block.program.json").calibration == ""
