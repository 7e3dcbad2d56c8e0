"""Programs run in simulation: force-guarded macros reach the goal, beat the open-loop replay where the
scene moved, fail with their allowance when the transition never comes; ``dlovr run`` and its bad
inputs. Short simulations only: a 0.9 s demonstration on the table scene, recorded once."""

from __future__ import annotations

import json
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest
from click.testing import CliRunner

from dlovr.cli import main
from dlovr.execution.engine import execute
from dlovr.execution.executor import ExecOptions
from dlovr.execution.run import load_track, resolve_scene, run_openloop, run_program
from dlovr.execution.scoring import format_result, score
from dlovr.execution.trials import TrialSetup, run_trials, summarize, write_outputs
from dlovr.execution.variation import parse_vary
from dlovr.model.program import Program

ROOT = Path(__file__).resolve().parents[2]


def test_force_guarded_program_reaches_its_goal(touch):
    program, scene, track, pieces = touch
    res = run_program(program, scene, ExecOptions(detect="force"), track=track, pieces=pieces)
    assert res.success and res.goal_reached, res.reason
    (m,) = res.macros
    assert m.outcome == "ok" and m.detected_at is not None and m.true_at is not None
    assert 0.0 <= m.latency < 0.3
    text = format_result(res)
    assert "result: goal reached (V/F[table.F1])" in text and "ok" in text


@pytest.mark.slow
def test_program_beats_open_loop_where_the_table_moved(touch, tmp_path):
    """Trial 2 of seed 1 lowers the table by 7.5 mm: the replayed demonstration stops short of it,
    the guarded macro goes on until it feels the contact. (Found by running trials 0-11; pinned.)"""
    program, scene, track, pieces = touch
    vary = (parse_vary("objects.pos=0.02"),)
    setup = TrialSetup(program=program, scene=scene, pieces=pieces, track=track, variations=vary, seed=1,
                       opts=ExecOptions(), baseline=True)
    trials = run_trials(setup, 3)
    t2 = trials[2]
    assert t2["values"]["objects.pos"][2] < -0.007
    assert t2["program"]["success"] and t2["program"]["goal_reached"]
    assert not t2["openloop"]["goal_reached"], t2["openloop"]
    assert "is not the goal" in t2["openloop"]["reason"]
    summary = summarize(trials, setup)
    assert summary["program_success_rate"] == 1.0 and summary["program_only"] >= 1
    assert summary["false_detections"] == 0 and summary["median_latency_s"] is not None
    assert summary["give_way_m"] == 0.0  # the executor's options that move the program say so
    paths = write_outputs(tmp_path / "out", trials, summary)
    names = {p.name for p in paths}
    assert {"trial_000.json", "trial_002.json", "trials.csv", "summary.json", "plot.png"} <= names
    assert (tmp_path / "out" / "plot.png").read_bytes()[:4] == b"\x89PNG"
    rows = (tmp_path / "out" / "trials.csv").read_text().splitlines()
    assert len(rows) == 4 and rows[0].startswith("trial,objects.pos,program_success")
    assert json.loads((tmp_path / "out" / "summary.json").read_text())["trials"] == 3


def test_a_transition_that_never_comes_fails_with_its_allowance(touch):
    """The table 20 cm lower: the tip never reaches it within 1.5x the demonstrated 9 cm."""
    program, scene, track, pieces = touch
    down = tuple(replace(o, pos=(o.pos[0], o.pos[1], o.pos[2] - 0.2)) for o in scene.objects)
    low = replace(scene, objects=down)
    res = run_program(program, low, ExecOptions(), track=track, pieces=pieces)
    assert not res.success and res.failed_macro == 1
    (m,) = res.macros
    assert m.outcome == "no transition" and m.detected_at is None
    assert m.allowed == pytest.approx(1.5 * program.macros[0].motion.distance)
    assert m.moved == pytest.approx(m.allowed)
    assert f"allowance (1.5x the demonstrated motion: {m.allowed * 1000:.1f} mm)" in res.reason
    ol = run_openloop(program, low, track, pieces=pieces)
    assert not ol.goal_reached


def test_a_hands_macro_not_felt_within_its_allowance_goes_on(touch):
    """The same lowered table, the track a hand's: the macro goes on with the demonstrated motion
    (its outcome says so), and the goal judges the run."""
    program, scene, track, pieces = touch
    down = tuple(replace(o, pos=(o.pos[0], o.pos[1], o.pos[2] - 0.2)) for o in scene.objects)
    hand = replace(track, by_hand=True)
    res = run_program(program, replace(scene, objects=down), ExecOptions(), track=hand, pieces=pieces)
    (m,) = res.macros
    assert m.outcome == "went on" and m.ended == "went on" and m.detected_at is None
    assert res.failed_macro is None and not res.goal_reached and not res.success
    assert "is not the goal" in res.reason
    assert "went on: nothing was felt" in format_result(res)


def test_the_final_hold_lets_the_gripper_reach_the_last_commanded_pose(touch):
    """A track whose last 20 ms raise the gripper 4 cm (a hand's jerk as the recording stops): the
    gripper, which lags its target at 0.25 m/s, is still on its way when the final motion ends; the
    final hold lets it arrive, as the open-loop replay's does, instead of stopping it where it is."""
    program, scene, track, pieces = touch
    pos = np.array(track.pos, dtype=float)
    pos[track.t > track.t[-1] - 0.02, 2] += 0.04
    jerk = replace(track, pos=pos)
    seen = []
    res = run_program(program, scene, ExecOptions(), track=jerk, pieces=pieces, on_step=seen.append)
    assert res.macros[0].outcome == "ok"
    after = [r for r in seen if r.time > res.macros[0].detected_at]
    last = max(after, key=lambda r: r.target_pos[2])  # the final motion's top
    assert last.target_pos[2] - last.gripper_pos[2] > 0.03  # the gripper lagging it by 3 cm or more
    assert np.array_equal(seen[-1].gripper_pos, last.target_pos)  # and there at the end


def test_a_diverged_simulation_is_a_failed_result(touch, monkeypatch):
    from dlovr.sim import SimulationDiverged, Simulator

    program, scene, track, pieces = touch
    sim = Simulator(scene, track=True, pieces=pieces)
    real = sim.step

    def step(n=1):
        if sim.step_index >= 50:
            raise SimulationDiverged(sim.step_index + 1, sim.time, "NaN/inf in the state")
        return real(n)

    monkeypatch.setattr(sim, "step", step)
    res = score(execute(program, sim, ExecOptions(), track=track), scene.name)
    assert not res.success and res.failed_macro == 1
    assert "simulation diverged" in res.reason and res.macros[0].outcome == "diverged"


@pytest.mark.slow
def test_table_program_runs_to_its_goal_with_the_oracle():
    """The sample table program, each macro ended by the contact tracker: every transition of the
    demonstration comes again, and the cable ends in the air as demonstrated."""
    program = Program.load(ROOT / "recordings/programs/table.program.json")
    scene = resolve_scene(program, None)
    track = load_track(ROOT / "recordings/table.mcap")
    res = run_program(program, scene, ExecOptions(detect="oracle"), track=track)
    assert res.success, format_result(res)
    # (the demonstration's bounce off the table and back within 36 ms is chatter, no macro since the
    # compiler removes it; a macro whose transition came with no force signal may still run by motion)
    out = [m.outcome for m in res.macros]
    assert all(o in ("ok", "by motion") for o in out) and out.count("ok") >= len(out) - 2, out


@pytest.fixture(scope="module")
def peg():
    program = Program.load(ROOT / "recordings/programs/peg_in_hole.program.json")
    return program, resolve_scene(program, None), load_track(ROOT / "recordings/peg_in_hole.mcap")


@pytest.mark.slow
def test_peg_in_hole_program_runs_to_its_goal_with_the_oracle(peg):
    """Every macro of the Fig. 11 program ends by its transition. Macro 3's transition comes a little
    later than demonstrated, in the turn about the edge: the gripper must go on turning (the recorded
    motion at the end of its stretch), not along the stretch's net push, or the cable slides off the
    edge in macro 4."""
    program, scene, track = peg
    res = run_program(program, scene, ExecOptions(detect="oracle"), track=track)
    assert res.success, format_result(res)
    assert [m.outcome for m in res.macros] == ["ok"] * len(res.macros)


@pytest.mark.slow
def test_peg_in_hole_force_detection_waits_for_the_last_motion_phase(peg):
    """The wrench shakes when the gripper stops and sets off again earlier in a stretch (macro 5: a
    lean, a hold, then the slide into the groove): armed in the last phase, no false detection, and
    the first five transitions come as demonstrated (macro 3, a gradual lift-off within 8x the noise,
    ends by its motion)."""
    program, scene, track = peg
    res = run_program(program, scene, ExecOptions(detect="force"), track=track)
    out = [m.outcome for m in res.macros]
    assert "false" not in out and out[:5] == ["ok"] * 5, format_result(res)
    assert res.macros[4].detected_at is not None and 0.0 <= res.macros[4].latency < 0.1


@pytest.mark.slow
def test_a_longer_cable_is_turned_about_its_tip_where_it_was_felt(peg):
    """A 10 % longer cable touches the block 2.5 cm sooner. The first touch tells the executor where
    the tip is: the lay-down turns about it (not about the demonstrated tip, which would slide the
    real one over the block's edge) and the program reaches its goal."""
    program, scene, track = peg
    longer = replace(scene, dlo=replace(scene.dlo, length=scene.dlo.length * 1.1))
    res = run_program(program, longer, ExecOptions(detect="force"), track=track)
    assert res.success, format_result(res)


@pytest.mark.slow
def test_a_long_soft_cable_rests_in_the_corner_through_the_final_hold(peg):
    """Trial 12 of seed 0 (docs/programs.md): a 5.5 % longer cable, 0.67x as stiff, with 23 % more
    friction. Until detections were taken back by their demonstrated latency (2026-11-27) its tip
    landed in the hole 2 cm short of the corner and crept into it more than 0.3 s into the final hold
    (a 0.3 s hold failed it); now, with the gripper no longer left 1.2 mm low, it lands in the corner
    before the hold (as trials 22, 30, 37, 41 and 48, the other long, soft, high-friction draws, do).
    The program still holds its last pose FINAL_SETTLE_S before it is judged, as the open-loop replay
    does, and the tip rests in the goal through that hold."""
    from dlovr.execution.executor import FINAL_SETTLE_S, principal_states
    from dlovr.execution.variation import parse_varies, perturb

    program, base, track = peg
    vary = parse_varies(["dlo.length=10%", "dlo.young=0.5..2", "dlo.friction=30%", "objects.pos=0.005"], base)
    scene, values = perturb(base, vary, 0, 12)
    assert values["dlo.length"] == pytest.approx(1.0554, abs=1e-4)  # the pinned draw
    at_goal: list[tuple[float, bool]] = []

    def on_step(r):
        if r.state is not None:
            at_goal.append((r.time, principal_states(r.state.discrete) == program.goal))

    res = run_program(program, scene, ExecOptions(detect="force"), track=track, on_step=on_step)
    assert res.success, format_result(res)
    hold_from = res.sim_time - FINAL_SETTLE_S
    assert all(ok for t, ok in at_goal if t >= hold_from)
    assert run_openloop.__kwdefaults__["settle"] == FINAL_SETTLE_S


def test_force_and_noise_runs_are_deterministic(touch):
    program, scene, track, pieces = touch
    a = run_program(program, scene, ExecOptions(noise=0.02, seed=4), track=track, pieces=pieces)
    b = run_program(program, scene, ExecOptions(noise=0.02, seed=4), track=track, pieces=pieces)
    assert a.macros == b.macros and a.final_situation == b.final_situation


# -- the command line --------------------------------------------------------------------------------


def cli(*args):
    return CliRunner().invoke(main, [str(a) for a in args])


def test_cli_runs_a_program_and_exits_by_the_result(touch):
    program, *_ = touch
    r = cli("run", program.path, "--scene", "table", "--detect", "oracle")
    assert r.exit_code == 0, r.output
    assert "result: goal reached" in r.output and "expected" in r.output
    r = cli("run", program.path, "--scene", "table", "--allowance", "1", "--path", "program", "--json")
    data = json.loads(r.output)
    assert r.exit_code == (0 if data["success"] else 1)
    assert set(data) >= {"success", "goal_reached", "macros", "reason"}


@pytest.mark.parametrize(
    ("args", "message"),
    [
        (["recordings/programs/table.program.json", "--scene", "peg_in_hole"], "a program for another scene"),
        (["recordings/programs/peg_in_hole.program.json", "--scene", "table"], "a program for another scene"),
        (["MALFORMED"], "not valid JSON"),
        (["recordings/programs/nope.program.json"], "no such program file"),
        (["recordings/programs/table.program.json", "--trials", "2", "-o", "OUT", "--vary", "dlo.colour=3%"],
         "unknown key 'dlo.colour'"),
        (["recordings/programs/table.program.json", "--noise", "-1"], "--noise: must be >= 0"),
        (["recordings/programs/table.program.json", "--noise", "lots"], "not a number"),
        (["recordings/programs/table.program.json", "--trials", "0", "-o", "OUT"], "--trials: must be >= 1"),
        (["recordings/programs/table.program.json", "--trials", "2"], "needs -o DIR"),
        (["recordings/programs/table.program.json", "--vary", "dlo.length=10%"], "need --trials"),
        (["recordings/programs/table.program.json", "--allowance", "0.5"], "--allowance: must be >= 1"),
        (["recordings/programs/table.program.json", "--give-way", "-0.01"], "--give-way: must be >= 0"),
        (["recordings/programs/table.program.json", "--scene", "atlantis"], "no built-in scene"),
        (["recordings/programs/table.program.json", "--detect", "psychic"], "--detect: 'psychic' is not"),
        (["recordings/programs/table.program.json", "--workers", "two"], "--workers: 'two' is not an"),
    ],
)
def test_cli_bad_inputs_are_one_line_and_exit_2(args, message, tmp_path, monkeypatch):
    monkeypatch.chdir(ROOT)
    bad = tmp_path / "bad.program.json"
    bad.write_text("{ macros: [")
    args = [str(bad) if a == "MALFORMED" else str(tmp_path / "out") if a == "OUT" else a for a in args]
    r = cli("run", *args)
    assert r.exit_code == 2, r.output
    assert message in r.output
    assert len(r.output.strip().splitlines()) == 1, r.output


def test_pinned_trial_draws_stay_the_same():
    """The trial the comparison test relies on: seed 1, trial 2 lowers the table by 7.5 mm."""
    d = parse_vary("objects.pos=0.02").draw(1, 2)
    np.testing.assert_allclose(d, [0.017652, -0.004054, -0.007525], atol=1e-6)


def test_the_first_touch_takes_back_the_detectors_own_latency(peg):
    """The demonstration's own scene: the tip touches the block where it was demonstrated, and the
    detector fires some 40 ms later (the step's rise to its threshold), 1.2 mm further down. That delay
    is how late the same detector fires on the demonstration's wrench, not a longer cable: the
    executor takes it back, so the tip offset it learns is nil and the gripper goes back to the
    demonstrated contact (it was left 1.2 mm low for the whole run, which turned objects' groove then
    held the tip in: 4 of 50 trials of ``objects.yaw=10`` missed the goal that the replay reached)."""
    from dlovr.execution.engine import Engine
    from dlovr.execution.executor import demo_detection_lag, macro_period
    from dlovr.execution.run import fresh_simulator

    program, scene, track = peg
    first = program.classed[0]
    opts = ExecOptions()
    period = macro_period(first, opts, track)
    lag = demo_detection_lag(first, opts, track, period, 500.0, first.t - period)
    assert lag is not None and 0.02 < lag < 0.06
    sim, why = fresh_simulator(scene)
    assert sim is not None, why
    eng = Engine(program, sim, opts, track=track, scene=scene)
    while eng.macro < 2 and eng.step():
        pass
    ses = eng.session
    assert ses is not None and ses.tool_known
    detected = next(e.t for e in ses.events if e.kind == "detected")
    assert abs(detected - first.t - lag) < 0.006  # the run's own delay, as measured on the demonstration
    assert abs(ses.tool[2]) < 2e-4, ses.tool  # no tip offset (before: +1.2 mm)
    k = int(np.searchsorted(track.t, first.t))
    assert abs(float(sim.target_pos[2]) - float(track.pos[k, 2])) < 2e-4  # back at the demonstrated touch


def test_a_shared_geometry_makes_the_same_tracker_and_run(touch):
    """A trial's program and open-loop replay share the scene's geometry (built once,
    ``fresh_simulator(..., geometry)``): the tracker is configured as ``Simulator(scene, track=True)``
    configures its own, and the replay reaches the same steps and end as with a geometry of its own."""
    from dataclasses import fields

    from dlovr.execution.run import fresh_simulator
    from dlovr.geometry import SceneGeometry
    from dlovr.sim.tracker import ContactTracker

    program, scene, track, pieces = touch
    geometry = SceneGeometry.from_scene(scene, pieces=pieces)
    own, _ = fresh_simulator(scene, pieces)
    shared, _ = fresh_simulator(scene, pieces, geometry)
    assert own is not None and shared is not None and shared.tracker.geometry is geometry
    for f in fields(ContactTracker):
        if f.name != "geometry":
            assert getattr(shared.tracker, f.name) == getattr(own.tracker, f.name), f.name
    a = run_openloop(program, scene, track, pieces=pieces, settle=0.1)
    b = run_openloop(program, scene, track, pieces=pieces, settle=0.1, geometry=geometry)
    assert (a.final_situation, a.sim_time, a.goal_reached) == (b.final_situation, b.sim_time, b.goal_reached)


def test_the_demonstrations_detection_lag_is_measured_once_per_track(peg):
    """Trials in one process ask for the same macros' lags on the same track: the second asks
    the kept result (the same value), another seed too; another track measures again."""
    from dataclasses import replace as dc_replace

    import dlovr.execution.executor as ex

    program, _, track = peg
    first = program.classed[0]
    opts = ExecOptions()
    period = ex.macro_period(first, opts, track)
    args = (period, 500.0, first.t - period)
    measured = []
    real = ex.measured_demo_lag

    def counted(*a):
        measured.append(1)
        return real(*a)

    ex.measured_demo_lag = counted
    track = dc_replace(track)  # (another test may have asked for this one: a copy starts empty)
    try:
        lag = ex.demo_detection_lag(first, opts, track, *args)
        assert ex.demo_detection_lag(first, dc_replace(opts, seed=7), track, *args) == lag
        assert len(measured) == 1
        other = dc_replace(track)
        assert ex.demo_detection_lag(first, opts, other, *args) == lag and len(measured) == 2
        later = dc_replace(opts, blank=opts.blank + 0.01)
        assert ex.demo_detection_lag(first, later, other, *args) is not None
        assert len(measured) == 3
        assert ex.demo_detection_lag(first, opts, track, *args) == lag and len(measured) == 3  # each its own
    finally:
        ex.measured_demo_lag = real
