"""The pieces of program execution that need no simulation: the tolerant program reader, the guarded
motion's path, and the scene variation of the trials."""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np
import pytest

from dlovr.execution.executor import expectation
from dlovr.execution.motion import ScrewPath, TrackPath, last_start, local_twist
from dlovr.execution.run import find_recording
from dlovr.execution.variation import VaryError, parse_varies, parse_vary, perturb
from dlovr.model.program import Program, ProgramError
from dlovr.transforms import matrix_to_rotvec, quat_rotate, quat_to_matrix

ROOT = Path(__file__).resolve().parents[2]
PROGRAMS = sorted((ROOT / "recordings" / "programs").glob("*.program.json"))


# -- the program reader ------------------------------------------------------------------------------


@pytest.mark.parametrize("path", PROGRAMS, ids=lambda p: p.stem)
def test_reads_every_sample_program(path):
    p = Program.load(path)
    raw = json.loads(path.read_text())
    assert len(p.classed) == sum(1 for m in raw["macros"] if m["classes"]) and p.name == raw["name"]
    assert p.final is not None  # the compiler's final macro (kind final, no class)
    for m in p.classed:
        assert m.classes and m.detection and {d.cls for d in m.detection} == set(m.classes)
        assert m.released or m.established  # a classed transition changes some principal contact
    assert find_recording(p) == ROOT / "recordings" / raw["source"]


def test_reader_tolerates_new_fields_and_a_final_macro():
    raw = json.loads((ROOT / "recordings/programs/table.program.json").read_text())
    raw["future_field"] = {"anything": 1}
    raw["macros"][0]["risk"] = "none"
    raw["macros"][0]["detection"][0]["params"]["derived_from"] = "demo"  # non-numbers are skipped
    assert raw["macros"][-1]["kind"] == "final" and raw["macros"][-1]["classes"] == []
    p = Program.from_json(raw)
    assert len(p.classed) == len(raw["macros"]) - 1 and p.final is not None and p.final.final
    assert p.goal == ()  # the table demonstration ends with the cable in the air
    params = p.macros[0].detection[0].params
    assert {"force_threshold_n", "max_angle_deg"} <= set(params) and "derived_from" not in params
    assert p.macros[0].expected == "N -> V/F[table.F1]"
    assert p.objects == {"table"}


def test_a_pinch_is_read_with_its_zero_vector_and_axis_for_the_detector():
    """A pinch (docs/model.md): its zero vector is kept, and its axis reaches the E detector."""
    raw = json.loads((ROOT / "recordings/programs/table.program.json").read_text())
    first = raw["macros"][0]["to_contacts"][0]
    first.update(vector=[0.0, 0.0, 0.0], axis=[0.0, 0.0, 1.0])
    m = Program.from_json(raw).macros[0]
    assert m.established[0].vector == (0.0, 0.0, 0.0) and m.established[0].axis == (0.0, 0.0, 1.0)
    assert expectation(m).axes == ((0.0, 0.0, 1.0),)
    first.update(axis=[0.0, 0.0, 2.0])
    with pytest.raises(ProgramError, match=r"to_contacts\[0\].axis: must be a unit vector"):
        Program.from_json(raw, "p.json")


@pytest.mark.parametrize(
    ("mutate", "message"),
    [
        (lambda r: r.pop("macros"), "macros: missing"),
        (lambda r: r["macros"][0].pop("motion"), r"macros\[0\]\.motion: missing"),
        (lambda r: r["macros"][0]["motion"].update(world=[0, 0]), r"macros\[0\].motion.world"),
        (lambda r: r["macros"][1].update(classes=["X"]), r"macros\[1\].classes"),
        (lambda r: r["macros"][0]["motion"].update(duration=-1), "must not be negative"),
        (lambda r: r["macros"][0]["to_contacts"][0].update(vector=[0, 0, "x"]), "finite number"),
        (lambda r: r.update(version=7), "program format 7"),
    ],
)
def test_malformed_programs_are_one_line_errors(mutate, message):
    raw = json.loads((ROOT / "recordings/programs/table.program.json").read_text())
    mutate(raw)
    with pytest.raises(ProgramError, match=message) as ei:
        Program.from_json(raw, "p.json")
    assert "\n" not in str(ei.value) and str(ei.value).startswith("p.json")


def test_unreadable_program_files(tmp_path):
    bad = tmp_path / "bad.program.json"
    bad.write_text("{ not json")
    with pytest.raises(ProgramError, match="not valid JSON"):
        Program.load(bad)
    with pytest.raises(ProgramError, match="no such program file"):
        Program.load(tmp_path / "missing.json")
    bad.write_text("[]")
    with pytest.raises(ProgramError, match="not a program"):
        Program.load(bad)


# -- the guarded motion's path -----------------------------------------------------------------------


@pytest.mark.parametrize("frame", ["world", "relative"])
def test_screw_reaches_the_demonstrated_end_pose(frame):
    p = Program.load(ROOT / "recordings/programs/peg_in_hole.program.json")
    for m in p.classed:
        mo = m.motion
        path = ScrewPath(mo.start_pos, mo.start_quat, mo.rotation, mo.relative, mo.start_quat, frame)
        pos, quat = path.at(1.0)
        np.testing.assert_allclose(pos - np.array(mo.start_pos), mo.world, atol=1e-9)
        rel = quat_to_matrix(mo.start_quat).T @ quat_to_matrix(quat)
        np.testing.assert_allclose(matrix_to_rotvec(rel), mo.rotation, atol=1e-7)
        np.testing.assert_allclose(path.at(0.0)[0], mo.start_pos, atol=1e-12)


def test_a_turn_about_the_tip_keeps_the_tip_in_place():
    """A demonstrated 60 deg turn about the cable's tip (0.3 m below the gripper) is repeated as that
    turn: the tip stays put all along, it is no straight line."""
    ang = math.radians(60.0)
    tip_local = np.array([0.0, 0.0, -0.3])
    rot = (0.0, ang, 0.0)
    r = quat_to_matrix([math.cos(ang / 2), 0.0, math.sin(ang / 2), 0.0])
    disp = tuple(tip_local - r @ tip_local)  # gripper frame: the tip (fixed) minus where R puts it
    path = ScrewPath((0.1, 0.2, 0.5), (1.0, 0.0, 0.0, 0.0), rot, disp, (1.0, 0.0, 0.0, 0.0), "relative")
    for s in (0.0, 0.3, 0.7, 1.0, 1.5):
        pos, quat = path.at(s)
        tip = pos + quat_rotate(quat, tip_local)
        np.testing.assert_allclose(tip, [0.1, 0.2, 0.2], atol=1e-9)


def test_a_turn_about_the_tip_is_repeated_about_the_tip_felt_further_away():
    """The demonstrated turn about a tip 0.3 m below the gripper, with ``tool`` saying the tip is
    4 cm further (a longer cable): the gripper turns about the point 0.34 m below it instead, in both
    paths (screw and recorded track, within the stretch and beyond it)."""
    ang = math.radians(60.0)
    tip_demo, tool = np.array([0.0, 0.0, -0.3]), (0.0, 0.0, -0.04)
    r = quat_to_matrix([math.cos(ang / 2), 0.0, math.sin(ang / 2), 0.0])
    disp = tuple(tip_demo - r @ tip_demo)
    start = (0.1, 0.2, 0.5)
    one = (1.0, 0.0, 0.0, 0.0)
    screw = ScrewPath(start, one, (0.0, ang, 0.0), disp, one, "relative", tool)
    t = np.linspace(0.0, 1.0, 101)
    quats = np.array([[math.cos(a / 2), 0.0, math.sin(a / 2), 0.0] for a in ang * t])
    pos = np.array([np.array([0.0, 0.0, 1.0]) + tip_demo - quat_rotate(q, tip_demo) for q in quats])
    beyond = ((0.0, ang / 2, 0.0), tuple(tip_demo - quat_to_matrix(quats[50]) @ tip_demo))
    track = TrackPath(t, pos, quats, 0.0, 1.0, start, (1.0, 0.0, 0.0, 0.0), "world", beyond, tool)
    tip_now = np.array(start) + tip_demo + tool
    for path in (screw, track):
        for s in (0.0, 0.4, 1.0, 1.3):
            p, q = path.at(s)
            np.testing.assert_allclose(p + quat_rotate(q, tip_demo + tool), tip_now, atol=1e-9)
    # no tool, no change: the demonstrated pivot
    p, q = ScrewPath(start, one, (0.0, ang, 0.0), disp, one, "relative").at(1.0)
    np.testing.assert_allclose(p + quat_rotate(q, tip_demo), np.array(start) + tip_demo, atol=1e-9)


def test_the_tips_first_touch_gives_its_offset():
    """An approach along the cable felt 2 cm early: the tip is 2 cm further from the gripper; felt at
    1.25 of a 4 cm approach: 1 cm nearer. Only a tip touching from free space along the cable counts."""
    from dlovr.execution.motion import tip_offset, touches_tip

    path = ScrewPath((0.0, 0.0, 0.5), (1.0, 0.0, 0.0, 0.0), (0.0, 0.0, 0.0), (0.0, 0.0, -0.04))
    np.testing.assert_allclose(tip_offset(path, 0.5), (0.0, 0.0, -0.02), atol=1e-12)
    np.testing.assert_allclose(tip_offset(path, 1.25), (0.0, 0.0, 0.01), atol=1e-12)
    program = Program.load(ROOT / "recordings/programs/peg_in_hole.program.json")
    assert [touches_tip(m) for m in program.classed] == [True] + [False] * (len(program.classed) - 1)


def test_track_path_repeats_the_recorded_stretch_from_where_the_gripper_is():
    t = np.linspace(0.0, 1.0, 11)
    pos = np.stack([t * 0.1, np.zeros_like(t), 0.5 - 0.2 * t * t], axis=1)  # a curve, not a line
    quat = np.tile([1.0, 0.0, 0.0, 0.0], (11, 1))
    here = (1.0, 1.0, 1.0)
    beyond = ((0.0, 0.0, 0.0), (0.0, 0.0, -0.1))
    path = TrackPath(t, pos, quat, 0.2, 0.6, here, (1.0, 0.0, 0.0, 0.0), "world", beyond)
    np.testing.assert_allclose(path.at(0.0)[0], here)
    np.testing.assert_allclose(path.at(0.5)[0], np.array(here) + pos[4] - pos[2], atol=1e-12)
    np.testing.assert_allclose(path.at(1.0)[0], np.array(here) + pos[6] - pos[2], atol=1e-12)
    # beyond the demonstrated stretch: the macro's own motion goes on (a guarded approach keeps going)
    np.testing.assert_allclose(path.at(1.5)[0], path.at(1.0)[0] + [0.0, 0.0, -0.05], atol=1e-12)


def test_local_twist_is_the_motion_at_the_end_of_the_stretch():
    """A recorded push along +x, then a turn about an axis 0.1 m below the gripper (about y): beyond
    the stretch the gripper goes on turning about that axis, not along the stretch's net motion."""
    t = np.arange(0.0, 2.0001, 0.002)
    pos, quat = np.zeros((len(t), 3)), np.zeros((len(t), 4))
    for k, tk in enumerate(t):
        a = max(tk - 1.0, 0.0) * 0.5  # rad: still until 1 s of push, then 0.5 rad/s
        pos[k] = [0.05 * min(tk, 1.0) + 0.1 * math.sin(a), 0.0, 0.4 - 0.1 + 0.1 * math.cos(a)]
        quat[k] = [math.cos(a / 2), 0.0, math.sin(a / 2), 0.0]
    twist = local_twist(t, pos, quat, 0.0, 2.0, span=1.0)
    assert twist is not None
    rot, disp = twist
    np.testing.assert_allclose(rot, [0.0, 0.5, 0.0], atol=1e-9)
    # one second of that twist, applied to the pose at 2 s, lands where the turn goes on to
    end = ScrewPath(tuple(pos[-1]), tuple(quat[-1]), rot, disp, tuple(quat[-1]), "relative")
    p, q = end.at(1.0)
    a = 1.0
    np.testing.assert_allclose(p, [0.05 + 0.1 * math.sin(a), 0.0, 0.3 + 0.1 * math.cos(a)], atol=1e-9)
    np.testing.assert_allclose(q, [math.cos(a / 2), 0.0, math.sin(a / 2), 0.0], atol=1e-9)
    # held still at the end: the last motion before the hold; still throughout: none
    held = np.concatenate([pos, np.repeat(pos[-1:], 100, axis=0)])
    held_q = np.concatenate([quat, np.repeat(quat[-1:], 100, axis=0)])
    t2 = np.arange(len(held)) * 0.002
    np.testing.assert_allclose(local_twist(t2, held, held_q, 0.0, t2[-1], span=1.0)[0], rot, atol=1e-9)
    assert local_twist(t, np.zeros_like(pos), np.tile([1.0, 0, 0, 0], (len(t), 1)), 0.0, 2.0, 1.0) is None


def test_a_hands_macro_goes_on_beyond_its_stretch_with_its_net_motion():
    """docs/programs.md (the allowance): a hand's approach, 6 cm straight down in 3 s, ends turning
    (its drift: 0.1 rad in its last 0.1 s). Beyond the stretch a hand's program goes on with the
    stretch's net motion (down), not with its last 0.1 s carried over 3 s (3 rad of turning); a
    script's (not by hand) keeps the recorded motion at the end of the stretch."""
    from dlovr.execution.executor import DemoTrack, ExecOptions, _path

    t = np.arange(0.0, 3.0001, 0.01)
    pos = np.stack([np.zeros_like(t), np.zeros_like(t), 0.44 - 0.02 * t], axis=1)
    a = np.clip(t - 2.9, 0.0, None)  # rad, about x: the drift of the last 0.1 s
    quat = np.stack([np.cos(a / 2), np.sin(a / 2), np.zeros_like(t), np.zeros_like(t)], axis=1)
    m, sim = _approach(t, pos, quat)
    hand = _path(m, sim, ExecOptions(), DemoTrack(t, pos, quat, by_hand=True))
    (p1, q1), (p2, q2) = hand.at(1.0), hand.at(1.5)
    # 3 cm more down (in the gripper frame at the end, turned 0.1 rad)
    np.testing.assert_allclose(p2 - p1, 0.5 * (pos[-1] - pos[0]), atol=3e-3)
    assert abs(float(np.dot(q1, q2))) > math.cos(0.05 / 2 + 1e-3)  # and turned by 0.05 rad at most
    script = _path(m, sim, ExecOptions(), DemoTrack(t, pos, quat))
    assert abs(float(np.dot(script.at(1.0)[1], script.at(1.5)[1]))) < math.cos(1.0 / 2)  # 1.5 rad


def test_a_hands_macro_eases_into_its_net_motion_beyond_its_stretch():
    """docs/programs.md (the allowance): a hand slows as it feels the touch, 6 cm down in 3 s ending at
    8 mm/s where its net motion is 20 mm/s. Beyond the stretch its program's gripper goes on at the
    stretch's last velocity and reaches the net motion's over HAND_EASE_S, not within a step (a jolt
    the force detectors take for a touch); a script's goes on at once, as before."""
    from dlovr.execution.executor import DemoTrack, ExecOptions, _path
    from dlovr.execution.motion import HAND_EASE_S

    t = np.arange(0.0, 3.0001, 0.002)
    speed = np.interp(t, [0.0, 2.0, 3.0], [0.024, 0.024, 0.008])  # m/s, slowing toward the touch
    z = 0.44 - np.concatenate([[0.0], np.cumsum(0.5 * (speed[1:] + speed[:-1]) * np.diff(t))])
    pos = np.stack([np.zeros_like(t), np.zeros_like(t), z], axis=1)
    quat = np.tile([1.0, 0.0, 0.0, 0.0], (len(t), 1))
    m, sim = _approach(t, pos, quat)
    net = (z[-1] - z[0]) / 3.0  # m/s, -0.02

    def vz(path, s, ds=1e-4):  # the commanded velocity (m/s) at s: 3 s of demonstration per unit
        return (path.at(s + ds)[0][2] - path.at(s - ds)[0][2]) / (2 * ds) / 3.0

    hand = _path(m, sim, ExecOptions(), DemoTrack(t, pos, quat, by_hand=True))
    assert hand.ease == pytest.approx(HAND_EASE_S / 3.0)
    assert vz(hand, 1.0 - 1e-3) == pytest.approx(-0.008, abs=5e-4)
    assert vz(hand, 1.0 + 1e-3) == pytest.approx(-0.008, abs=5e-4)  # no jump at s = 1
    assert vz(hand, 1.0 + 0.5 * hand.ease) == pytest.approx(0.5 * (net - 0.008), abs=5e-4)  # half way
    assert vz(hand, 1.0 + hand.ease + 1e-3) == pytest.approx(net, abs=5e-4)  # the net motion's from then
    at_once = TrackPath(t, pos, quat, 0.0, 3.0, tuple(pos[0]), tuple(quat[0]), "world", hand.beyond)
    assert vz(at_once, 1.0 + 1e-3) == pytest.approx(net, abs=5e-4)  # without easing: the jump
    script = _path(m, sim, ExecOptions(), DemoTrack(t, pos, quat))
    assert script.ease == 0.0


def _approach(t: np.ndarray, pos: np.ndarray, quat: np.ndarray):
    """The first macro of a program whose demonstration (gripper ``pos``, ``quat`` at times ``t``)
    approaches the table until 3 s, when the tip touches it; and a stand-in simulator with the gripper
    at the demonstration's start (what ``_path`` reads)."""
    from types import SimpleNamespace

    from dlovr.model.discrete import parse_discrete_situation
    from dlovr.model.program import PoseTrack, TimedSituation, compile_program

    states = [TimedSituation(0.0, 3.0, parse_discrete_situation("V/G & E/N & V/N")),
              TimedSituation(3.0, 1.0, parse_discrete_situation("V/G & E/N & V/F[table.F1]"))]
    m = compile_program(states, PoseTrack(t, pos, quat)).classed[0]
    start = (tuple(pos[0]), tuple(quat[0]))
    sim = SimpleNamespace(built=SimpleNamespace(mocap_id=0), target_pos=start[0], target_quat=start[1],
                          data=SimpleNamespace(mocap_pos=[start[0]], mocap_quat=[start[1]]))
    return m, sim


def test_last_start_is_where_the_last_motion_phase_began():
    t = np.arange(0.0, 3.0001, 0.002)
    x = np.interp(t, [0.0, 1.0, 1.5, 2.5, 3.0], [0.0, 0.1, 0.1, 0.2, 0.2])  # move, hold, move, hold
    pos = np.stack([x, np.zeros_like(t), np.zeros_like(t)], axis=1)
    quat = np.tile([1.0, 0.0, 0.0, 0.0], (len(t), 1))
    assert last_start(t, pos, quat, 0.0, 2.4) == pytest.approx(1.5, abs=0.003)
    assert last_start(t, pos, quat, 0.0, 3.0) == pytest.approx(1.5, abs=0.003)  # held at the end
    assert last_start(t, pos, quat, 0.0, 0.9) == 0.0  # no hold before: the stretch's start
    assert last_start(t, pos, quat, 1.7, 2.4) == 1.7
    jitter = pos.copy()
    jitter[(t > 1.0) & (t < 1.5), 0] += 1e-7 * np.sin(np.arange(((t > 1.0) & (t < 1.5)).sum()))
    assert last_start(t, jitter, quat, 0.0, 2.4) == pytest.approx(1.5, abs=0.003)  # a still hand


# -- variation ---------------------------------------------------------------------------------------


def test_vary_specs():
    v = parse_vary("dlo.length=10%")
    assert (v.kind, v.lo, v.hi) == ("relative", 0.9, 1.1)
    v = parse_vary("dlo.young=0.5..2")
    assert (v.kind, v.lo, v.hi) == ("range", 0.5, 2.0)
    v = parse_vary("objects.pos=0.005")
    assert (v.kind, v.hi) == ("offset", 0.005)
    for k in range(20):
        friction, young = parse_vary("dlo.friction=10%").draw(3, k), parse_vary("dlo.young=0.5..2").draw(3, k)
        offset = parse_vary("gripper.pos=0.005").draw(3, k)
        assert isinstance(friction, float) and isinstance(young, float) and isinstance(offset, tuple)
        assert 0.9 <= friction <= 1.1 and 0.5 <= young <= 2.0
        assert max(map(abs, offset)) <= 0.005


@pytest.mark.parametrize(
    ("item", "message"),
    [
        ("dlo.colour=10%", "unknown key 'dlo.colour'"),
        ("speed=2", "unknown key"),
        ("dlo.length", "expected KEY=SPEC"),
        ("dlo.length=0.005", "relative change"),
        ("objects.pos=10%", "absolute offset in metres"),
        ("dlo.young=2..0.5", "0 < A <= B"),
        ("dlo.length=abc", "bad spec"),
        ("objects.pos=1", r"\[0, 0.1\] m"),
    ],
)
def test_bad_vary_items_are_one_line_errors(item, message):
    with pytest.raises(VaryError, match=message) as ei:
        parse_vary(item)
    assert "\n" not in str(ei.value)


def test_variation_is_deterministic_and_keys_are_independent():
    from dlovr.scene import load_scene

    scene = load_scene("peg_in_hole")
    a = [parse_vary("dlo.length=10%"), parse_vary("objects.pos=0.005")]
    s1, v1 = perturb(scene, a, seed=5, trial=3)
    s2, v2 = perturb(scene, a, seed=5, trial=3)
    assert v1 == v2 and s1 == s2
    _, v3 = perturb(scene, [a[1]], seed=5, trial=3)
    assert v3["objects.pos"] == v1["objects.pos"]  # adding a key does not change the others' draws
    _, v4 = perturb(scene, a, seed=5, trial=4)
    assert v4 != v1
    assert s1.dlo.length == pytest.approx(scene.dlo.length * v1["dlo.length"])
    shift = np.array(v1["objects.pos"])
    for o, o1 in zip(scene.objects, s1.objects, strict=True):
        np.testing.assert_allclose(np.array(o1.pos) - o.pos, shift)  # the objects move together
    one, _ = perturb(scene, [parse_vary("objects.holeblock.pos=0.005", scene)], seed=1, trial=0)
    assert one.object("block").pos == scene.object("block").pos
    assert one.object("holeblock").pos != scene.object("holeblock").pos
    with pytest.raises(VaryError, match="no object 'nope'"):
        parse_vary("objects.nope.pos=0.005", scene)


def test_bounces_and_weak_detections_end_by_motion():
    """A transition undone by the next within 0.1 s of demonstrated motion is a bounce; a detection
    whose threshold is not below the demonstrated step, or whose step is within a few times the
    noise before it, has no force signal to watch."""
    from dataclasses import replace

    from dlovr.execution.executor import bounces
    from dlovr.model.detection import no_force_signal as _weak
    prog = Program.load(ROOT / "recordings" / "programs" / "table.program.json")
    ms = list(prog.classed)
    assert len(ms) >= 2
    a, b = ms[0], ms[1]
    back = replace(b, from_contacts=a.to_contacts, to_contacts=a.from_contacts,
                   motion=replace(b.motion, duration=0.05))
    assert bounces([a, back], 0.1) == {a.index, back.index}
    assert bounces([a, replace(back, motion=replace(b.motion, duration=0.5))], 0.1) == set()
    assert _weak("E", {"force_threshold_n": 0.07, "step_n": 0.06})
    assert not _weak("E", {"force_threshold_n": 0.03, "step_n": 0.06})
    # a step within 8x the noise before it (a gradual change) is not trusted either
    assert _weak("C", {"force_threshold_n": 0.02, "step_n": 0.027, "noise_n": 0.005}, min_snr=8.0)
    assert not _weak("C", {"force_threshold_n": 0.02, "step_n": 0.027, "noise_n": 0.005}, min_snr=5.0)
    assert not _weak("E", {"force_threshold_n": 0.13, "step_n": 0.18, "noise_n": 0.003}, min_snr=8.0)
    assert not _weak("E", {"force_threshold_n": 0.5})  # no derived step: nothing known, detect


def test_a_vary_key_given_twice_is_refused():
    keys = [v.key for v in parse_varies(["dlo.length=10%", "dlo.young=0.5..2"])]
    assert keys == ["dlo.length", "dlo.young"]
    with pytest.raises(VaryError, match=r"key 'dlo\.length' given twice"):
        parse_varies(["dlo.length=10%", "dlo.length=5%"])
