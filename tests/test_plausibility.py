"""Plausibility of simulation steps (docs/recordings.md): penetration and point speed against their
bounds, one episode per stretch of steps beyond a bound."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import pytest

from dlovr.plausibility import GAP_S, Implausible, PlausibilityMonitor, implausible_from_payload, speed_bound


@dataclass
class Arrays:
    dist: np.ndarray
    obj: np.ndarray
    names: tuple[tuple[str, ...], dict[int, str]]

    def __len__(self) -> int:
        return len(self.dist)


@dataclass
class Rec:
    step: int
    time: float
    points: np.ndarray
    contact_arrays: Arrays


def rec(k: int, depth: float = 0.0, shift: float = 0.0) -> Rec:
    """Step ``k`` (2 ms each): the last of 4 points at x = ``shift``, one contact ``depth`` m deep."""
    pts = np.zeros((4, 3))
    pts[:, 0] = [0.0, 0.01, 0.02, 0.03 + shift]
    arrays = Arrays(np.array([0.0001, -depth]), np.array([0, 1]), (("table", "box"), {}))
    return Rec(k, 0.002 * k, pts, arrays)


def test_speed_bound_is_three_times_what_the_gripper_can_give():
    assert speed_bound(0.6, 0.25, 2.0) == pytest.approx(4.35)
    assert speed_bound(0.12, 0.25, 2.0) == pytest.approx(1.47)


def test_a_deep_penetration_is_one_episode_with_its_peak_and_obstacle():
    m = PlausibilityMonitor(0.005, 0.002, 1.5)
    ended: list[Implausible] = []
    for k in range(100):
        depth = 0.004 if 10 <= k < 20 else (0.006 if k == 15 else 0.0005)  # 15: the peak, 4 mm > 2.5 mm
        ended += m.update(rec(k, depth=0.006 if k == 15 else depth))
    assert [e.kind for e in ended] == ["penetration"] and m.finish() == []
    [e] = ended
    assert (e.step, e.start, e.end) == (10, 0.02, pytest.approx(0.038)) and e.where == "box"
    assert e.peak == pytest.approx(0.006) and e.bound == pytest.approx(0.0025)
    assert implausible_from_payload(e.payload()) == e
    assert e.text() == "penetration 6.0 mm (bound 2.5 mm) at 0.020-0.038 s, box"


def test_steps_beyond_a_bound_closer_than_the_gap_are_one_episode_and_the_end_closes_it():
    m = PlausibilityMonitor(0.005, 0.002, 1.5)
    gap = round(GAP_S / 0.002) - 1
    ended = []
    x = 0.0
    for k in range(5 + gap + 10):  # ends before the gap passed after the second jump
        jump = k in (5, 5 + gap)  # 5 mm in one step: 2.5 m/s
        x += 0.005 if jump else 0.0
        ended += m.update(rec(k, shift=x))
    assert ended == []  # the second jump came within the gap, and the episode is still open
    [e] = m.finish()
    assert e.kind == "speed" and e.where == "point 3" and e.peak == pytest.approx(2.5)
    assert (e.start, e.end) == (pytest.approx(0.01), pytest.approx(0.002 * (5 + gap)))


def test_plausible_steps_give_nothing():
    m = PlausibilityMonitor(0.005, 0.002, 1.5)
    assert all(m.update(rec(k, depth=0.001, shift=0.001 * k)) == [] for k in range(50))  # 0.5 m/s
    assert m.finish() == [] and m.episodes == []
