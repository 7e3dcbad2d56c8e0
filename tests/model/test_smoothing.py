"""The intended motion of a trembling hand (dlovr.model.smoothing, docs/people.md) and its place in
programs (``smoothing_s``): unit checks, no simulation."""

from __future__ import annotations

import json

import numpy as np
import pytest

from dlovr.execution.demo_track import DemoTrack
from dlovr.execution.engine import smoothed
from dlovr.model import smoothing as sm
from dlovr.model.discrete import parse_discrete_situation as P
from dlovr.model.program import PoseTrack, Program, TimedSituation, compile_program

DT = 0.002
T = np.arange(0.0, 4.0, DT)


def legs():
    """Straight legs at constant speed with holds, as a script commands them (m)."""
    x = np.interp(T, [0, 1, 1.5, 3, 4], [0, 0.1, 0.1, 0.2, 0.2])
    return np.stack([x, np.zeros_like(x), np.full_like(x, 0.5)], axis=1)


def test_a_script_is_played_by_a_machine_a_hand_drifts_eases_and_jogs():
    """``made_by_hand``: a script's legs accelerate only at their corners; a hand's drift, its eased
    moves without drift or tremor, its tremor and its key steps accelerate far more often (the
    network removes chatter only from demonstrations a hand made, docs/networks.md)."""
    assert not sm.made_by_hand(T, legs())
    drift = legs() + 0.0015 * np.sin(2 * np.pi * 0.1 * T)[:, None]  # 0.1 Hz: 6e-4 m/s^2 at most
    assert sm.made_by_hand(T, drift)
    s = np.clip(T / 2.0, 0.0, 1.0)
    x = 0.1 * (10 * s**3 - 15 * s**4 + 6 * s**5)  # minimum jerk
    eased = np.stack([x, np.zeros_like(T), np.full_like(T, 0.5)], axis=1)
    assert sm.made_by_hand(T, eased)
    assert sm.made_by_hand(T, legs() + 0.0003 * np.sin(2 * np.pi * 9.0 * T)[:, None])
    jog = legs().copy()
    jog[:, 0] = np.floor(T * 30.0) * 0.005  # a held key: a 5 mm step 30 times a second
    assert sm.made_by_hand(T, jog)
    assert not sm.made_by_hand(T[:2], legs()[:2])


def test_a_script_does_not_tremble_a_hand_does():
    assert sm.tremor_of(T, legs()) == 0.0
    hand = legs() + 0.0003 * np.sin(2 * np.pi * 9.0 * T)[:, None]
    assert sm.tremor_of(T, hand) > 5 * sm.TREMOR_ACCEL
    slow = legs() + 0.0015 * np.sin(2 * np.pi * 0.5 * T)[:, None]  # drift alone: what the hand meant
    assert sm.tremor_of(T, slow) < sm.TREMOR_ACCEL


def test_the_moving_average_takes_out_tremor_and_keeps_the_meant_motion():
    n = sm.samples(T, sm.WINDOW_S)
    assert n == 51
    tremor = np.sin(2 * np.pi * 8.0 * T)
    drift = np.sin(2 * np.pi * 1.0 * T)
    inner = slice(200, -200)
    assert np.abs(sm.moving_average(tremor, n)[inner]).max() < 1 / 70
    assert np.abs(sm.moving_average(drift, n)[inner]).max() > 0.93
    line = legs()[:400]  # a straight leg stays itself away from its ends
    assert np.allclose(sm.moving_average(line, n)[100:300], line[100:300], atol=1e-12)


def test_the_tremor_is_taken_out_and_a_quick_move_kept():
    # a drag of 3 cm along -y in 0.5 s and a quick 6 mm move back in 0.1 s (lowering a cable into a
    # hole), with 0.3 mm of tremor at 8-11 Hz on each axis: the average rounds the quick move off
    # by 1.5 mm; the fitted tremor taken out leaves the meant track within 0.3 mm
    def mj(s):
        s = np.clip(s, 0.0, 1.0)
        return s**3 * (10 - 15 * s + 6 * s * s)

    y = -0.03 * mj((T - 1.0) / 0.5) + 0.006 * mj((T - 1.5) / 0.1)
    meant = np.stack([np.zeros_like(T), y, np.full_like(T, 0.3)], axis=1)
    shake = [np.sin(2 * np.pi * 9.3 * T), np.sin(2 * np.pi * 10.7 * T + 1), np.sin(2 * np.pi * 8.4 * T + 2)]
    hand = meant + 0.0003 * np.stack(shake, axis=1)
    pos, _ = sm.smooth_poses(T, hand, np.tile([1.0, 0.0, 0.0, 0.0], (len(T), 1)))
    avg = sm.moving_average(hand, sm.samples(T, sm.WINDOW_S))
    assert np.abs(avg - meant).max() > 0.0012
    assert np.abs(pos - meant).max() < 0.0004
    assert sm.tremor_of(T, pos) < 0.1 * sm.TREMOR_ACCEL < sm.tremor_of(T, hand)
    # unevenly spaced samples: the moving average
    keep = np.arange(len(T)) != 100
    n = sm.samples(T[keep], sm.WINDOW_S)
    np.testing.assert_array_equal(sm.remove_tremor(T[keep], hand[keep]), sm.moving_average(hand[keep], n))


def test_smoothed_quaternions_stay_unit_and_one_hemisphere():
    q = np.tile([1.0, 0.0, 0.0, 0.0], (len(T), 1))
    q[::2] *= -1  # the same orientation written both ways
    _, qs = sm.smooth_poses(T, legs(), q)
    assert np.allclose(np.abs(qs[:, 0]), 1.0)


def test_programs_say_how_they_were_smoothed_and_the_executor_follows_suit():
    states = [TimedSituation(0.0, 1.0, P("V/G & E/N & V/N")),
              TimedSituation(1.0, 3.0, P("V/G & E/N & V/F[t.F1]"))]
    quat = np.tile([1.0, 0.0, 0.0, 0.0], (len(T), 1))
    prog = compile_program(states, PoseTrack(T, legs(), quat))
    assert "smoothing_s" not in prog.to_json()  # as recorded: nothing written, programs unchanged
    from dataclasses import replace

    shaky = replace(prog, smoothing_s=0.1, smoothing="the commanded track trembles")
    back = Program.from_json(json.loads(shaky.dumps()))
    assert (back.smoothing_s, back.smoothing) == (0.1, "the commanded track trembles")
    track = DemoTrack(T, legs() + 0.0003 * np.sin(2 * np.pi * 9.0 * T)[:, None], quat)
    assert smoothed(prog, track) is track
    calm = smoothed(back, track)
    assert calm is not None and sm.tremor_of(T, calm.pos) < sm.TREMOR_ACCEL
    with pytest.raises(ValueError, match="smoothing_s"):
        Program.from_json({**json.loads(shaky.dumps()), "smoothing_s": -1})


def test_a_smoothed_program_says_so_per_derived_parameter():
    from dlovr.model.derivation import WrenchSeries
    from dlovr.recording.compile import _smoothed_program

    states = [TimedSituation(0.0, 1.0, P("V/G & E/N & V/N")),
              TimedSituation(1.0, 3.0, P("V/G & E/N & V/F[t.F1]"))]
    quat = np.tile([1.0, 0.0, 0.0, 0.0], (len(T), 1))
    force = np.zeros((len(T), 3))
    force[T >= 1.0, 2] = 0.2
    prog = compile_program(states, PoseTrack(T, legs(), quat), wrench=WrenchSeries(T, force, force * 0))
    marked = _smoothed_program(prog, "why")
    texts = [v for m in marked.macros for d in m.detection for v in d.derivation.values()]
    assert texts and all(v.endswith("tremor taken out)") for v in texts if v.startswith("derived:"))
    assert marked.smoothing_s == sm.WINDOW_S and marked.smoothing == "why"
