"""Detection parameters derived from the demonstration's wrench (dlovr/model/derivation.py): a synthetic
wrench series with a known step gives the expected thresholds and derivation texts; no signal gives
the defaults, marked."""

from __future__ import annotations

import numpy as np
import pytest
from numpy.typing import ArrayLike

from dlovr.model.derivation import DEFAULT_PARAMS, DerivationRules, WrenchSeries, derive
from dlovr.model.discrete import parse_discrete_situation as P
from dlovr.model.program import PoseTrack, TimedSituation, compile_program


def series(step_at: float, before: ArrayLike, after: ArrayLike, noise: float = 0.0, dt: float = 0.01,
           t_end: float = 2.0, seed: int = 0) -> WrenchSeries:
    """A wrench series holding ``before`` (N) until ``step_at`` s, then ``after``, with noise."""
    t = np.arange(0.0, t_end, dt)
    f = np.where((t < step_at)[:, None], np.asarray(before, float), np.asarray(after, float))
    f = f + noise * np.random.default_rng(seed).standard_normal(f.shape)
    return WrenchSeries(t, f, np.zeros_like(f))


def test_e_threshold_is_a_fraction_of_the_step_along_minus_v():
    # the cable lands on a table (v = (0, 0, 1)): the force on the gripper drops by 0.31 N along -z
    w = series(1.0, [0, 0, -0.25], [0, 0, 0.06])
    w = WrenchSeries(w.t, w.force * np.array([1, 1, -1]), w.torque)  # before (0,0,0.25), after (0,0,-0.06)
    d = derive("E", [], [(0.0, 0.0, 1.0)], w, 0.0, 1.0, 2.0)
    assert d.params["force_threshold_n"] == pytest.approx(0.4 * 0.31)
    assert d.derivation["force_threshold_n"] == "derived: 40% of the 0.31 N step along -v, noise 0 N"
    assert d.params["max_angle_deg"] == 30.0  # the step lies on -v: the default cone suffices
    assert d.derivation["max_angle_deg"].startswith("derived: step at 0 deg from -v")


def test_noise_raises_the_threshold_to_k_times_the_noise():
    w = series(1.0, [0, 0, 0.0], [0, 0, -0.1], noise=0.02, seed=3)
    d = derive("E", [], [(0.0, 0.0, 1.0)], w, 0.0, 1.0, 2.0, DerivationRules(quiet_margin=0.0))
    noise = float(w.window(1.0 - 0.15, 1.0 - 0.01)[:, 2].std())
    assert d.params["force_threshold_n"] == pytest.approx(round(4 * noise, 6))
    assert d.derivation["force_threshold_n"].startswith(f"derived: 4x noise {noise:.3g} N (above 40% of the")


def test_a_step_within_the_noise_is_marked_weak():
    w = series(1.0, [0, 0, 0.0], [0, 0, -0.02], noise=0.02, seed=1)
    d = derive("E", [], [(0.0, 0.0, 1.0)], w, 0.0, 1.0, 2.0)
    assert "weak signal" in d.derivation["force_threshold_n"]
    assert d.params["force_threshold_n"] > 0.02


def test_released_contact_watches_plus_v_and_widens_the_cone():
    # a contact with v = (0, 0, 1) ends: the force rises along +v, here tilted 40 deg toward x
    step = 0.5 * np.array([np.sin(np.radians(40)), 0, np.cos(np.radians(40))])
    w = series(1.0, [0, 0, 0], step)
    d = derive("E", [(0.0, 0.0, 1.0)], [], w, 0.0, 1.0, 2.0)
    assert d.params["force_threshold_n"] == pytest.approx(0.4 * 0.5 * np.cos(np.radians(40)), abs=1e-6)
    assert "along +v" in d.derivation["force_threshold_n"]
    assert d.params["max_angle_deg"] == pytest.approx(55.0, abs=1e-3)


def test_c_t_i_s_derive_their_thresholds():
    w = series(1.0, [0, 0, 0], [0.3, 0, 0])
    c = derive("C", [(1.0, 0, 0)], [(0, 0, 1.0)], w, 0.0, 1.0, 2.0)
    assert "min_turn_fraction" not in c.params
    assert c.params["force_threshold_n"] == pytest.approx(0.4 * 0.3 / np.sqrt(2), abs=1e-6)
    assert "v_old - v_new" in c.derivation["force_threshold_n"]
    t = derive("T", [], [], w, 0.0, 1.0, 2.0)
    assert t.params["rise_n"] == pytest.approx(0.12)
    assert t.derivation["max_angle_deg"].startswith("default:")
    i = derive("I", [], [(-1.0, 0, 0)], w, 0.0, 1.0, 2.0)
    assert i.params["min_force_n"] == pytest.approx(0.12)
    s = derive("S", [], [], w, 0.0, 1.0, 2.0)
    assert s.params["jump_n"] == pytest.approx(0.12)
    assert s.params["min_rate_hz"] == 500.0


@pytest.mark.parametrize("cls", sorted(DEFAULT_PARAMS))
def test_no_signal_gives_the_defaults_marked(cls):
    d = derive(cls, [], [(0, 0, 1.0)], None, 0.0, 1.0, 2.0)
    assert d.params == DEFAULT_PARAMS[cls]
    assert set(d.derivation) == set(d.params)
    assert all(v == "default: no wrench signal in the recording" for v in d.derivation.values())
    # a state too short for the windows: no signal either
    w = series(1.0, [0, 0, 0], [0, 0, -1.0])
    d = derive(cls, [], [(0, 0, 1.0)], w, 0.99, 1.0, 2.0, DerivationRules())
    assert d.params == {**DEFAULT_PARAMS[cls], "step_n": 0.0}  # no step: the executor will not wait
    why = "default: no signal (fewer than 3 wrench samples before"
    assert all(v.startswith(why) for k, v in d.derivation.items() if k != "step_n")
    assert d.derivation["step_n"] == (
        "derived: none measurable (the state before it held 10 ms): the force cannot show this transition"
    )


def test_compile_program_derives_per_macro_and_is_pure_and_deterministic():
    a, b = P("V/G & E/N & V/N"), P("V/G & E/N & V/F[t.F1]")
    from dataclasses import replace

    b = type(b)((b.contacts[0], b.contacts[1], replace(b.contacts[2], vector=(0.0, 0.0, 1.0))))
    states = [TimedSituation(0.0, 1.0, a), TimedSituation(1.0, 1.0, b)]
    t = np.linspace(0, 2, 3)
    track = PoseTrack(t, np.zeros((3, 3)), np.tile([1.0, 0, 0, 0], (3, 1)))
    w = series(1.0, [0, 0, 0.25], [0, 0, -0.05])
    p1 = compile_program(states, track, wrench=w)
    det = p1.macros[0].detection[0]
    assert det.params["force_threshold_n"] == pytest.approx(0.12)
    assert det.derivation["force_threshold_n"] == "derived: 40% of the 0.3 N step along -v, noise 0 N"
    assert p1.dumps() == compile_program(states, track, wrench=w).dumps()
    assert '"derivation"' in p1.dumps()
    assert "force_threshold_n: derived: 40% of the 0.3 N step" in p1.listing()


def test_the_quiet_level_before_the_transition_raises_the_threshold():
    """A rise of 0.06 N within 0.15 s while the previous state held (a swing) lifts the threshold to
    1.25x that, above 40% of the 0.1 N step; 0.2 N would make the step a weak signal."""
    for swing, weak in ((0.06, False), (0.2, True)):
        w = series(1.0, [0, 0, 0.0], [0, 0, -0.1])
        f = w.force.copy()
        f[(w.t > 0.6) & (w.t < 0.7), 2] -= swing  # along -v = -z for v = (0, 0, 1)
        w = WrenchSeries(w.t, f, w.torque)
        d = derive("E", [], [(0.0, 0.0, 1.0)], w, 0.0, 1.0, 2.0)
        assert d.params["force_threshold_n"] == pytest.approx(1.25 * swing, abs=1e-6)
        text = d.derivation["force_threshold_n"]
        assert text.startswith(f"derived: 1.25x the {swing:.3g} N largest rise along -v within 0.15 s")
        assert ("weak signal" in text) == weak
        assert d.params["step_n"] == pytest.approx(0.1) and d.params["ref_lag_s"] == 0.15


def test_a_known_arming_counts_only_the_rises_a_detector_armed_then_would_see():
    """With ``armed_at`` (a calibration run knows when its detector is armed) a swing that is over
    before the arming does not lift the threshold; one that ends after it does."""
    w = series(1.0, [0, 0, 0.0], [0, 0, -0.1])
    f = w.force.copy()
    f[(w.t > 0.6) & (w.t < 0.65), 2] -= 0.06  # a swing along -v, over at 0.65 s
    w = WrenchSeries(w.t, f, w.torque)
    assert derive("E", [], [(0.0, 0.0, 1.0)], w, 0.0, 1.0, 2.0).params["force_threshold_n"] == \
        pytest.approx(0.075, abs=1e-6)  # armed from half the stretch on: the swing counts
    late = derive("E", [], [(0.0, 0.0, 1.0)], w, 0.0, 1.0, 2.0, armed_at=0.8)
    assert late.params["force_threshold_n"] == pytest.approx(0.04)  # 40 % of the 0.1 N step
    early = derive("E", [], [(0.0, 0.0, 1.0)], w, 0.0, 1.0, 2.0, armed_at=0.62)
    assert early.params["force_threshold_n"] == pytest.approx(0.075, abs=1e-6)


def test_a_pinch_derives_its_e_threshold_along_its_axis():
    """A pinch begins (zero contact vector, axis z): the step is measured along the axis line, in the
    sign it took, not in the step's own direction (docs/model.md, Pinch)."""
    w = series(1.0, [0, 0, 0], [0.3, 0, -0.4])  # 0.4 N down along the axis, 0.3 N sideways
    d = derive("E", [], [(0.0, 0.0, 0.0)], w, 0.0, 1.0, 2.0, axes=[(0.0, 0.0, 1.0)])
    assert d.params["step_n"] == pytest.approx(0.4)
    assert d.params["force_threshold_n"] == pytest.approx(0.4 * 0.4)
    assert d.derivation["force_threshold_n"] == "derived: 40% of the 0.4 N step along -axis, noise 0 N"
    assert d.params["max_angle_deg"] == pytest.approx(37 + 15, abs=0.2)  # the step is 37 deg off the axis
    without = derive("E", [], [(0.0, 0.0, 0.0)], w, 0.0, 1.0, 2.0)
    assert without.params["step_n"] == pytest.approx(0.5)  # no direction: the whole step
