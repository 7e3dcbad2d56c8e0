"""Force-based detection of contact-state transitions, one detector per class (paper §V.B; docs/model.md).

Pure numpy. A detector watches the wrench a wrist sensor at the gripper reads (force N and torque
N m, world frame, one sample per simulation step) while a macro's guarded motion runs, and says
when the transition the macro expects has happened. It never sees the contact model: what it knows
of the transition is what the program carries -- the class, the contact vectors of the principal
contacts that end and begin (unit, world frame, eq. 2: the direction in which the environment
blocks the cable, so the environment pushes the cable along ``-v``), and the detection parameters.

Sign convention: the sensed force is the force the cable exerts on the gripper. In a static
situation it is the cable's weight plus the forces the environment exerts on the cable, so a contact
that begins adds about ``-v * F`` to it and one that ends removes that (adds ``+v * F``).

- ``E`` (``force_along_contact_vector``): the force rises, from the lowest it has been since the
  macro started, by at least ``force_threshold_n`` along ``-v`` of a contact that begins (or ``+v``
  of one that ends; along either sign of the axis of a pinch, whose ``v`` is zero), the rise within
  ``max_angle_deg`` of that direction;
- ``C`` (``force_direction_turn``): the contact force turns from the old contact vector to the new
  one: the change points along ``v_old - v_new`` (within ``max_angle_deg``) and reaches
  ``min_turn_fraction`` of the turn of a force of the size sensed at the start;
- ``T`` (``force_rise_then_change``): the force first rises by ``rise_n`` (the cable bends against
  the contact), then its change turns by ``max_angle_deg`` from the direction it rose in or falls
  back to half of it;
- ``I`` (``force_enters_instable_vector``): the change of force enters the cone of ``max_angle_deg``
  about ``-v`` of the instable contact that begins, with at least ``min_force_n``;
- ``S`` (``force_jump``): the force jumps by ``jump_n`` within ``window_s`` (needs a sampling rate of
  ``min_rate_hz`` or more: a spontaneous transition is over in a few milliseconds).

Reference: by default a detector measures the change of force from the first sample of the macro.
With ``ref_lag_s`` > 0 (the compiler derives it: the time scale over which it measured the
demonstrated step) the reference slides: the change is measured from the force ``ref_lag_s`` before
the current sample (the first sample until then), so a slow drift of the force while the gripper
moves is not taken for a transition, while a transition's step, quick on that scale, is. Where the
program gives no contact vector for a ``C`` or ``I`` detector, ``dir_x``, ``dir_y``, ``dir_z`` (the
demonstrated step's direction, unit, world frame) stand in for it.

Shared signal conditioning: :class:`NoiseModel` (optional Gaussian sensor noise) and
:class:`LowPass` (first-order low-pass filter, time constant ``filter_tau_s``), applied by
:class:`WrenchConditioner` before the detectors see the samples. Parameters missing from a program
take the defaults of :data:`DEFAULTS`.
"""

from __future__ import annotations

import math
from collections.abc import Iterable, Mapping, Sequence
from dataclasses import dataclass, field

import numpy as np

from dlovr.transforms import angle_deg, dot, norm, unit

#: Default parameters per class (forces N, angles degrees, times s, rates Hz).
DEFAULTS: dict[str, dict[str, float]] = {
    "E": {"force_threshold_n": 0.5, "max_angle_deg": 30.0},
    "C": {"min_turn_fraction": 0.5, "max_angle_deg": 20.0},
    "T": {"rise_n": 0.5, "max_angle_deg": 20.0},
    "I": {"max_angle_deg": 15.0, "min_force_n": 0.05},
    "S": {"jump_n": 0.5, "min_rate_hz": 500.0, "window_s": 0.01},
}
ALGORITHMS = {
    "E": "force_along_contact_vector",
    "C": "force_direction_turn",
    "T": "force_rise_then_change",
    "I": "force_enters_instable_vector",
    "S": "force_jump",
}
#: A direction (contact vector, axis, step; any unit) shorter than this has none to watch.
_NO_DIRECTION = 1e-12
#: Time constant (s) of the shared low-pass filter when the program gives none.
DEFAULT_FILTER_TAU_S = 0.004
#: Ratio of torque noise (N m) to force noise (N) of :class:`NoiseModel` (a lever of 5 cm).
TORQUE_NOISE_LEVER_M = 0.05


# --------------------------------------------------------------------------------------------------
# Signal conditioning


@dataclass
class LowPass:
    """First-order low-pass filter of a vector signal: ``y += (x - y) * dt / (tau + dt)``.

    ``tau`` (s) 0 passes the signal through. The first sample initialises the output.
    """

    tau: float
    _y: np.ndarray | None = field(default=None, init=False, repr=False)

    def __post_init__(self) -> None:
        if not self.tau >= 0.0:
            raise ValueError(f"filter time constant must be >= 0 s, got {self.tau}")

    def reset(self) -> None:
        self._y = None

    def __call__(self, x: np.ndarray, dt: float) -> np.ndarray:
        x = np.asarray(x, dtype=float)
        y = self._y
        if y is None or self.tau == 0.0:
            self._y = x.copy()
        elif x.ndim == 1 and self.running(len(x)):  # every step: in Python floats, numpy's roundings
            return np.array(self.step(x.tolist(), dt))
        else:
            self._y = y + (x - y) * (dt / (self.tau + dt))
        return self._y.copy()

    def running(self, n: int) -> bool:
        """Whether the next sample of ``n`` values takes :meth:`step`: the filter has started on
        samples of that many and smooths."""
        y = self._y
        return y is not None and self.tau != 0.0 and y.shape == (n,)

    def step(self, x: list[float], dt: float) -> list[float]:
        """:meth:`__call__` on Python floats where the filter is :meth:`running` (the same values),
        without the arrays: for the sensor chain's every step."""
        assert self._y is not None
        k = dt / (self.tau + dt)  # the array expression's roundings, element by element
        out = [a + (b - a) * k for a, b in zip(self._y.tolist(), x, strict=True)]
        self._y = np.array(out)
        return out


@dataclass
class NoiseModel:
    """A wrist force/torque sensor's errors (docs/programs.md, "The sensor"), drawn from ``seed``:

    - white noise: ``force_std`` (N) on each force component of every sample, ``torque_std`` (N m)
      on each torque component (default ``force_std *`` :data:`TORQUE_NOISE_LEVER_M`);
    - bias drift: a random walk of the force bias, ``drift`` N per square root of a second on each
      component (``dt`` s between samples; 0: none);
    - quantisation: the force read in steps of ``quantum`` N (0: none).

    The sensor's bandwidth is the low-pass filter of :class:`WrenchConditioner`. ``dlovr run --noise``
    simulates the white noise only.
    """

    force_std: float = 0.0
    torque_std: float | None = None
    seed: int = 0
    drift: float = 0.0
    quantum: float = 0.0
    dt: float = 0.002

    def __post_init__(self) -> None:
        if not self.force_std >= 0.0 or (self.torque_std is not None and not self.torque_std >= 0.0):
            raise ValueError("noise standard deviations must be >= 0")
        if not (self.drift >= 0.0 and self.quantum >= 0.0 and self.dt > 0.0):
            raise ValueError("drift and quantum must be >= 0, dt > 0")
        self._rng = np.random.default_rng(self.seed)
        self._bias = np.zeros(3)

    def __call__(self, force: np.ndarray, torque: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        if self.force_std == 0.0 and not self.torque_std and self.drift == 0.0 and self.quantum == 0.0:
            return np.asarray(force, float), np.asarray(torque, float)
        ts = self.force_std * TORQUE_NOISE_LEVER_M if self.torque_std is None else self.torque_std
        n = self._rng.standard_normal(6)
        f = np.asarray(force, float) + self.force_std * n[:3]
        if self.drift > 0.0:
            self._bias = self._bias + self.drift * math.sqrt(self.dt) * self._rng.standard_normal(3)
            f = f + self._bias
        if self.quantum > 0.0:
            f = np.round(f / self.quantum) * self.quantum
        return f, np.asarray(torque, float) + ts * n[3:]


@dataclass
class WrenchConditioner:
    """Noise, then the low-pass filter, on the raw wrench: what the detectors see."""

    noise: NoiseModel = field(default_factory=NoiseModel)
    tau: float = DEFAULT_FILTER_TAU_S

    def __post_init__(self) -> None:
        self._filter = LowPass(self.tau)

    def __call__(self, force: np.ndarray, torque: np.ndarray, dt: float) -> tuple[np.ndarray, np.ndarray]:
        f, t = self.noise(force, torque)
        lp = self._filter
        if f.shape != (3,) or t.shape != (3,) or not lp.running(6):
            y = lp(np.concatenate([f, t]), dt)
            return y[:3], y[3:]
        out = lp.step(f.tolist() + t.tolist(), dt)  # every step: what lp(...) does
        return np.array(out[:3]), np.array(out[3:])


# --------------------------------------------------------------------------------------------------
# Detectors


def _step_dir(params: Mapping[str, float]) -> np.ndarray | None:
    """The demonstrated step's direction the program carries (``dir_x``, ``dir_y``, ``dir_z``), if any."""
    if not all(k in params for k in ("dir_x", "dir_y", "dir_z")):
        return None
    return unit([params["dir_x"], params["dir_y"], params["dir_z"]], _NO_DIRECTION)


@dataclass(frozen=True)
class Expectation:
    """What a detector knows of the transition: the contact vectors (unit, world) of the principal
    contacts that end (``released``) and begin (``established``); ``None`` entries have no vector.
    ``axes``: the pinch axes (unit, world) of those contacts that are pinches (zero vector, the DLO
    clamped between opposite faces, docs/model.md): the force changes along that line, either sign."""

    released: tuple[tuple[float, float, float] | None, ...] = ()
    established: tuple[tuple[float, float, float] | None, ...] = ()
    axes: tuple[tuple[float, float, float], ...] = ()


class Detector:
    """Base of the detectors: :meth:`start` with the first sample of a macro, then :meth:`update`
    with every later one; ``update`` returns True once the transition is detected (and keeps
    returning True). ``signal``: how far the detection criterion is met (1 = fires), for display.

    With ``smooth_s`` > 0 (:func:`for_sensor`: a noisy sensor) the detector low-passes the force it
    is given once more (first order, that time constant) before measuring its change; ``start`` then
    takes the samples before the first (``history``: (time s, force N) pairs, oldest first) to
    settle that filter, so that its reference is no single noisy sample.

    Every sample's arithmetic runs on the force's three components as Python floats (lists), with
    numpy's roundings: element by element, and a sum of products ``(a * b).sum()`` as :func:`dot`
    (from 0.0, left to right), so that the detectors cost no small arrays per step."""

    cls = "?"

    def __init__(self, params: Mapping[str, float], expect: Expectation):
        self.params = {**DEFAULTS[self.cls], **{k: float(v) for k, v in params.items()}}
        self.expect = expect
        self.fired_at: float | None = None
        self.signal = 0.0
        self._f0 = [0.0, 0.0, 0.0]
        self.lag = float(self.params.get("ref_lag_s", 0.0))
        self.smooth = float(self.params.get("smooth_s", 0.0))
        self._hist: list[tuple[float, list[float]]] = []
        self._ema: tuple[float, list[float]] | None = None

    def smoothing_lag(self) -> float:
        """How much later (s) the detector's own smoothing makes it fire than without it: its time
        constant ``smooth_s`` (the delay of a first-order low-pass on a ramp; 0 without smoothing)."""
        return self.smooth

    def _smoothed(self, t: float, f: list[float]) -> list[float]:
        """``f`` through the detector's own low-pass filter (``f`` itself without one)."""
        if self.smooth <= 0.0:
            return f
        if self._ema is None:
            self._ema = (t, list(f))
        else:
            t_last, y = self._ema
            dt = max(t - t_last, 0.0)
            k = dt / (self.smooth + dt)  # y + (f - y) * k, element by element
            self._ema = (t, [a + (b - a) * k for a, b in zip(y, f, strict=True)])
        return list(self._ema[1])

    def start(
        self, t: float, force: np.ndarray, torque: np.ndarray,
        history: Sequence[tuple[float, np.ndarray]] = (),
    ) -> None:
        self._ema = None
        if self.smooth > 0.0:
            for th, fh in history:
                if th < t:
                    self._smoothed(float(th), _floats(fh))
        self._f0 = self._smoothed(t, _floats(force))
        self._hist = [(t, list(self._f0))]
        self.fired_at = None
        self.signal = 0.0

    def _reference(self, t: float, f: list[float]) -> list[float]:
        """The force the change is measured from: the first sample, or with ``ref_lag_s`` the latest
        sample at least that long ago (the first one until then)."""
        if self.lag <= 0.0:
            return self._f0
        h = self._hist
        h.append((t, f))
        while len(h) > 1 and h[1][0] <= t - self.lag + 1e-12:
            h.pop(0)
        return h[0][1]

    def update(self, t: float, force: np.ndarray, torque: np.ndarray) -> bool:
        if self.fired_at is not None:
            return True
        f = self._smoothed(t, _floats(force))
        r = self._reference(t, f)
        self.signal = self._signal(t, [f[0] - r[0], f[1] - r[1], f[2] - r[2]])
        if self.signal >= 1.0:
            self.fired_at = t
        return self.fired_at is not None

    def _signal(self, t: float, df: list[float]) -> float:  # pragma: no cover - abstract
        """How far the criterion is met by the change of force ``df`` (N, world, Python floats)."""
        raise NotImplementedError


def _floats(v: np.ndarray | Sequence[float]) -> list[float]:
    """A force sample's components as a new list of Python floats (numpy's float64 values)."""
    return np.asarray(v, dtype=float).tolist()


class EDetector(Detector):
    """``E``: the force changes along ``-v`` of a contact that begins or ``+v`` of one that ends
    (along the line of a pinch's axis, either sign: its ``v`` is zero).

    The change is measured from the lowest the force has been along that direction since the macro
    started (not from its first sample), so a force still settling from the previous transition
    when the macro begins neither hides the step nor fakes one.
    """

    cls = "E"

    def __init__(self, params: Mapping[str, float], expect: Expectation):
        super().__init__(params, expect)
        dirs = [-np.asarray(v) for v in expect.established if v is not None]
        dirs += [np.asarray(v, float) for v in expect.released if v is not None]
        dirs += [s * np.asarray(a, float) for a in expect.axes for s in (1.0, -1.0)]  # a pinch: either sign
        self.dirs = [u for d in dirs if (u := unit(d, _NO_DIRECTION)) is not None]
        self._dirs = [u.tolist() for u in self.dirs]
        self._low: list[list[float]] = []

    def start(
        self, t: float, force: np.ndarray, torque: np.ndarray,
        history: Sequence[tuple[float, np.ndarray]] = (),
    ) -> None:
        super().start(t, force, torque, history)
        self._low = [[0.0, 0.0, 0.0] for _ in self.dirs]  # per direction: the change where it was lowest

    def _signal(self, t: float, df: list[float]) -> float:
        thr, cone = self.params["force_threshold_n"], self.params["max_angle_deg"]
        if not self._dirs:  # no vector known: any change of that size
            return norm(df) / thr
        best = 0.0
        lows = self._low
        for k, u in enumerate(self._dirs):
            if self.lag <= 0.0 and dot(df, u) < dot(lows[k], u):
                lows[k] = df  # (a sliding reference follows the force by itself; df is a new list)
            low = lows[k]
            rise = [df[0] - low[0], df[1] - low[1], df[2] - low[2]]
            along = dot(rise, u)
            if along > 0 and angle_deg(rise, u) <= cone:
                best = max(best, along / thr)
        return best


class CDetector(Detector):
    """``C``: the change of force points along ``v_old - v_new`` and reaches the set fraction of the
    turn of a force as large as the one sensed when the macro started."""

    cls = "C"

    def __init__(self, params: Mapping[str, float], expect: Expectation):
        super().__init__(params, expect)
        old = [np.asarray(v, float) for v in expect.released if v is not None]
        new = [np.asarray(v, float) for v in expect.established if v is not None]
        turn = (sum(old, np.zeros(3)) / len(old) if old else np.zeros(3)) - (
            sum(new, np.zeros(3)) / len(new) if new else np.zeros(3)
        )
        self.turn = norm(turn)
        self.dir = unit(turn, _NO_DIRECTION)
        if self.dir is None:
            self.dir = _step_dir(self.params)
        self._dir = None if self.dir is None else self.dir.tolist()
        self._scale = 0.0

    def start(
        self, t: float, force: np.ndarray, torque: np.ndarray,
        history: Sequence[tuple[float, np.ndarray]] = (),
    ) -> None:
        super().start(t, force, torque, history)
        self._scale = norm(self._f0)

    def threshold(self) -> float:
        if "force_threshold_n" in self.params:
            return self.params["force_threshold_n"]
        return max(self.params["min_turn_fraction"] * max(self.turn, 0.1) * self._scale, 1e-3)

    def _signal(self, t: float, df: list[float]) -> float:
        thr = self.threshold()
        u = self._dir
        if u is None:
            return norm(df) / thr
        along = dot(df, u)
        if along <= 0 or angle_deg(df, u) > self.params["max_angle_deg"]:
            return 0.0
        return along / thr


class TDetector(Detector):
    """``T``: a rise of the force by ``rise_n``, then a turn of its change by ``max_angle_deg`` from
    the direction it rose in, or a fall back to half of the rise."""

    cls = "T"

    def start(
        self, t: float, force: np.ndarray, torque: np.ndarray,
        history: Sequence[tuple[float, np.ndarray]] = (),
    ) -> None:
        super().start(t, force, torque, history)
        self._peak: list[float] | None = None

    def _signal(self, t: float, df: list[float]) -> float:
        rise = self.params["rise_n"]
        mag = norm(df)
        if self._peak is None:
            if mag >= rise:
                self._peak = df  # (a new list each sample)
            return 0.5 * min(mag / rise, 1.0)
        pk = norm(self._peak)
        if mag > pk and angle_deg(df, self._peak) < 0.5 * self.params["max_angle_deg"]:
            self._peak = df  # still rising the same way
            return 0.5
        turned = angle_deg(df, self._peak) / self.params["max_angle_deg"]
        fell = (pk - mag) / (0.5 * pk) if pk > 0 else 0.0
        return max(0.5, turned, fell)


class IDetector(Detector):
    """``I``: the change of force enters the cone about ``-v`` of the instable contact that begins."""

    cls = "I"

    def __init__(self, params: Mapping[str, float], expect: Expectation):
        super().__init__(params, expect)
        dirs = [unit(-np.asarray(v, float), _NO_DIRECTION) for v in expect.established if v is not None]
        self.dirs = [u for u in dirs if u is not None]
        if not self.dirs and (d := _step_dir(self.params)) is not None:
            self.dirs = [d]
        self._dirs = [u.tolist() for u in self.dirs]

    def _signal(self, t: float, df: list[float]) -> float:
        mag = norm(df)
        size = min(mag / self.params["min_force_n"], 1.0)
        if not self._dirs:  # no vector known: a change of that size
            return size
        if min(angle_deg(df, u) for u in self._dirs) > self.params["max_angle_deg"]:
            return 0.0
        return size


class SDetector(Detector):
    """``S``: the force jumps by ``jump_n`` within ``window_s``."""

    cls = "S"

    def __init__(self, params: Mapping[str, float], expect: Expectation, rate_hz: float | None = None):
        super().__init__(params, expect)
        if rate_hz is not None and rate_hz < self.params["min_rate_hz"] * (1.0 - 1e-6):
            raise ValueError(
                f"force_jump needs {self.params['min_rate_hz']:g} Hz of force samples, got {rate_hz:g} Hz"
            )
        self._hist: list[tuple[float, list[float]]] = []

    def start(
        self, t: float, force: np.ndarray, torque: np.ndarray,
        history: Sequence[tuple[float, np.ndarray]] = (),
    ) -> None:
        super().start(t, force, torque, history)
        self._hist = [(t, _floats(force))]

    def update(self, t: float, force: np.ndarray, torque: np.ndarray) -> bool:
        if self.fired_at is not None:
            return True
        f = _floats(force)
        w = self.params["window_s"]
        self._hist.append((t, f))
        while len(self._hist) > 2 and self._hist[1][0] <= t - w - 1e-12:
            self._hist.pop(0)
        f0 = self._hist[0][1]
        self.signal = norm([f[0] - f0[0], f[1] - f0[1], f[2] - f0[2]]) / self.params["jump_n"]
        if self.signal >= 1.0:
            self.fired_at = t
        return self.fired_at is not None

    def _signal(self, t: float, df: list[float]) -> float:  # pragma: no cover - update overrides
        return 0.0


# --------------------------------------------------------------------------------------------------
# Detection parameters for a noisy sensor

#: The threshold parameter of each class (the one a derivation derives from the demonstrated step).
THRESHOLD_PARAM = {"E": "force_threshold_n", "C": "force_threshold_n", "T": "rise_n",
                   "I": "min_force_n", "S": "jump_n"}


def _sensor_threshold(cls: str) -> str | None:
    """The threshold a noisy sensor raises: none for ``S`` (a jump within milliseconds, which no
    smoothing may blur) or an unknown class."""
    return None if cls == "S" else THRESHOLD_PARAM.get(cls)

#: A threshold is at least this many standard deviations of the change a detector measures.
SENSOR_K = 4.0
#: The longest smoothing (s): longer would blur a step within the detectors' 0.15 s reference.
SENSOR_MAX_SMOOTH_S = 0.06
#: A threshold above this fraction of the demonstrated step leaves no signal to trust at that noise.
SENSOR_WEAK_FRACTION = 0.8
#: The fraction of the step the derivation sets the threshold to (for programs without ``step_n``).
_DERIVED_FRACTION = 0.4


def change_std(sigma: float, dt: float, smooth_s: float) -> float:
    """Standard deviation (N) of the change a detector measures along one direction (the force now
    minus the force ``ref_lag_s`` earlier, both through a first-order low-pass of ``smooth_s``
    seconds) when the sensor adds white noise of ``sigma`` N to each component of each sample,
    ``dt`` s apart (the two samples far enough apart to be independent)."""
    return math.sqrt(2.0) * sigma * math.sqrt(dt / (2.0 * smooth_s + dt))


def for_sensor(
    cls: str, params: Mapping[str, float], sigma: float, dt: float = 0.002
) -> tuple[dict[str, float], dict[str, str]]:
    """The parameters of a ``cls`` detector for a sensor with white noise ``sigma`` (N, each force
    component of each sample, samples ``dt`` s apart), and texts for the parameters it changed.

    The threshold (derived from the expected step: its size along the direction the detector
    watches) sets the detector's own smoothing ``smooth_s``: the shortest time constant (at most
    :data:`SENSOR_MAX_SMOOTH_S`) at which :data:`SENSOR_K` standard deviations of the measured change
    (:func:`change_std`) are no more than the threshold. The threshold is then raised to at least
    those :data:`SENSOR_K` standard deviations; one above
    :data:`SENSOR_WEAK_FRACTION` of the step means the force cannot show the transition at that noise
    (the executor ends the macro by its motion). ``sensor_noise_n`` records ``sigma``. Idempotent;
    ``sigma`` 0, the ``S`` class (a jump within milliseconds) and parameters without a threshold
    are returned unchanged.
    """
    p = {k: float(v) for k, v in params.items()}
    key = _sensor_threshold(cls)
    if sigma <= 0.0 or key is None:
        return p, {}
    thr = p.get(key, DEFAULTS[cls].get(key, 0.0))
    step = p.get("step_n", thr / _DERIVED_FRACTION)
    if step <= 0.0 or thr >= step:  # no step to see: it ends by its motion anyway
        p["sensor_noise_n"] = max(p.get("sensor_noise_n", 0.0), sigma)
        return p, {"sensor_noise_n": f"derived: the sensor's white noise, {sigma:g} N"}
    tau = SENSOR_MAX_SMOOTH_S
    if thr > 0.0:  # K std of the change (change_std) at most the threshold
        r = SENSOR_K * math.sqrt(2.0) * sigma / thr
        tau = min(max(0.5 * dt * (r * r - 1.0), 0.0), SENSOR_MAX_SMOOTH_S)
    tau = max(math.ceil(tau * 1e4 - 1e-9) / 1e4, p.get("smooth_s", 0.0))  # to 0.1 ms, not below
    floor = SENSOR_K * change_std(sigma, dt, tau)
    texts = {"sensor_noise_n": f"derived: the sensor's white noise, {sigma:g} N"}
    p["sensor_noise_n"] = max(p.get("sensor_noise_n", 0.0), sigma)
    if tau > 0.0:
        p["smooth_s"] = tau
        texts["smooth_s"] = (
            f"derived: low-pass time constant at which {SENSOR_K:g} std of the measured change "
            f"({floor:.3g} N at {sigma:g} N noise) is at most the threshold (the step is {step:.3g} N)"
        )
    if floor > thr:
        p[key] = round(floor, 6)
        weak = ": weak signal at this noise" if floor > SENSOR_WEAK_FRACTION * step else ""
        texts[key] = f"derived: {SENSOR_K:g} std of the measured change at {sigma:g} N sensor noise{weak}"
    return p, texts


def sensor_weak(cls: str, params: Mapping[str, float]) -> bool:
    """Whether parameters adapted by :func:`for_sensor` leave no force signal to trust: the threshold
    is above :data:`SENSOR_WEAK_FRACTION` of the demonstrated step."""
    key = _sensor_threshold(cls)
    if key is None or "sensor_noise_n" not in params or "step_n" not in params or key not in params:
        return False
    return float(params[key]) > SENSOR_WEAK_FRACTION * float(params["step_n"])


MIN_SNR = 8.0
"""A demonstrated step smaller than this many times the noise before it is no force signal (a gradual
change, not a step a run would show again): :func:`no_force_signal`'s default in runs."""


def no_force_signal(cls: str, params: Mapping[str, float], min_snr: float = 0.0) -> bool:
    """Whether a detection has no force signal to watch, so that its macro ends by its motion: its
    threshold is not below the step its demonstration showed (``step_n``, N), or that step is less
    than ``min_snr`` times the noise seen before it (``noise_n``), or the sensor's noise leaves it
    none (:func:`sensor_weak`). False without a demonstrated step (the class's defaults)."""
    step, key = params.get("step_n"), THRESHOLD_PARAM.get(cls, "")
    if step is None:
        return False
    step = float(step)
    if step <= 0.0 or (key in params and float(params[key]) >= step) or sensor_weak(cls, params):
        return True
    return "noise_n" in params and step < min_snr * float(params["noise_n"])


_CLASSES: dict[str, type[Detector]] = {
    "E": EDetector, "C": CDetector, "T": TDetector, "I": IDetector, "S": SDetector,
}


def make_detector(
    cls: str, params: Mapping[str, float], expect: Expectation, rate_hz: float | None = None
) -> Detector:
    """The detector of class ``cls`` with the program's parameters (defaults where absent)."""
    if cls not in _CLASSES:
        raise ValueError(f"no detector for class {cls!r} (known: {', '.join(_CLASSES)})")
    if cls == "S":
        return SDetector(params, expect, rate_hz)
    return _CLASSES[cls](params, expect)


def detect(
    cls: str,
    params: Mapping[str, float],
    expect: Expectation,
    times: Sequence[float] | np.ndarray,
    forces: Iterable[Sequence[float]] | np.ndarray,
    torques: Iterable[Sequence[float]] | np.ndarray | None = None,
    conditioner: WrenchConditioner | None = None,
) -> int | None:
    """Run a detector over a whole wrench stream; the index of the sample where it fires, or None.

    ``times`` (s), ``forces`` (N) and ``torques`` (N m) per sample, world frame; ``conditioner``
    (default: the shared low-pass filter, no noise) is applied first.
    """
    t = np.asarray(times, dtype=float)
    f = np.asarray(forces, dtype=float).reshape(len(t), 3)
    tq = np.zeros_like(f) if torques is None else np.asarray(torques, dtype=float).reshape(len(t), 3)
    cond = conditioner if conditioner is not None else WrenchConditioner()
    rate = 1.0 / float(np.median(np.diff(t))) if len(t) > 1 else None
    det = make_detector(cls, params, expect, rate)
    for i in range(len(t)):
        dt = float(t[i] - t[i - 1]) if i else 0.0
        fi, ti = cond(f[i], tq[i], dt)
        if i == 0:
            det.start(float(t[i]), fi, ti)
        elif det.update(float(t[i]), fi, ti):
            return i
    return None
