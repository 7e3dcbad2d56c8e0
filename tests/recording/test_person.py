"""The person-like demonstrator (dlovr.recording.person, docs/people.md): unit checks, no simulation."""

from __future__ import annotations

import dataclasses
import math
import re

import numpy as np
import pytest

from dlovr.execution.variation import VaryError, parse_varies, perturb
from dlovr.recording.person import PersonMotion, PersonScript, motion_of
from dlovr.script import parse_script

SCRIPT = parse_script({"waypoints": [
    {"pos": [0.0, 0.0, 0.5], "duration": 1.0, "hold": 0.5},
    {"pos": [0.1, 0.0, 0.5], "duration": 1.0},
    {"pos": [0.2, 0.0, 0.5], "duration": 1.0, "hold": 0.5},
    {"pos": [0.2, 0.0, 0.4], "quat": [0.9659258, 0, -0.258819, 0], "duration": 2.0},
]})
START = (0.0, 0.0, 0.6)


def poses(person, dt=0.002):
    plan = person.plan(START, (1.0, 0.0, 0.0, 0.0))
    ts = np.arange(0.0, person.total_duration + dt, dt)
    pos, quat = zip(*(plan.at(t) for t in ts), strict=True)
    return ts, np.array(pos), np.array(quat)


def test_a_still_hand_plays_the_script_exactly():
    still = PersonMotion(drift_m=0, drift_deg=0, tremor_m=0, pace=(1, 1), ease=0, hesitate_s=0)
    person = PersonScript(SCRIPT, still)
    assert person.total_duration == pytest.approx(SCRIPT.total_duration)
    plan, ref = person.plan(START, (1, 0, 0, 0)), SCRIPT.plan(START, (1, 0, 0, 0))
    for t in np.linspace(0, SCRIPT.total_duration, 37):
        assert np.allclose(plan.at(t)[0], ref.at(t)[0], atol=1e-12)
        assert np.allclose(plan.at(t)[1], ref.at(t)[1], atol=1e-12)


def test_the_hand_drifts_trembles_and_keeps_its_own_pace_deterministically():
    person = PersonScript(SCRIPT, PersonMotion(), seed=3, trial=1)
    ts, pos, _ = poses(person)
    again = poses(PersonScript(SCRIPT, PersonMotion(), seed=3, trial=1))[1]
    assert np.array_equal(pos, again)  # the same trial is the same demonstration, bit for bit
    assert not np.array_equal(pos, poses(PersonScript(SCRIPT, PersonMotion(), seed=3, trial=2))[1])
    assert np.allclose(pos[0], START, atol=1e-12)  # drift and tremor fade in from the start pose
    # the end pose: the script's last waypoint plus the hand's offset (drift of a few mm at most)
    assert np.linalg.norm(pos[-1] - np.array([0.2, 0.0, 0.4])) < 0.01
    lo, hi = (SCRIPT.total_duration * f for f in PersonMotion().pace)
    assert lo <= person.total_duration <= hi + 4 * PersonMotion().hesitate_s
    # tremor: the 8-12 Hz band carries a few tenths of a millimetre
    still = poses(PersonScript(SCRIPT, PersonMotion(tremor_m=0), seed=3, trial=1))[1]
    tremor = pos - still
    assert 1e-4 < np.abs(tremor[ts > 1.0]).max() < 4e-4


def test_key_jogging_moves_in_key_steps_one_axis_at_a_time():
    jog = PersonScript(SCRIPT, PersonMotion(jog_m=0.005), seed=0, trial=0)
    _, pos, _ = poses(jog)
    steps = np.diff(pos, axis=0)
    moved = steps[np.abs(steps).max(axis=1) > 0]
    assert len(moved) > 10
    assert np.allclose(np.abs(moved).max(axis=1), 0.005)
    assert ((np.abs(moved) > 0).sum(axis=1) == 1).all()


def test_demo_keys_set_the_motion_and_leave_the_scene_alone():
    v = parse_varies(["demo.person=2", "demo.pace=0.9..1.1", "demo.jog=0.005"], demo=True)
    scene = _Scene()
    same, values = perturb(scene, v, 0, 0)
    assert same == scene
    m = motion_of(values)
    assert m == PersonMotion(drift_m=0.003, drift_deg=3.0, tremor_m=0.0006, pace=(0.9, 1.1), jog_m=0.005)
    assert motion_of({"dlo.length": 1.1}) is None


@dataclasses.dataclass(frozen=True)
class _Dlo:
    poisson: float = 0.3


@dataclasses.dataclass(frozen=True)
class _Scene:
    dlo: _Dlo = _Dlo()
    gripper: object = None
    objects: tuple = ()


@pytest.mark.parametrize(("item", "demo", "message"), [
    ("demo.drift=0.002", False, "demo.* keys vary demonstrations"),
    ("demo.wobble=1", True, "unknown key 'demo.wobble'"),
    ("demo.pace=1.2", True, "demo.pace is a range"),
    ("demo.drift=1", True, "demo.drift is a number in [0, 0.05] m"),
])
def test_bad_demo_keys_are_one_line(item, demo, message):
    with pytest.raises(VaryError, match=re.escape(message)):
        parse_varies([item], demo=demo)


def test_bad_motion_is_refused():
    with pytest.raises(ValueError, match="drift_m"):
        PersonMotion(drift_m=-1)
    with pytest.raises(ValueError, match="pace"):
        PersonMotion(pace=(1.2, 0.8))
    assert math.isclose(PersonMotion().scaled(2).tremor_m, 0.0006)
