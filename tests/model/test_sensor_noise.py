"""Detection under sensor noise (issue 28): the detectors' parameters for a noisy sensor
(:func:`dlovr.model.detection.for_sensor`), the sensor model's drift and quantisation, and an ``E``
detector that finds a 0.1 N step in 0.02 N of white noise and stays silent on the noise alone."""

from __future__ import annotations

import numpy as np
import pytest

from dlovr.model.detection import (
    SENSOR_K,
    Expectation,
    NoiseModel,
    WrenchConditioner,
    change_std,
    detect,
    for_sensor,
    make_detector,
    sensor_weak,
)

DT = 0.002
#: the peg-in-hole program's first macro: the tip touches the block (0.096 N step along -v)
TOUCH = {"force_threshold_n": 0.038502, "max_angle_deg": 30.0, "ref_lag_s": 0.15, "step_n": 0.096254}


def test_no_noise_leaves_the_parameters_as_they_are():
    p, texts = for_sensor("E", TOUCH, 0.0)
    assert p == TOUCH and texts == {}


def test_thresholds_respect_the_noise_and_smoothing_follows_the_step():
    for sigma in (0.01, 0.02, 0.05):
        p, texts = for_sensor("E", TOUCH, sigma, DT)
        assert p["force_threshold_n"] >= SENSOR_K * change_std(sigma, DT, p["smooth_s"]) - 1e-6
        assert p["force_threshold_n"] >= TOUCH["force_threshold_n"]
        assert p["sensor_noise_n"] == sigma and "smooth_s" in texts
        assert for_sensor("E", p, sigma, DT)[0] == p  # idempotent: a compiled-in floor is kept
    assert for_sensor("E", TOUCH, 0.02)[0]["smooth_s"] < for_sensor("E", TOUCH, 0.05)[0]["smooth_s"]


def test_a_step_too_small_for_the_noise_ends_its_macro_by_motion():
    small = {**TOUCH, "force_threshold_n": 0.008, "step_n": 0.02}
    assert not sensor_weak("E", for_sensor("E", TOUCH, 0.02)[0])
    assert sensor_weak("E", for_sensor("E", small, 0.05)[0])
    assert for_sensor("S", {"jump_n": 0.5}, 0.05)[0] == {"jump_n": 0.5}  # a jump: left as it is
    assert not sensor_weak("S", {"jump_n": 0.6, "step_n": 0.5, "sensor_noise_n": 0.05})


def _stream(step: float, seed: int, n: int = 1500, at: int = 1000) -> tuple[np.ndarray, np.ndarray]:
    t = np.arange(n) * DT
    f = np.tile([0.0, 0.0, -0.6], (n, 1))
    ramp = np.clip((np.arange(n) - at) / 15.0, 0.0, 1.0)  # a 30 ms rise along +z (-v of a top face)
    f[:, 2] += step * ramp
    return t, f


@pytest.mark.parametrize("seed", range(6))
def test_e_detects_the_step_in_noise_and_not_the_noise_alone(seed):
    sigma = 0.02
    p, _ = for_sensor("E", TOUCH, sigma, DT)
    exp = Expectation((), ((0.0, 0.0, -1.0),))
    t, f = _stream(TOUCH["step_n"], seed)
    hit = detect("E", p, exp, t, f, conditioner=WrenchConditioner(NoiseModel(sigma, seed=seed)))
    assert hit is not None and 1000 <= hit <= 1000 + 50  # within 100 ms of the step's start
    t, f = _stream(0.0, seed)
    assert detect("E", p, exp, t, f, conditioner=WrenchConditioner(NoiseModel(sigma, seed=seed))) is None
    d = make_detector("E", p, exp)
    assert d.smoothing_lag() > 0.0


def test_smoothing_settles_on_the_history_before_the_start():
    p, _ = for_sensor("E", TOUCH, 0.02, DT)
    d = make_detector("E", p, Expectation((), ((0.0, 0.0, -1.0),)))
    hist = [(k * DT, np.array([0.0, 0.0, -0.6])) for k in range(100)]
    d.start(100 * DT, np.array([0.0, 0.0, -0.5]), np.zeros(3), hist)  # one outlying sample
    assert abs(d._f0[2] + 0.6) < 0.05  # the reference is the settled force, not the 0.1 N outlier


def test_noise_model_drift_and_quantisation():
    m = NoiseModel(0.0, seed=1, drift=0.01, dt=DT)
    f = [m(np.zeros(3), np.zeros(3))[0] for _ in range(5000)]  # 10 s
    assert 0.001 < float(np.abs(f[-1]).max()) < 0.2  # a random walk of ~0.03 N after 10 s
    q = NoiseModel(0.0, quantum=0.01)
    assert q(np.array([0.123, -0.004, 0.0]), np.zeros(3))[0].tolist() == pytest.approx([0.12, 0.0, 0.0])
    with pytest.raises(ValueError):
        NoiseModel(0.0, drift=-1.0)
