"""The parts of issue 28's executor that need no simulation: macros in the frame of the objects
they touch (registered runs), the first macro whose outcome differed from the plan, the sensed goal
check, and the executor's assumption about its sensor."""

from __future__ import annotations

import json
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

from dlovr.execution.executor import (
    GOAL_ANGLE_DEG,
    DemoTrack,
    ExecOptions,
    Guard,
    goal_check,
    macro_shift,
)
from dlovr.execution.motion import (
    HAND_GIVE_WAY_M,
    ScrewPath,
    ShiftedPath,
    eased,
    give_way_m,
    given_way,
    slid_face_normal,
)
from dlovr.execution.scoring import MacroScore, first_deviation
from dlovr.execution.variation import object_shifts, parse_varies, perturb
from dlovr.model.program import Program
from dlovr.scene import load_scene

ROOT = Path(__file__).resolve().parents[2]
PEG = Program.load(ROOT / "recordings/programs/peg_in_hole.program.json")


def test_a_macro_moves_in_the_frame_of_the_objects_its_contacts_name():
    shifts = (("block", (0.01, 0.0, 0.0)), ("holeblock", (0.0, 0.02, 0.0)), ("table", (0.0, 0.0, 0.0)))
    opts = ExecOptions(object_shifts=shifts)
    first, groove = PEG.classed[0], PEG.classed[4]  # the tip on block.F1; landing on block.F3 + holeblock.F2
    assert macro_shift(first, opts) == pytest.approx((0.01, 0.0, 0.0))
    assert macro_shift(groove, opts) == pytest.approx((0.005, 0.01, 0.0))  # the mean of both objects
    assert macro_shift(first, ExecOptions()) is None  # blind: the world frame
    assert opts.registered and not ExecOptions().registered


def test_shifted_path_adds_the_shift_along_the_motion():
    base = ScrewPath((0.0, 0.0, 0.5), (1.0, 0.0, 0.0, 0.0), (0.0, 0.0, 0.0), (0.1, 0.0, 0.0))
    p = ShiftedPath(base, (0.0, 0.02, 0.0))
    assert p.at(0.0)[0].tolist() == pytest.approx([0.0, 0.0, 0.5])
    assert p.at(0.5)[0].tolist() == pytest.approx([0.05, 0.01, 0.5])
    assert p.at(1.5)[0].tolist() == pytest.approx([0.15, 0.02, 0.5])  # beyond: the whole shift
    assert eased((0.0, 0.0, 0.0), (1.0, 2.0, 0.0), 0.5) == pytest.approx((0.5, 1.0, 0.0))


def test_a_slide_along_a_face_into_a_new_contact_gives_way_from_that_face():
    """``give_way``: the ``E`` macro whose cable slides down block.F3 (contact vector -x) into the groove
    it makes with holeblock.F2 moves that far along F3's outward normal (+x) over its motion; no other
    macro of the program moves, and nothing at 0."""
    groove = PEG.classed[4]  # E/F[block.F3] -> V/E^LS[block.F3,holeblock.F2]
    assert slid_face_normal(groove) == pytest.approx((1.0, 0.0, 0.0))
    assert [m.index for m in PEG.macros if slid_face_normal(m) is not None] == [groove.index]
    base = ScrewPath((0.0, 0.0, 0.5), (1.0, 0.0, 0.0, 0.0), (0.0, 0.0, 0.0), (0.0, 0.0, -0.1))
    moved = given_way(base, groove, 0.01)
    assert moved.at(0.0)[0].tolist() == pytest.approx([0.0, 0.0, 0.5])
    assert moved.at(1.0)[0].tolist() == pytest.approx([0.01, 0.0, 0.4])
    assert given_way(base, groove, 0.0) is base and given_way(base, PEG.classed[0], 0.01) is base
    with pytest.raises(ValueError, match="give_way"):
        ExecOptions(give_way=-0.01)


def test_a_hand_s_track_gives_way_by_default_a_script_s_does_not(monkeypatch):
    """``give_way`` None (the default): 5 mm where the run follows a hand's track (a program compiled
    smoothed), none where it follows a script's; a given value wins either way. The executor's
    macros get it from the track they follow, and trials report the value applied."""
    import dlovr.execution.executor as ex
    from dlovr.execution.run import load_track
    from dlovr.execution.trials import TrialSetup
    from dlovr.sim import Simulator

    assert ExecOptions().give_way is None and HAND_GIVE_WAY_M == 0.005
    assert give_way_m(None, True) == 0.005 and give_way_m(None, False) == 0.0
    assert give_way_m(0.0, True) == 0.0 and give_way_m(0.01, False) == 0.01
    scene, track = load_scene("peg_in_hole"), load_track(ROOT / "recordings/peg_in_hole.mcap")
    hand = replace(PEG, smoothing_s=0.1)
    for program, opts, use_track, want in (
        (hand, ExecOptions(), True, 0.005), (PEG, ExecOptions(), True, 0.0),
        (hand, ExecOptions(), False, 0.0), (hand, ExecOptions(give_way=0.002), True, 0.002),
    ):
        setup = TrialSetup(program=program, scene=scene, pieces=None, track=track, variations=(), seed=0,
                           opts=opts, use_track=use_track)
        assert setup.give_way == want
    import dlovr.execution.motion as motion

    seen: list[float] = []
    real = motion.given_way
    monkeypatch.setattr(motion, "given_way", lambda path, m, d: seen.append(d) or real(path, m, d))
    sim = Simulator(scene, track=True)
    said = []
    for by_hand, option in ((True, None), (False, None), (True, 0.0), (False, 0.01)):
        ses = ex.Session(sim, ExecOptions(give_way=option))
        next(ex.run_macro(PEG.classed[4], ses, replace(track, by_hand=by_hand)))
        said.append(ses.events[-1].text)
    assert seen == [0.005, 0.0, 0.0, 0.01]
    # the macro's event says so (the browser's log, the run's recording)
    assert said[0].endswith("(giving way 5 mm from the face it slides along)")
    assert "giving way" not in said[1] + said[2] and "giving way 10 mm" in said[3]


def test_a_hand_s_drag_into_an_instability_goes_on_for_a_longer_cable():
    """``dragged_on``: an ``I`` macro that drags (peg-in-hole's drag along the groove into its corner)
    and whose transition a force shows goes on along its net displacement by DRAG_PER_EXCESS times
    how much further the tip was felt than demonstrated, less what the hand dragged on after the
    transition; nothing for a shorter or the demonstrated cable, a margin the hand left, a motion
    under DRAG_MIN_M or another class; ``hand_path`` only on a hand's track, and the executor's event
    says so."""
    import dlovr.execution.executor as ex
    from dlovr.execution.motion import DRAG_MIN_M, DRAG_PER_EXCESS, dragged_on, hand_path
    from dlovr.execution.run import load_track
    from dlovr.model.margins import tip_drag, went_on
    from dlovr.sim import Simulator

    assert DRAG_PER_EXCESS == 0.4 and DRAG_MIN_M == 0.02
    drag = _felt(replace(PEG.classed[5], t=1.0))  # I: V/E^LS[...] -> V/VI[...], the corner, felt
    assert drag.classes == ("I",) and not tip_drag(drag)
    hand = _hand_drag(0.001)
    assert went_on(hand.t, hand.pos, 1.0, (0.0, -1.0, 0.0)) == pytest.approx(0.001)
    base = ScrewPath((0.0, 0.0, 0.5), (1.0, 0.0, 0.0, 0.0), (0.0, 0.0, 0.0), (0.0, -0.06, 0.0))
    on, why = dragged_on(base, drag, (0.0, 0.0, -0.01), hand)  # the tip 10 mm further: 4 mm less the 1 mm
    assert on.at(0.0)[0].tolist() == pytest.approx([0.0, 0.0, 0.5])
    assert on.at(1.0)[0].tolist() == pytest.approx([0.0, -0.063, 0.5])
    assert why == "the cable's tip is 10.0 mm further than demonstrated"
    short = ScrewPath((0.0, 0.0, 0.5), (1.0, 0.0, 0.0, 0.0), (0.0, 0.0, 0.0), (0.0, -0.01, 0.0))
    for path, tool, m in ((base, (0.0, 0.0, 0.01), drag), (base, (0.0, 0.0, 0.0), drag),
                          (base, (0.0, 0.0, -0.002), drag), (short, (0.0, 0.0, -0.01), drag),
                          (base, (0.0, 0.0, -0.01), replace(PEG.classed[4], t=1.0))):
        assert dragged_on(path, m, tool, hand) == (path, "")
    assert hand_path(base, drag, None, replace(hand, by_hand=False), (0.0, 0.0, -0.01)) == (base, "")
    moved, said = hand_path(base, drag, None, hand, (0.0, 0.0, -0.01))
    assert moved.at(1.0)[0][1] == pytest.approx(-0.063)
    assert said == " (dragging 3.0 mm further: the cable's tip is 10.0 mm further than demonstrated)"
    scene, track = load_scene("peg_in_hole"), load_track(ROOT / "recordings/peg_in_hole.mcap")
    ses = ex.Session(Simulator(scene, track=True), ExecOptions())
    ses.tool = (0.0, 0.0, -0.04)
    next(ex.run_macro(PEG.classed[5], ses, replace(track, by_hand=True)))
    assert "mm further: the cable's tip is 40.0 mm further than demonstrated)" in ses.events[-1].text


def test_a_hand_s_drag_of_the_tip_that_no_force_ends_goes_on_15_mm_past_its_transition():
    """Where no force shows the tip's transition (``tip_drag``: the scripted peg-in-hole's drag into
    the groove's corner, no signal), a hand's drag goes on DRAG_PAST_M past it at least, counting what
    the hand went on itself, whatever the cable's length; more for a cable longer by more than
    DRAG_PAST_M / DRAG_PER_EXCESS; nothing where the hand went on that far; a drag of the tip from
    DRAG_TIP_MIN_M on."""
    from dlovr.execution.motion import DRAG_PAST_M, DRAG_TIP_MIN_M, dragged_on, hand_path
    from dlovr.model.margins import tip_drag

    assert (DRAG_PAST_M, DRAG_TIP_MIN_M) == (0.015, 0.01)
    drag = replace(PEG.classed[5], t=1.0)
    assert tip_drag(drag)
    base = ScrewPath((0.0, 0.0, 0.5), (1.0, 0.0, 0.0, 0.0), (0.0, 0.0, 0.0), (0.0, -0.06, 0.0))
    for tool, y in (((0.0, 0.0, 0.01), -0.074), ((0.0, 0.0, 0.0), -0.074), ((0.0, 0.0, -0.01), -0.074),
                    ((0.0, 0.0, -0.05), -0.079)):  # 15 mm less the hand's 1; 0.4 x 50 mm less 1
        on, _ = dragged_on(base, drag, tool, _hand_drag(0.001))
        assert on.at(1.0)[0][1] == pytest.approx(y), tool
    assert dragged_on(base, drag, (0.0, 0.0, 0.0), _hand_drag(0.016)) == (base, "")
    moved, said = hand_path(base, drag, None, _hand_drag(0.0023), (0.0, 0.0, 0.0))
    assert moved.at(1.0)[0][1] == pytest.approx(-0.0727)
    assert said == (" (dragging 12.7 mm further: no force shows where the tip arrives, and the "
                    "demonstration went on 2.3 mm past it, not 15)")
    assert hand_path(base, drag, None, replace(_hand_drag(0.0), by_hand=False), (0.0, 0.0, 0.0)) == (base, "")
    # a drag shorter than DRAG_MIN_M and than DRAG_PAST_M but not than DRAG_TIP_MIN_M: drawn on where no
    # force shows it, not where one does; one shorter than DRAG_TIP_MIN_M is not
    short = ScrewPath((0.0, 0.0, 0.5), (1.0, 0.0, 0.0, 0.0), (0.0, 0.0, 0.0), (0.0, -0.0125, 0.0))
    on, _ = dragged_on(short, drag, (0.0, 0.0, 0.0), _hand_drag(0.001))
    assert on.at(1.0)[0][1] == pytest.approx(-0.0265)
    assert dragged_on(short, _felt(drag), (0.0, 0.0, -0.04), _hand_drag(0.001)) == (short, "")
    shorter = ScrewPath((0.0, 0.0, 0.5), (1.0, 0.0, 0.0, 0.0), (0.0, 0.0, 0.0), (0.0, -0.009, 0.0))
    assert dragged_on(shorter, drag, (0.0, 0.0, 0.0), _hand_drag(0.001)) == (shorter, "")


def _felt(m):
    """``m`` with a force signal for its transition (a step well above its threshold and noise)."""
    d = m.detection[0]
    return replace(m, detection=(replace(d, params={**d.params, "step_n": 0.2, "noise_n": 0.001}),))


def _hand_drag(on: float) -> DemoTrack:
    """A hand's track dragging 60 mm along -y to its transition at 1 s, then ``on`` m further."""
    q = np.tile([1.0, 0.0, 0.0, 0.0], (4, 1))
    ys = [0.0, -0.06, -0.06 - on, -0.06 - on]
    return DemoTrack(np.array([0.0, 1.0, 1.5, 3.0]), np.array([[0.0, y, 0.5] for y in ys]), q, by_hand=True)


def test_object_shifts_are_the_trials_true_object_positions():
    scene = load_scene("peg_in_hole")
    var = parse_varies(["objects.pos=0.015"], scene)
    moved, values = perturb(scene, var, 7, 3)
    shifts = dict(object_shifts(scene, moved))
    assert set(shifts) == {o.name for o in scene.objects}
    for d in shifts.values():
        assert d == pytest.approx(tuple(values["objects.pos"]))


def _score(index: int, outcome: str) -> MacroScore:
    return MacroScore(index, "E", "", 0.0, None, None, None, outcome, 0.0, 0.0)


def test_first_deviation_is_the_first_macro_off_the_plan():
    assert first_deviation([_score(1, "ok"), _score(2, "ok")]) is None
    assert first_deviation([_score(1, "ok"), _score(3, "by motion"), _score(2, "false")]) == 2
    assert first_deviation([_score(1, "ok"), _score(2, "not run")]) is None


def test_goal_check_compares_the_sensed_contact_vector_with_the_demonstrations():
    # measured on peg_in_hole (docs/programs.md): the demonstration's end, a run that reached the goal
    # (a stiffer cable pressing harder: another size, the same direction) and one that ended with the
    # tip on the hole block's top
    track = DemoTrack(np.zeros(1), np.zeros((1, 3)), np.array([[1.0, 0, 0, 0]]), (0.056, -0.070, 0.174),
                      free_force=(0.0, 0.0, -0.245))
    weight = (0.0, 0.0, -0.245)
    ok, angle = goal_check([0.072, -0.085, 0.292], track, 0.0, 100, weight)
    assert ok is True and angle < 1.0
    missed, angle = goal_check([0.211, -0.011, 0.320], track, 0.0, 100, weight)
    assert missed is False and angle > 2 * GOAL_ANGLE_DEG
    # the weight the robot knows of its payload: a heavier cable's larger weight is no contact force
    heavy = goal_check([0.056, -0.070, 0.174 - 0.05], track, 0.0, 100, (0.0, 0.0, -0.295))
    assert heavy[0] is True and heavy[1] == pytest.approx(0.0, abs=1e-9)
    assert goal_check([0.0, 0.0, -0.245], track, 0.0, 100)[0] is False  # hanging free: no contact at all
    # much noise on few samples widens the angle allowed
    assert goal_check([0.211, -0.011, 0.320], track, 5.0, 1, weight)[0] is True
    assert goal_check([0.0, 0.0, -0.4], replace(track, end_force=None), 0.0, 100) == (None, None)
    assert goal_check([0.0, 0.0, -0.4], replace(track, free_force=None), 0.0, 100) == (None, None)


def test_the_executor_sets_its_detectors_for_the_noise_it_assumes():
    touch = PEG.classed[0]
    quiet, noisy = Guard(touch, ExecOptions(), 500.0), Guard(touch, ExecOptions(noise=0.02), 500.0)
    assert quiet.detectors[0].smooth == 0.0 and noisy.detectors[0].smooth > 0.0
    told = Guard(touch, ExecOptions(noise=0.02, sensor_noise=0.0), 500.0)
    assert told.detectors[0].smooth == 0.0  # a sensor said to be clean: the program's own parameters
    assert Guard(PEG.classed[4], ExecOptions(noise=0.2), 500.0).weak  # too noisy: ends by its motion


# -- short simulations (the 0.9 s touch demonstration of conftest.py) --------------------------------


@pytest.mark.slow
def test_a_gripper_started_elsewhere_goes_to_the_programs_start_and_a_registered_run_follows_the_table(
    touch,
):
    from dlovr.execution.run import run_program
    from dlovr.execution.variation import object_shifts

    program, scene, track, pieces = touch
    moved = replace(scene, gripper=replace(scene.gripper, pos=tuple(
        x + d for x, d in zip(scene.gripper.pos, (0.003, -0.002, 0.002), strict=True))))
    events: list = []
    res = run_program(program, moved, ExecOptions(), track=track, pieces=pieces, on_event=events.append)
    assert res.success and any("to the program's start pose" in e.text for e in events)
    lowered = replace(scene, objects=tuple(replace(o, pos=(o.pos[0], o.pos[1], o.pos[2] - 0.01))
                                           for o in scene.objects))
    opts = ExecOptions(object_shifts=object_shifts(scene, lowered))
    events.clear()
    reg = run_program(program, lowered, opts, track=track, pieces=pieces, on_event=events.append)
    assert reg.success and reg.first_deviation is None
    assert any("to the program's start pose" in e.text for e in events)  # moved down with the table
    quiet = run_program(program, scene, ExecOptions(), track=track, pieces=pieces, on_event=events.append)
    assert quiet.success and quiet.goal_sensed is not None


def test_trials_count_how_the_goal_check_judged_the_runs():
    from dlovr.execution.trials import goal_check_counts

    def trial(reached: bool, sensed: bool | None) -> dict:
        return {"program": {"goal_reached": reached, "goal_sensed": sensed}}

    runs = [trial(True, True), trial(True, False), trial(False, False), trial(False, True),
            trial(False, None)]
    assert goal_check_counts(runs) == {"missed": 2, "caught": 1, "reached": 2, "doubted": 1}


def test_the_demonstrations_weight_is_sensed_only_where_its_cable_hung_free():
    from dlovr.execution.executor import _starts_free

    edges = Program.load(ROOT / "recordings/programs/edges.program.json")
    assert _starts_free(PEG) and not _starts_free(edges)  # edges starts lying on concave90.F1
    track = DemoTrack(np.zeros(1), np.zeros((1, 3)), np.array([[1.0, 0, 0, 0]]), (0.0, 0.0, -0.181),
                      free_force=(0.0, 0.0, -0.093))  # edges: its "free" force is not its weight
    ok, angle = goal_check([0.0, 0.0, -0.181], track, 0.0, 100, (0.0, 0.0, -0.196), (0.0, 0.0, -0.196))
    assert ok is True and angle == pytest.approx(0.0, abs=1e-6)


def _wrench(t_goal: float, t_end: float, turn_deg: float, share: float = 0.5):
    """A demonstration's wrench at 500 Hz: the cable's weight (1 N down) while it hangs free, then
    from ``t_goal`` on a contact pushing up by ``share`` N whose direction turns by ``turn_deg``
    (in x-z) steadily to its end direction at ``t_end``."""
    from dlovr.model.derivation import WrenchSeries

    t = np.arange(0.0, t_end + 1e-9, 0.002)
    f = np.tile([0.0, 0.0, -1.0], (len(t), 1))
    after = t >= t_goal
    a = np.radians(turn_deg * (t_end - t[after]) / (t_end - t_goal))
    f[after] += share * np.stack([np.sin(a), np.zeros(len(a)), np.cos(a)], axis=1)
    return WrenchSeries(t, f, np.zeros_like(f))


def test_the_goal_tolerance_is_how_far_the_demonstrations_own_contact_vector_turned_in_its_goal():
    from dlovr.model.derivation import GOAL_MIN_TOLERANCE_DEG, goal_tolerance_deg

    # turning 20 deg over 2 s: windows from 0.2 s after the entry to the end's, the 90th percentile
    tol = goal_tolerance_deg(_wrench(1.0, 3.0, 20.0), 1.0)
    assert tol is not None and 14.0 < tol < 17.0
    assert goal_tolerance_deg(_wrench(1.0, 3.0, 1.0), 1.0) == GOAL_MIN_TOLERANCE_DEG  # at least the floor
    assert goal_tolerance_deg(_wrench(1.0, 3.0, 20.0, share=0.001), 1.0) is None  # no contact at the end
    # each sample program carries its own; its nominal run is not doubted (docs/programs.md)
    tols = {n: Program.load(ROOT / f"recordings/programs/{n}.program.json").goal_tolerance_deg
            for n in ("table", "l_block", "edges", "corners", "peg_in_hole")}
    assert tols == {"table": None, "l_block": 22.2, "edges": 6.0, "corners": 6.0, "peg_in_hole": 6.0}


def test_the_goal_check_takes_the_programs_tolerance():
    track = DemoTrack(np.zeros(1), np.zeros((1, 3)), np.zeros((1, 4)), (0.0, 0.0, -0.5), (0.0, 0.0, -1.0))
    ten = [0.5 * np.sin(np.radians(10.0)), 0.0, -1.0 + 0.5 * np.cos(np.radians(10.0))]
    assert goal_check(ten, track, 0.0, 100)[0] is False  # 10 deg: beyond the default 6
    ok, angle = goal_check(ten, track, 0.0, 100, tolerance=22.2)
    assert ok and angle == pytest.approx(10.0)
    raw = json.loads(PEG.dumps())
    assert Program.from_json({**raw, "goal_tolerance_deg": 12.5}).goal_tolerance_deg == 12.5
    with pytest.raises(ValueError, match="goal_tolerance_deg: must be a number of degrees"):
        Program.from_json({**raw, "goal_tolerance_deg": -1})


def test_objects_turned_together_are_told_as_a_rigid_motion_per_object():
    from dlovr.execution.variation import object_turns
    from dlovr.transforms import quat_rotate

    scene = load_scene("peg_in_hole")
    (v,) = parse_varies(["objects.yaw=5"], scene)
    with pytest.raises(ValueError, match=r"angle bound in \[0, 45\] degrees"):
        parse_varies(["objects.yaw=50"], scene)
    turned, values = perturb(scene, (v,), 0, 3)
    deg = values["objects.yaw"]
    assert 0 < abs(deg) <= 5 and v.level(deg) == abs(deg)
    turns, shifts = dict(object_turns(scene, turned)), dict(object_shifts(scene, turned))
    assert set(turns) == {o.name for o in scene.objects}
    for before, after in zip(scene.objects, turned.objects, strict=True):
        r = np.asarray(turns[before.name])
        assert 2 * np.degrees(np.arctan2(r[3], r[0])) == pytest.approx(deg)  # about z
        moved = quat_rotate(r, np.asarray(before.pos)) + np.asarray(shifts[before.name])
        assert moved == pytest.approx(np.asarray(after.pos), abs=1e-12)  # p -> R p + t
    assert object_turns(scene, scene) == ()


def test_a_world_motion_turns_with_its_objects():
    from dlovr.execution.executor import expectation, macro_turn, turned
    from dlovr.execution.motion import TurnedPath
    from dlovr.transforms import quat_rotate

    yaw90 = (np.sqrt(0.5), 0.0, 0.0, np.sqrt(0.5))
    # a screw along +x while turning 0.2 rad about x; turned 90 deg about z: along +y, about y
    path = ScrewPath((0.1, 0.0, 0.5), (1.0, 0.0, 0.0, 0.0), (0.2, 0.0, 0.0), (0.02, 0.0, 0.0),
                     (1.0, 0.0, 0.0, 0.0), "world")
    turned_path = TurnedPath(path, yaw90, (0.1, 0.0, 0.5), (1.0, 0.0, 0.0, 0.0))
    p, q = turned_path.at(1.0)
    assert p == pytest.approx([0.1, 0.02, 0.5], abs=1e-12)
    assert q == pytest.approx([np.cos(0.1), 0.0, np.sin(0.1), 0.0], abs=1e-12)
    assert turned_path.at(0.0)[0] == pytest.approx([0.1, 0.0, 0.5], abs=1e-15)
    opts = ExecOptions(object_shifts=(("block", (0.0, 0.0, 0.0)),), object_turns=(("holeblock", yaw90),))
    first, groove = PEG.classed[0], PEG.classed[4]  # block; block + holeblock: half the turn
    assert macro_turn(first, opts) == pytest.approx((1.0, 0.0, 0.0, 0.0))
    half = macro_turn(groove, opts)
    assert half is not None and 2 * np.degrees(np.arctan2(half[3], half[0])) == pytest.approx(45.0)
    assert macro_turn(first, ExecOptions(object_shifts=opts.object_shifts)) is None
    exp = turned(expectation(groove), yaw90)
    (v,) = exp.established
    assert v == pytest.approx(quat_rotate(np.asarray(yaw90), np.asarray(groove.established[0].vector)))


@pytest.mark.slow
def test_a_registered_run_moves_in_the_frame_of_a_tilted_table(touch):
    """The table tilted 3 degrees about the x axis through the point under the gripper: registered,
    the program's start pose and its motion turn with the table, and the gripper ends where the
    nominal run ends, turned with it."""
    from dlovr.execution.run import run_program
    from dlovr.execution.variation import object_turns
    from dlovr.transforms import quat_mul, quat_rotate

    program, scene, track, pieces = touch
    a = np.radians(3.0) / 2
    r = np.array([np.cos(a), np.sin(a), 0.0, 0.0])
    tilted = replace(scene, objects=tuple(
        replace(o, pos=tuple(float(x) for x in quat_rotate(r, np.asarray(o.pos))),
                quat=tuple(float(x) for x in quat_mul(r, np.asarray(o.quat)))) for o in scene.objects))

    opts = ExecOptions(object_shifts=object_shifts(scene, tilted), object_turns=object_turns(scene, tilted))
    last: dict = {}

    def keep(rec):
        last["pos"], last["quat"] = np.asarray(rec.gripper_pos, float), np.asarray(rec.gripper_quat, float)

    nominal = run_program(program, scene, ExecOptions(), track=track, pieces=pieces, on_step=keep)
    p0, q0 = last["pos"], last["quat"]
    reg = run_program(program, tilted, opts, track=track, pieces=pieces, on_step=keep)
    assert nominal.success and reg.success and reg.goal_sensed
    assert last["pos"] == pytest.approx(quat_rotate(r, p0), abs=5e-4)
    assert abs(float(np.dot(last["quat"], quat_mul(r, q0)))) > np.cos(np.radians(0.25))
