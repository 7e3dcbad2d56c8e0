"""The force detectors of the five transition classes on synthetic wrench streams: each fires on its
own pattern, not on sensor noise, and not on the other classes' patterns."""

from __future__ import annotations

import math

import numpy as np
import pytest

from dlovr.model.detection import (
    ALGORITHMS,
    DEFAULTS,
    Expectation,
    LowPass,
    NoiseModel,
    WrenchConditioner,
    detect,
    make_detector,
)

DT = 0.002
N = 600  # 1.2 s at 500 Hz
T = np.arange(N) * DT
WEIGHT = np.array([0.0, 0.0, -0.6])  # a hanging cable pulls the gripper down with its weight
START = 250  # the pattern begins at 0.5 s

# contact vectors (eq. 2: the direction in which the face blocks the cable): a table top, a side wall
TOP = (0.0, 0.0, -1.0)
WALL = (-1.0, 0.0, 0.0)
RIM = (-0.6, 0.0, -0.8)  # an instable edge contact


def _ramp(k: int, length: int) -> float:
    return min(max((k - START) / length, 0.0), 1.0)


def pattern(name: str) -> np.ndarray:
    """(N, 3) force streams (N, world) of each class's transition, on top of the cable's weight."""
    f = np.tile(WEIGHT, (N, 1))
    for k in range(N):
        if name == "E":  # a contact on the table top begins: the table pushes the cable up
            f[k] += [0.0, 0.0, 1.0 * _ramp(k, 25)]
        elif name == "C":  # a contact force of 1 N turns from the table top (up) to the wall (+x)
            th = 0.5 * math.pi * _ramp(k, 50)
            f[k] += [math.sin(th), 0.0, math.cos(th) - 1.0]
        elif name == "T":  # the force rises along +x as the cable bends, then turns toward +y
            rise = _ramp(k, 50)
            phi = 0.5 * math.pi * min(max((k - START - 75) / 25, 0.0), 1.0)
            f[k] += [rise * math.cos(phi), rise * math.sin(phi), 0.0]
        elif name == "I":  # a small force along the rim's vector appears
            f[k] += 0.3 * _ramp(k, 25) * -np.asarray(RIM)
        elif name == "S":  # a jump within one step, sideways
            f[k] += [0.0, -1.0 if k >= START else 0.0, 0.0]
    return f


EXPECT = {
    "E": Expectation((), (TOP,)),
    "C": Expectation((TOP,), (WALL,)),
    "T": Expectation((), (WALL,)),
    "I": Expectation((), (RIM,)),
    "S": Expectation((RIM,), ()),
}


def run(cls: str, forces: np.ndarray, noise: float = 0.0, seed: int = 0) -> int | None:
    cond = WrenchConditioner(NoiseModel(noise, seed=seed))
    return detect(cls, {}, EXPECT[cls], T, forces, conditioner=cond)


@pytest.mark.parametrize("cls", ["E", "C", "T", "I", "S"])
def test_fires_on_its_own_pattern_soon_after_it_begins(cls):
    k = run(cls, pattern(cls))
    assert k is not None, f"{cls} missed its pattern"
    assert START <= k <= START + 110, f"{cls} fired at {(k - START) * DT * 1000:.0f} ms"


@pytest.mark.parametrize("cls", ["E", "C", "T", "I", "S"])
def test_fires_on_its_own_pattern_with_noise(cls):
    k = run(cls, pattern(cls), noise=0.01, seed=3)
    assert k is not None and START - 5 <= k <= START + 120


@pytest.mark.parametrize("cls", ["E", "C", "T", "I", "S"])
@pytest.mark.parametrize("seed", [1, 2, 3])
def test_silent_on_noise(cls, seed):
    assert run(cls, pattern("none"), noise=0.02, seed=seed) is None


@pytest.mark.parametrize(("cls", "other"), [(a, b) for a in "ECTIS" for b in "ECTIS" if a != b])
def test_silent_on_the_other_classes_patterns(cls, other):
    assert run(cls, pattern(other)) is None, f"{cls} fired on the {other} pattern"


def test_release_fires_on_the_support_going_away():
    """An E for a contact that ends: the table stops carrying 0.4 N, the gripper gets it back (+v)."""
    f = np.tile(WEIGHT + np.array([0.0, 0.0, 0.4]), (N, 1))
    f[START:] = WEIGHT
    k = detect("E", {"force_threshold_n": 0.3}, Expectation((TOP,), ()), T, f)
    assert k is not None and START <= k < START + 10
    assert detect("E", {"force_threshold_n": 0.3}, Expectation((), (TOP,)), T, f) is None


def test_parameters_from_the_program_override_the_defaults():
    weak = np.tile(WEIGHT, (N, 1))
    weak[START:, 2] += 0.2
    assert detect("E", {}, EXPECT["E"], T, weak) is None  # default threshold 0.5 N
    assert detect("E", {"force_threshold_n": 0.1}, EXPECT["E"], T, weak) is not None
    det = make_detector("E", {"force_threshold_n": 0.1}, EXPECT["E"])
    assert det.params == {**DEFAULTS["E"], "force_threshold_n": 0.1}
    assert set(ALGORITHMS) == set(DEFAULTS) == {"E", "C", "T", "I", "S"}


def test_jump_detection_needs_a_high_sampling_rate():
    with pytest.raises(ValueError, match="500 Hz"):
        make_detector("S", {}, EXPECT["S"], rate_hz=100.0)
    with pytest.raises(ValueError, match="no detector"):
        make_detector("X", {}, EXPECT["S"])


def test_low_pass_and_noise_are_deterministic():
    lp = LowPass(0.01)
    y = [lp(np.array([1.0]), DT)[0] for _ in range(3)]
    assert y[0] == 1.0  # the first sample initialises
    lp2 = LowPass(0.01)
    lp2(np.array([0.0]), DT)
    step = lp2(np.array([1.0]), DT)[0]
    assert step == pytest.approx(DT / (0.01 + DT))
    a = NoiseModel(0.1, seed=7)(np.zeros(3), np.zeros(3))
    b = NoiseModel(0.1, seed=7)(np.zeros(3), np.zeros(3))
    assert np.array_equal(a[0], b[0]) and np.array_equal(a[1], b[1])
    assert np.all(np.abs(a[1]) < np.abs(a[0]).max() + 1)  # torque noise is scaled down
    with pytest.raises(ValueError):
        LowPass(-1.0)


# --------------------------------------------------------------------------------------------------
# Sliding reference (``ref_lag_s``) and the demonstrated step's direction (``dir_*``)


def _drift_then_step(step_at: int | None) -> np.ndarray:
    """A force drifting by 0.2 N over the stream (a moving gripper), plus a 0.1 N step along +z."""
    f = np.tile(WEIGHT, (N, 1))
    f[:, 0] += 0.2 * np.arange(N) / N  # slow drift along x: 0.2 N in 1.2 s
    if step_at is not None:
        f[step_at:, 2] += 0.1
    return f


def test_a_sliding_reference_ignores_slow_drift_and_catches_a_step():
    exp = Expectation((), (TOP,))  # a table contact begins: the force rises along -v = +z
    params = {"force_threshold_n": 0.04, "max_angle_deg": 45.0}
    # drift alone: from the first sample, 0.2 N along x is outside the cone; a 0.05 N threshold on
    # any change (no vector) fires on the drift, with a sliding reference of 0.15 s it does not
    any_change = Expectation()
    assert detect("E", {"force_threshold_n": 0.05}, any_change, T, _drift_then_step(None)) is not None
    lagged = {"force_threshold_n": 0.05, "ref_lag_s": 0.15}
    assert detect("E", lagged, any_change, T, _drift_then_step(None)) is None
    i = detect("E", {**params, "ref_lag_s": 0.15}, exp, T, _drift_then_step(START))
    assert i is not None and START <= i <= START + 10
    # the reference follows the force: a step that came more than ref_lag_s ago no longer counts
    det = make_detector("E", {**params, "ref_lag_s": 0.15}, exp)
    f = _drift_then_step(START)
    det.start(0.0, f[0], np.zeros(3))
    assert all(det._reference(T[k], f[k]) is not None for k in range(1, START + 100))
    assert det._reference(T[START + 100], f[START + 100])[2] == pytest.approx(WEIGHT[2] + 0.1)


def test_c_and_i_without_contact_vectors_watch_the_demonstrated_step_direction():
    up = {"dir_x": 0.0, "dir_y": 0.0, "dir_z": 1.0}
    f = _drift_then_step(START)  # +0.1 N along z at START, drift along x
    c = {"force_threshold_n": 0.04, "max_angle_deg": 20.0, "ref_lag_s": 0.15}
    assert detect("C", {**c, **up}, Expectation(), T, f) is not None
    down = {"dir_x": 0.0, "dir_y": 0.0, "dir_z": -1.0}
    assert detect("C", {**c, **down}, Expectation(), T, f) is None  # the step points the other way
    i = {"min_force_n": 0.04, "max_angle_deg": 20.0, "ref_lag_s": 0.15}
    assert detect("I", {**i, **up}, Expectation(), T, f) is not None
    assert detect("I", {**i, **down}, Expectation(), T, f) is None


def test_e_for_a_pinch_watches_the_line_of_its_axis_either_sign():
    """A pinch (the DLO clamped between a floor and a ceiling) has the zero contact vector: the E
    detector watches its axis, either sign, not just any change of force (docs/model.md, Pinch)."""
    pinch = Expectation((), ((0.0, 0.0, 0.0),), axes=((0.0, 0.0, -1.0),))
    p = {"force_threshold_n": 0.2}
    for sign in (1.0, -1.0):
        f = np.tile(WEIGHT, (N, 1))
        f[START:, 2] += sign * 0.4  # along the axis, up or down
        k = detect("E", p, pinch, T, f)
        assert k is not None and START <= k < START + 10, sign
    across = np.tile(WEIGHT, (N, 1))
    across[START:, 0] += 0.4  # sideways: no pinch force
    assert detect("E", p, pinch, T, across) is None
    assert detect("E", p, Expectation((), ((0.0, 0.0, 0.0),)), T, across) is not None  # without the axis
