"""A person-like demonstrator: a script played with the motion of a human hand (docs/people.md).

An engineered script moves the gripper along straight legs at constant speed, exactly. A person at a
mouse, at the keys or at a 6-DoF device moves along what they mean, plus

- **drift**: a slow wandering of position and orientation (below about 1 Hz): each coordinate (m) and
  each rotation axis (degrees) is a sum of :data:`DRIFT_COMPONENTS` sinusoids of random frequency in
  :attr:`PersonMotion.drift_band_hz` and random phase, scaled to an RMS of ``drift_m`` / ``drift_deg``;
- **tremor**: physiological tremor, a few tenths of a millimetre at 8-12 Hz: per coordinate one
  sinusoid of frequency drawn from :attr:`PersonMotion.tremor_band_hz`, peak ``tremor_m``, its
  amplitude swelling and fading by 30 % at a fraction of a hertz;
- **pace**: every move (the legs between two holds of the script) is made ``f`` times as long, ``f``
  drawn uniformly from :attr:`PersonMotion.pace`, its holds too;
- **easing**: a move starts and ends at rest: the script's progress through the move follows the
  minimum-jerk profile ``10 s^3 - 15 s^4 + 6 s^5`` (Flash & Hogan 1985, human reaching), blended
  with the script's constant speed by ``ease`` (0: the script's speed, 1: minimum jerk);
- **hesitation**: before every move a pause drawn uniformly from ``[0, hesitate_s]`` s;
- **key jog** (``jog_m`` > 0): the browser's jog keys (5 mm a press, :data:`dlovr.ui.JOG_STEP`) held
  down repeat at ``jog_hz``; the position target moves one key step along one axis at a time toward
  where the hand means to be (drift and tremor included: a person's aim wanders too), the orientation
  as the gizmo's rings move it (continuously).

Drift and tremor fade in over the first :data:`FADE_IN_S` s, so the demonstration starts from the
scene's gripper pose as the script does. Every random draw comes from a generator seeded with
``(seed, trial)`` (and a constant for the demonstrator): the same trial is the same demonstration,
bit for bit. Frames: positions m and quaternions wxyz in the world frame; rotations are applied in
the world frame about the gripper's origin.
"""

from __future__ import annotations

import bisect
import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field, fields, replace
from typing import Any

import numpy as np

from dlovr.transforms import quat_mul, quat_normalize, rotvec_to_quat

#: Sinusoids per drift channel.
DRIFT_COMPONENTS = 5
#: Seconds over which drift and tremor grow from nothing to their full size.
FADE_IN_S = 1.0
#: The demonstrator's own seed word (so that its draws differ from the scene perturbations').
_SEED_WORD = 0x9E12_50A1


@dataclass(frozen=True)
class PersonMotion:
    """How a person's hand departs from the script (module docstring): ``drift_m`` (RMS, m, per
    coordinate) and ``drift_deg`` (RMS, degrees, per rotation axis) of the slow drift with frequencies
    in ``drift_band_hz``; ``tremor_m`` (peak, m) in ``tremor_band_hz``; the ``pace`` factor range of a
    move's duration; ``ease`` (0..1) of the minimum-jerk profile; ``hesitate_s`` (s), the longest pause
    before a move; ``jog_m`` (m, 0: no jogging) key steps repeated at ``jog_hz``.

    The defaults are a person at a mouse-driven gizmo or a 6-DoF device doing a careful task:
    docs/people.md gives their sources."""

    drift_m: float = 0.0015
    drift_deg: float = 1.5
    drift_band_hz: tuple[float, float] = (0.05, 1.0)
    tremor_m: float = 0.0003
    tremor_band_hz: tuple[float, float] = (8.0, 12.0)
    pace: tuple[float, float] = (0.8, 1.3)
    ease: float = 1.0
    hesitate_s: float = 0.3
    jog_m: float = 0.0
    jog_hz: float = 30.0

    def __post_init__(self) -> None:
        for name in ("drift_m", "drift_deg", "tremor_m", "hesitate_s", "jog_m"):
            if not (getattr(self, name) >= 0 and math.isfinite(getattr(self, name))):
                raise ValueError(f"{name} must be a finite number >= 0, got {getattr(self, name)}")
        for name in ("drift_band_hz", "tremor_band_hz", "pace"):
            lo, hi = getattr(self, name)
            if not 0 < lo <= hi < math.inf:
                raise ValueError(f"{name} must be a range 0 < lo <= hi, got {(lo, hi)}")
        if not 0.0 <= self.ease <= 1.0:
            raise ValueError(f"ease must be in [0, 1], got {self.ease}")
        if not self.jog_hz > 0:
            raise ValueError(f"jog_hz must be > 0, got {self.jog_hz}")

    def scaled(self, s: float) -> PersonMotion:
        """This motion with drift and tremor ``s`` times as large (``s = 2``: twice the defaults')."""
        return replace(
            self, drift_m=self.drift_m * s, drift_deg=self.drift_deg * s, tremor_m=self.tremor_m * s
        )


#: ``--vary demo.KEY=...`` keys and the :class:`PersonMotion` field each sets (``person`` scales the
#: defaults' drift and tremor; ``pace`` takes a range ``A..B``; the others a number).
DEMO_KEYS: dict[str, str] = {
    "person": "",
    "drift": "drift_m",
    "turn": "drift_deg",
    "tremor": "tremor_m",
    "pace": "pace",
    "ease": "ease",
    "hesitate": "hesitate_s",
    "jog": "jog_m",
}


def motion_of(values: Mapping[str, Any]) -> PersonMotion | None:
    """The person's motion that the drawn ``--vary demo.*`` values ask for (``{"demo.drift": 0.002,
    ...}``; other keys are ignored), or None without any: ``demo.person=S`` starts from the defaults
    scaled by ``S``, any other ``demo.*`` key from the defaults, and sets its field."""
    demo = {k.split(".", 1)[1]: v for k, v in values.items() if k.startswith("demo.")}
    if not demo:
        return None
    m = PersonMotion().scaled(float(demo.get("person", 1.0)))
    names = {f.name for f in fields(PersonMotion)}
    for key, value in demo.items():
        attr = DEMO_KEYS.get(key, "")
        if attr in names:
            v = tuple(float(x) for x in value) if isinstance(value, list | tuple) else float(value)
            m = replace(m, **{attr: v})
    return m


@dataclass(frozen=True)
class _Move:
    """One move of the person's timeline: from person time ``t0`` the script's time runs from ``tau0``
    over ``duration`` (s, the person's) through ``span`` s of the script; a pause (``span`` 0) holds."""

    t0: float
    tau0: float
    duration: float
    span: float


def _min_jerk(s: float) -> float:
    return s * s * s * (10.0 - 15.0 * s + 6.0 * s * s)


@dataclass(frozen=True)
class PersonScript:
    """``script`` (a :class:`dlovr.script.Script`) as a person demonstrates it with ``motion``; trial
    ``trial`` of ``seed`` (deterministic). It plays wherever a script does (``Simulator.run``):
    :attr:`total_duration` and :meth:`plan`."""

    script: Any
    motion: PersonMotion
    seed: int = 0
    trial: int = 0
    _moves: tuple[_Move, ...] = field(init=False, repr=False, compare=False)
    _starts: tuple[float, ...] = field(init=False, repr=False, compare=False)

    def __post_init__(self) -> None:
        object.__setattr__(self, "_moves", self._timeline())
        object.__setattr__(self, "_starts", tuple(mv.t0 for mv in self._moves))

    @property
    def source(self) -> str:
        return str(getattr(self.script, "source", "<script>"))

    @property
    def scene(self) -> str | None:
        return getattr(self.script, "scene", None)

    @property
    def total_duration(self) -> float:
        last = self._moves[-1]
        return last.t0 + last.duration

    def _rng(self, word: int) -> np.random.Generator:
        return np.random.default_rng([int(self.seed) & 0xFFFFFFFF, int(self.trial), _SEED_WORD, word])

    def _timeline(self) -> tuple[_Move, ...]:
        """The person's moves and pauses: the script's legs grouped into moves (split at holds), each
        after a hesitation and at its own pace, its hold scaled by the same pace."""
        rng, m = self._rng(1), self.motion
        out: list[_Move] = []
        t = tau = 0.0
        span = 0.0
        wps = list(self.script.waypoints)
        for i, w in enumerate(wps):
            span += w.duration
            if w.hold <= 0.0 and i + 1 < len(wps):
                continue
            f = float(rng.uniform(*m.pace))
            pause = float(rng.uniform(0.0, m.hesitate_s)) if m.hesitate_s > 0 else 0.0
            if pause > 0:
                out.append(_Move(t, tau, pause, 0.0))
                t += pause
            out.append(_Move(t, tau, f * span, span))
            t, tau = t + f * span, tau + span
            if w.hold > 0:
                out.append(_Move(t, tau, f * w.hold, 0.0))
                t, tau = t + f * w.hold, tau + w.hold
            span = 0.0
        return tuple(out)

    def script_time(self, t: float) -> float:
        """The script's time (s) the person's intended pose at ``t`` (s) corresponds to."""
        moves = self._moves
        j = max(bisect.bisect_right(self._starts, t) - 1, 0)
        mv = moves[j]
        if mv.span == 0.0:
            return mv.tau0
        s = min(max((t - mv.t0) / mv.duration, 0.0), 1.0)
        e = self.motion.ease
        return mv.tau0 + mv.span * ((1.0 - e) * s + e * _min_jerk(s))

    def plan(
        self, start_pos: Sequence[float] | None = None, start_quat: Sequence[float] | None = None
    ) -> Any:
        """The person's pose targets from a start pose (as :meth:`dlovr.script.Script.plan`)."""
        return PersonPlan(self, self.script.plan(start_pos, start_quat), _Hand.draw(self))


@dataclass(frozen=True)
class _Hand:
    """The random parts of one demonstration: drift (6 channels of sinusoids: frequency Hz, amplitude,
    phase) and tremor (3 channels: frequency, peak m, phase; swell frequency, phase)."""

    drift: tuple[tuple[tuple[float, float, float], ...], ...]
    tremor: tuple[tuple[float, float, float, float, float], ...]

    @classmethod
    def draw(cls, person: PersonScript) -> _Hand:
        m, rng = person.motion, person._rng(2)
        drift = []
        for ch in range(6):
            rms = m.drift_m if ch < 3 else math.radians(m.drift_deg)
            lo, hi = m.drift_band_hz
            f = np.exp(rng.uniform(math.log(lo), math.log(hi), DRIFT_COMPONENTS))
            a = rng.uniform(0.5, 1.0, DRIFT_COMPONENTS)
            a = a * rms / math.sqrt(float((a * a).sum()) / 2.0)  # RMS of a sum of sinusoids
            ph = rng.uniform(0.0, 2 * math.pi, DRIFT_COMPONENTS)
            drift.append(tuple((float(x), float(y), float(z)) for x, y, z in zip(f, a, ph, strict=True)))
        tremor = []
        for _ in range(3):
            f = float(rng.uniform(*m.tremor_band_hz))
            tremor.append((f, m.tremor_m, float(rng.uniform(0, 2 * math.pi)), float(rng.uniform(0.1, 0.5)),
                           float(rng.uniform(0, 2 * math.pi))))
        return cls(tuple(drift), tuple(tremor))

    def offset(self, t: float) -> tuple[list[float], list[float]]:
        """Drift plus tremor at ``t`` (s): the position offset (m) and the rotation vector (rad)."""
        fade = _min_jerk(min(max(t / FADE_IN_S, 0.0), 1.0))
        two_pi = 2.0 * math.pi
        d = [fade * sum(a * math.sin(two_pi * f * t + ph) for f, a, ph in ch) for ch in self.drift]
        for i, (f, a, ph, fs, phs) in enumerate(self.tremor):
            d[i] += fade * a * (1.0 + 0.3 * math.sin(two_pi * fs * t + phs)) * math.sin(two_pi * f * t + ph)
        return d[:3], d[3:]


@dataclass(frozen=True, eq=False)
class PersonPlan:
    """A person's pose targets over time (what :meth:`dlovr.script.Plan.at` gives for a script)."""

    person: PersonScript
    base: Any
    hand: _Hand
    _jog: tuple[np.ndarray, float] | None = field(default=None, init=False)

    def __post_init__(self) -> None:
        if self.person.motion.jog_m > 0:
            object.__setattr__(self, "_jog", (self._jog_track(), 1.0 / self.person.motion.jog_hz))

    def intended(self, t: float) -> tuple[np.ndarray, np.ndarray]:
        """Where the hand means to be at ``t`` (s): the script's pose at the person's pace, with drift
        and tremor (pos m, quat wxyz; world)."""
        pos, quat = self.base.at(self.person.script_time(t))
        dp, dr = self.hand.offset(t)
        q = quat_normalize(quat_mul(rotvec_to_quat(dr), quat))
        return pos + np.array(dp), np.asarray(q, dtype=float)

    def _jog_track(self) -> np.ndarray:
        """The jogged position target at every key repeat (k, 3): one key step along the axis the aim
        is farthest from, when that is more than half a step."""
        m = self.person.motion
        n = math.ceil(self.person.total_duration * m.jog_hz) + 1
        out = np.zeros((n, 3))
        cur = self.base.at(0.0)[0].copy()
        for k in range(n):
            aim = self.intended(k / m.jog_hz)[0]
            gap = aim - cur
            i = int(np.argmax(np.abs(gap)))
            if abs(gap[i]) > 0.5 * m.jog_m:
                cur[i] += math.copysign(m.jog_m, gap[i])
            out[k] = cur
        return out

    def at(self, t: float) -> tuple[np.ndarray, np.ndarray]:
        """The gripper target (pos m, quat wxyz; world) at ``t`` s."""
        pos, quat = self.intended(t)
        if self._jog is not None:
            track, period = self._jog
            pos = track[min(int(t / period), len(track) - 1)].copy()
        return pos, quat
