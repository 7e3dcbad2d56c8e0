"""Detection parameters derived from the demonstration's force signal (paper §V.B, §VI; docs/model.md).

Pure numpy. A program's detectors (:mod:`dlovr.model.detection`) need thresholds: how large a change
of the sensed wrench means that the expected transition has happened. They come from the
demonstration, not from constants: around each transition the recording's wrench series (the force
the cable exerts on the gripper, N, world frame) gives

- the **baseline** and the **noise**: mean and standard deviation (along the detector's direction) of
  the force over a window of :attr:`DerivationRules.window_s` before the transition, while the
  previous situation held (the last :attr:`DerivationRules.gap_s` left out: the transition's own
  onset);
- the **step**: the mean force over a window after the transition (while the new situation held)
  minus the baseline, projected on the direction the class's detector watches (``-v`` of a contact
  that begins, ``+v`` of one that ends for ``E``; ``v_old - v_new`` for ``C``; the step's own
  direction for ``T``, ``I`` and ``S``);
- the **threshold**: :attr:`DerivationRules.fraction` of the step, but at least
  :attr:`DerivationRules.k_noise` times the noise, :attr:`DerivationRules.quiet_margin` times the
  largest rise along that direction within :attr:`DerivationRules.window_s` while the previous state
  held (the quiet level a detector with that sliding reference sees before the transition), and
  :attr:`DerivationRules.floor_n`.

``step_n`` records the demonstrated step itself: where the threshold is not below it, the force
signal cannot show the transition (the executor then ends the macro by its motion). Each parameter
carries a text saying how it was derived (``derived: 40% of the 0.31 N step along -v,
noise 0.004 N``); a parameter the signal cannot give keeps the class's default, marked ``default: ...``
with the reason (no wrench samples around the transition, too short a state, no expected vector).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from dlovr.model.detection import DEFAULTS, THRESHOLD_PARAM
from dlovr.transforms import angle_deg, dot, norm, unit

#: The classes' default parameters (forces N, angles degrees, times s, rates Hz): used where the
#: demonstration gives no signal (the same values as :data:`dlovr.model.detection.DEFAULTS`).
#: The parameters a derivation starts from: the detectors' defaults, less the ``S`` window, which a
#: derived program leaves to the detector (so that program files say only what was derived).
DEFAULT_PARAMS: dict[str, dict[str, float]] = {
    cls: {k: v for k, v in params.items() if k != "window_s"} for cls, params in DEFAULTS.items()
}
#: Classes whose cone (``max_angle_deg``) is widened to the demonstrated step's direction.
CONE_CLASSES = ("E", "C", "I")
#: A contact vector, axis or turn (unit vectors, or differences of them) shorter than this has no
#: direction to watch.
_NO_DIRECTION = 1e-9

Vec = tuple[float, float, float] | None


@dataclass(frozen=True)
class WrenchSeries:
    """The gripper's wrench as the recording sampled it: times ``t`` (k,) s, ``force`` (k, 3) N,
    ``torque`` (k, 3) N m, world frame, times increasing."""

    t: np.ndarray
    force: np.ndarray
    torque: np.ndarray

    def __post_init__(self) -> None:
        t = np.asarray(self.t, float).ravel()
        f = np.asarray(self.force, float).reshape(len(t), 3)
        tq = np.asarray(self.torque, float).reshape(len(t), 3)
        if np.any(np.diff(t) < 0):
            raise ValueError("wrench series times must not decrease")
        object.__setattr__(self, "t", t)
        object.__setattr__(self, "force", f)
        object.__setattr__(self, "torque", tq)

    def window(self, t0: float, t1: float) -> np.ndarray:
        """The force samples (m, 3) with ``t0 <= t <= t1``."""
        a, b = np.searchsorted(self.t, t0, side="left"), np.searchsorted(self.t, t1, side="right")
        return self.force[a:b]


@dataclass(frozen=True)
class DerivationRules:
    """How thresholds are derived: ``window_s`` before and after the transition (s, cut to the time
    the states held), ``gap_s`` left out on either side of it, at least ``min_samples`` samples per
    window; threshold ``fraction`` of the step, at least ``k_noise`` x noise and ``floor_n`` N; the
    cone widened to the step's angle plus ``cone_margin_deg`` (at most ``max_cone_deg``); and at least
    ``quiet_margin`` x the largest rise along the watched direction within ``window_s`` while the
    previous state held, from ``armed_from`` of it on and up to ``window_s`` before the transition
    (what a detector with that sliding reference, armed after that fraction of the demonstrated
    motion, would have seen without the transition; the last window holds the transition's onset)."""

    window_s: float = 0.15
    gap_s: float = 0.01
    min_samples: int = 3
    fraction: float = 0.4
    k_noise: float = 4.0
    floor_n: float = 0.01
    quiet_margin: float = 1.25
    armed_from: float = 0.5
    cone_margin_deg: float = 15.0
    max_cone_deg: float = 75.0


@dataclass(frozen=True)
class Derived:
    """Parameters of one class's detector and, per parameter, how it was derived."""

    params: dict[str, float]
    derivation: dict[str, str]


def _directions(
    cls: str, released: Sequence[Vec], established: Sequence[Vec], axes: Sequence[Vec] = ()
) -> list[tuple[np.ndarray, str]]:
    """The directions the class's detector watches, with a name for the texts (a pinch's zero
    vector gives none; ``E`` watches its ``axes`` instead, either sign)."""
    begins = [
        (u, "-v")
        for v in established
        if v is not None and (u := unit(-np.asarray(v, float), _NO_DIRECTION)) is not None
    ]
    if cls == "E":
        signs = ((1.0, "+axis"), (-1.0, "-axis"))
        pinch = [
            (s * u, name)
            for a in axes
            if a is not None and (u := unit(a, _NO_DIRECTION)) is not None
            for s, name in signs
        ]
        return (
            begins
            + [(u, "+v") for v in released if v is not None and (u := unit(v, _NO_DIRECTION)) is not None]
            + pinch
        )
    if cls == "I":
        return begins
    if cls == "C":
        old = [np.asarray(v, float) for v in released if v is not None]
        new = [np.asarray(v, float) for v in established if v is not None]
        if not old or not new:
            return []
        u = unit(sum(old, np.zeros(3)) / len(old) - sum(new, np.zeros(3)) / len(new), _NO_DIRECTION)
        return [] if u is None else [(u, "v_old - v_new")]
    return []  # T, S: the step's own direction


def _quiet(wrench: WrenchSeries, u: np.ndarray, t0: float, t1: float, lag: float, ends_from: float = -np.inf,
           ) -> float:
    """The largest rise of the force along ``u`` (N) within ``lag`` s, between ``t0`` and ``t1``
    (only rises that end at ``ends_from`` or later: a detector armed then)."""
    a, b = np.searchsorted(wrench.t, t0, side="left"), np.searchsorted(wrench.t, t1, side="right")
    t, x = wrench.t[a:b], (wrench.force[a:b] * u).sum(axis=1)
    best, j = 0.0, 0
    for i in range(len(t)):
        if t[i] < ends_from:
            continue
        while t[j] < t[i] - lag - 1e-12:
            j += 1
        best = max(best, float(x[i] - x[j : i + 1].min()))
    return best


def _default(cls: str, why: str) -> Derived:
    p = dict(DEFAULT_PARAMS[cls])
    return Derived(p, {k: f"default: {why}" for k in p})


def derive(
    cls: str,
    released: Sequence[Vec],
    established: Sequence[Vec],
    wrench: WrenchSeries | None,
    t_prev: float,
    t: float,
    t_next: float,
    rules: DerivationRules | None = None,
    axes: Sequence[Vec] = (),
    armed_at: float | None = None,
) -> Derived:
    """The detector parameters of class ``cls`` for a transition at ``t`` (s), the previous situation
    having held since ``t_prev`` and the new one until ``t_next``; ``released``/``established``: the
    contact vectors (unit, world) of the principal contacts the transition ends and begins;
    ``axes``: the axes (unit, world) of those that are pinches (zero vector, docs/model.md).
    ``armed_at`` (s): when a run's detector is armed, where it is known (a calibration run in
    simulation, :mod:`dlovr.execution.calibration`): the quiet level is measured from then on
    (its reference reaching back one window) instead of from :attr:`DerivationRules.armed_from`."""
    if wrench is None or len(wrench.t) == 0:
        return _default(cls, "no wrench signal in the recording")
    r = rules or DerivationRules()
    before = wrench.window(max(t_prev, t - r.window_s), t - r.gap_s)
    after = wrench.window(t + r.gap_s, min(t_next, t + r.window_s))
    if len(before) < r.min_samples or len(after) < r.min_samples:
        return _unmeasurable(cls, r, len(before) < r.min_samples, t_prev, t, t_next)
    base = before.mean(axis=0)
    step = after.mean(axis=0) - base
    dirs = _directions(cls, released, established, axes)
    u, name, size, noise = _measure(step, before, dirs)
    p = dict(DEFAULT_PARAMS[cls])
    texts = {k: f"default: {cls} keeps it" for k in p}
    key = THRESHOLD_PARAM[cls]
    armed = t_prev + r.armed_from * (t - t_prev) if armed_at is None else armed_at
    armed -= r.window_s  # the reference reaches back one window
    # up to one window before the transition: the force may start to change before the contact
    # label does (the transition's onset belongs to the step, not to the quiet level)
    quiet_to = t - r.window_s
    ends = -np.inf if armed_at is None else armed_at  # a known arming: rises that end after it
    quiet = 0.0 if u is None else _quiet(wrench, u, max(t_prev + r.gap_s, armed), quiet_to, r.window_s, ends)
    thr, texts[key] = _threshold(r, size, noise, quiet, name)
    p[key] = round(thr, 6)
    lag_key = "window_s" if cls == "S" else "ref_lag_s"  # S compares over its own window
    p[lag_key] = r.window_s
    texts[lag_key] = f"derived: the {r.window_s:g} s windows the step was measured over"
    if not dirs and cls in ("C", "I") and u is not None:
        for axis, x in zip("xyz", u, strict=True):
            p[f"dir_{axis}"] = round(float(x), 6)
            texts[f"dir_{axis}"] = "derived: the demonstrated step's direction (no contact vector to watch)"
    _step_and_noise(p, texts, name, size, noise, len(before), len(after))
    if cls == "C":
        texts.pop("min_turn_fraction", None)
        p.pop("min_turn_fraction", None)
    _cone(cls, p, texts, r, bool(dirs), u, step, size, name)
    return Derived(p, {k: texts[k] for k in p})


def _unmeasurable(
    cls: str, r: DerivationRules, short_before: bool, t_prev: float, t: float, t_next: float
) -> Derived:
    """The class's defaults and ``step_n`` 0 for a transition with fewer than ``r.min_samples``
    wrench samples in its window before (``short_before``) or else after it."""
    which = "before" if short_before else "after"
    why = f"no signal (fewer than {r.min_samples} wrench samples {which} the transition)"
    d = _default(cls, why)
    held = (t - t_prev) if which == "before" else (t_next - t)
    return Derived(
        {**d.params, "step_n": 0.0},
        {**d.derivation, "step_n": f"derived: none measurable (the state {which} it held "
         f"{held * 1000:.0f} ms): the force cannot show this transition"},
    )


def _measure(
    step: np.ndarray, before: np.ndarray, dirs: list[tuple[np.ndarray, str]]
) -> tuple[np.ndarray | None, str, float, float]:
    """The direction watched (unit; ``None`` for a zero step without ``dirs``), its name, the
    step's size along it and the noise of the samples ``before`` along it: the one of ``dirs``
    the step rises most along, else the step's own direction."""
    if dirs:
        u, name = max(dirs, key=lambda d: dot(step, d[0]))
        size = dot(step, u)
        noise = float((before * u).sum(axis=1).std())
    else:
        n = norm(step)
        u, name, size = (step / n if n > 1e-12 else None), "its own direction", n
        noise = norm(before.std(axis=0))
    return u, name, size, noise


def _threshold(r: DerivationRules, size: float, noise: float, quiet: float, name: str) -> tuple[float, str]:
    """The threshold (N) for a step of ``size`` along ``name`` with ``noise`` and a ``quiet`` level
    before it, and the text saying which of the rules gave it."""
    frac = r.fraction * size
    thr = max(frac, r.k_noise * noise, r.quiet_margin * quiet, r.floor_n)
    if thr == r.quiet_margin * quiet and thr > max(frac, r.k_noise * noise):
        text = (
            f"derived: {r.quiet_margin:g}x the {quiet:.3g} N largest rise along {name} within "
            f"{r.window_s:g} s while the previous state held (the step is {size:.3g} N"
            + (", weak signal)" if thr >= size else ")")
        )
    elif size <= 0:
        text = (
            f"derived: {r.k_noise:g}x noise {noise:.3g} N (the demonstrated step along {name} is "
            f"{size:.3g} N: no rise to detect)"
        )
    elif thr == frac:
        text = f"derived: {r.fraction:.0%} of the {size:.3g} N step along {name}, noise {noise:.3g} N"
    elif thr < size:
        text = (
            f"derived: {r.k_noise:g}x noise {noise:.3g} N (above {r.fraction:.0%} of the {size:.3g} N "
            f"step along {name})"
        )
    else:
        text = (
            f"derived: {max(r.k_noise * noise, r.floor_n):.3g} N floor (the {size:.3g} N step along {name} "
            f"is within {r.k_noise:g}x noise {noise:.3g} N: weak signal)"
        )
    return thr, text


def _step_and_noise(
    p: dict[str, float],
    texts: dict[str, str],
    name: str,
    size: float,
    noise: float,
    n_before: int,
    n_after: int,
) -> None:
    """Record the demonstrated step and the noise (``step_n``, ``noise_n``) in ``p`` and ``texts``."""
    p["step_n"] = round(size, 6)
    p["noise_n"] = round(noise, 6)
    texts["noise_n"] = (
        f"derived: the standard deviation along {name} over the {n_before} samples before the "
        "transition; a step within a few times it is no signal to trust"
    )
    texts["step_n"] = (
        f"derived: the demonstrated step along {name} (mean over {n_after} samples after minus "
        f"{n_before} before); a threshold at or above it means the force cannot show the transition"
    )


def _cone(
    cls: str,
    p: dict[str, float],
    texts: dict[str, str],
    r: DerivationRules,
    has_dirs: bool,
    u: np.ndarray | None,
    step: np.ndarray,
    size: float,
    name: str,
) -> None:
    """For a class with a cone (:data:`CONE_CLASSES`): widen ``max_angle_deg`` in ``p`` to the
    step's angle from the watched direction ``u`` plus the margin, or say in ``texts`` why not."""
    if cls in CONE_CLASSES and has_dirs and u is not None and size > 0:
        n = norm(step)  # the angle to the unit u, rounded as numpy's arccos (programs stay bit for bit)
        ang = 180.0 if n < 1e-12 else float(np.degrees(np.arccos(np.clip(size / n, -1.0, 1.0))))
        cone = min(max(DEFAULT_PARAMS[cls]["max_angle_deg"], ang + r.cone_margin_deg), r.max_cone_deg)
        p["max_angle_deg"] = round(cone, 3)
        texts["max_angle_deg"] = (
            f"derived: step at {ang:.0f} deg from {name} + {r.cone_margin_deg:g} deg margin "
            f"(at least the default {DEFAULT_PARAMS[cls]['max_angle_deg']:g}, at most {r.max_cone_deg:g})"
        )
    elif cls in CONE_CLASSES:
        why = "no step along " + name if has_dirs else "no expected contact vector to compare the step with"
        texts["max_angle_deg"] = f"default: {why}"


#: The goal check's tolerance (degrees) at least: the angle a reached goal's sensed contact vector
#: may turn from the demonstration's end one through the cable's and the scene's variation alone
#: (measured on peg_in_hole: reached 0.5-3 deg, the tip on the hole block's top 14-16 deg).
GOAL_MIN_TOLERANCE_DEG = 6.0
#: Where (s from its start) a demonstration's cable hangs free and settled, its weight sensed.
FREE_WINDOW_S = (0.2, 0.4)
#: The time (s) a sensed contact vector of the goal check is averaged over.
GOAL_SENSE_S = 0.2
#: An environment share of the sensed force below this (N) is no contact: no direction.
GOAL_MIN_CONTACT_N = 0.01


def goal_tolerance_deg(
    wrench: WrenchSeries, t_goal: float, *, skip_s: float = 0.2, step_s: float = 0.05, quantile: float = 0.9
) -> float | None:
    """The goal check's tolerance (degrees) of a program whose demonstration entered its goal
    situation at ``t_goal`` (s): how far the contact vector the demonstration itself sensed turned
    while it held its goal. The contact vector is the mean force over :data:`GOAL_SENSE_S` minus the
    cable's weight as sensed over :data:`FREE_WINDOW_S`; every window from ``skip_s`` after the entry
    (the entry still rings) on, ``step_s`` apart, is compared with the last one (the demonstration's
    end, what a run is compared with); the ``quantile`` of those angles (a passing jolt left out),
    at least :data:`GOAL_MIN_TOLERANCE_DEG`. None without a contact at the end (below
    :data:`GOAL_MIN_CONTACT_N`: the goal check then compares sizes) or without the free windows."""
    t = wrench.t
    if len(t) == 0:
        return None
    free = wrench.window(*FREE_WINDOW_S)
    t1 = float(t[-1])
    end = wrench.window(t1 - GOAL_SENSE_S, t1)
    if len(free) == 0 or len(end) == 0:
        return None
    weight = free.mean(axis=0)
    end_v = end.mean(axis=0) - weight
    if norm(end_v.tolist()) < GOAL_MIN_CONTACT_N:
        return None
    angles: list[float] = []
    a = t_goal + skip_s
    while a + GOAL_SENSE_S <= t1 - GOAL_SENSE_S + 1e-9:
        rows = wrench.window(a, a + GOAL_SENSE_S)
        a += step_s
        v = rows.mean(axis=0) - weight if len(rows) else None
        if v is None or norm(v.tolist()) < GOAL_MIN_CONTACT_N:
            continue
        angles.append(angle_deg(v, end_v))
    spread = float(np.quantile(angles, quantile)) if angles else 0.0
    return round(max(GOAL_MIN_TOLERANCE_DEG, spread), 1)
