"""Physical plausibility of a simulation step: how deep the cable penetrates an obstacle and how fast
its points move, against documented bounds (docs/recordings.md, "Plausibility warnings").

A jam is an artefact, not a state: a stiff cable pushed into a narrow V can sink into the obstacle
deeper than its radius and snap out at metres per second. Nothing in the contact model sees that, so
:class:`PlausibilityMonitor` measures both every step (two small numpy reductions over arrays the step
record already holds) and reports each stretch of steps beyond a bound as one :class:`Implausible`
episode, which recordings store as a warning event (``/dlovr/warnings``).

A base module (numpy only): it reads a step record's ``points`` and ``contact_arrays`` (``dist``,
``obj``, ``names``) without importing the simulator, so readers of recordings use its values cheaply.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any, Literal

import numpy as np

PENETRATION_BOUND = 0.5
"""A cable point deeper in an obstacle than this fraction of the cable's radius is implausible
(MuJoCo's soft contacts let a resting cable sink a fraction of a millimetre)."""

SPEED_FACTOR = 3.0
"""A cable point faster than this many times what the gripper's own motion can give it (its top speed
plus its top turn rate times the cable's length, :func:`speed_bound`) is implausible."""


def speed_bound(length: float, max_speed: float, max_angular_speed: float) -> float:
    """The point-speed bound (m/s) of a cable ``length`` (m) held by a gripper of top speed
    ``max_speed`` (m/s) and turn rate ``max_angular_speed`` (rad/s): :data:`SPEED_FACTOR` times
    ``max_speed + max_angular_speed * length`` (4.35 m/s for the 0.6 m table cable at the simulator's
    0.25 m/s and 2 rad/s, 1.47 m/s for a 12 cm one). The built-in demonstrations reach at most 0.32 of
    it (the table cable turned over while it swings), so perturbed ones keep a margin."""
    return SPEED_FACTOR * (float(max_speed) + float(max_angular_speed) * float(length))

GAP_S = 0.05
"""Steps beyond a bound less than this (s) apart are one episode."""

Kind = Literal["penetration", "speed"]
_SQRT3 = 3.0**0.5


@dataclass(frozen=True)
class Implausible:
    """One episode of steps beyond a bound: ``kind``, when it began and ended (s, simulated), the
    step it began at, its peak (m of penetration or m/s of point speed), the bound (same unit), and
    where: the cable point (speed) or the obstacle (penetration) of the peak."""

    kind: Kind
    start: float
    end: float
    step: int
    peak: float
    bound: float
    where: str

    def payload(self) -> dict[str, Any]:
        """JSON-able form (recordings)."""
        return {
            "kind": self.kind, "t": self.start, "end": self.end, "step": self.step,
            "peak": self.peak, "bound": self.bound, "where": self.where,
        }  # fmt: skip

    def text(self) -> str:
        """One line for people: ``penetration 6.2 mm (bound 2.5 mm) at 1.234-1.300 s, v``."""
        if self.kind == "penetration":
            size = f"{self.peak * 1000:.1f} mm (bound {self.bound * 1000:.1f} mm)"
        else:
            size = f"{self.peak:.2f} m/s (bound {self.bound:.2f} m/s)"
        return f"{self.kind} {size} at {self.start:.3f}-{self.end:.3f} s, {self.where}"


def implausible_from_payload(p: dict[str, Any]) -> Implausible:
    """The episode of a recorded warning message (:meth:`Implausible.payload`)."""
    return Implausible(
        p["kind"], float(p["t"]), float(p["end"]), int(p["step"]), float(p["peak"]), float(p["bound"]),
        str(p["where"]),
    )  # fmt: skip


def monitor_of(sim: Any) -> PlausibilityMonitor:
    """The monitor of a :class:`dlovr.sim.Simulator` of a scene: its cable's radius and length, its time
    step and its gripper's top speeds."""
    dlo = sim.scene.dlo
    bound = speed_bound(dlo.length, sim.max_speed, sim.max_angular_speed)
    return PlausibilityMonitor(dlo.radius, float(sim.model.opt.timestep), bound)


class PlausibilityMonitor:
    """Watches a simulation's steps for penetration and point speed beyond their bounds.

    ``radius``: the cable's radius (m); ``dt``: the time step (s); ``speed``: the point-speed bound
    (m/s, :func:`speed_bound`). Call :meth:`update` with every
    :class:`dlovr.sim.StepRecord` in order; it returns the episodes that ended with that step (an
    episode ends once its quantity stayed within its bound for :data:`GAP_S`), :meth:`finish` those
    still open. ``episodes`` holds all ended ones.
    """

    def __init__(self, radius: float, dt: float, speed: float):
        self.bounds: dict[Kind, float] = {
            "penetration": PENETRATION_BOUND * float(radius), "speed": float(speed)
        }  # fmt: skip
        self.dt = float(dt)
        self._prev: np.ndarray | None = None
        self._open: dict[Kind, list[Any]] = {}
        self.episodes: list[Implausible] = []

    def measure(self, rec: Any) -> tuple[float, int, float, int]:
        """This step's deepest penetration (m, >= 0) and its obstacle index (-1: none), and its fastest
        cable point's speed (m/s, 0 at the first step) and that point's index."""
        arrays = rec.contact_arrays
        depth, obj = 0.0, -1
        if len(arrays):
            dist = arrays.dist
            i = int(np.argmin(dist))
            depth, obj = max(0.0, -float(dist[i])), int(arrays.obj[i])
        pts, prev = rec.points, self._prev
        self._prev = pts
        if prev is None or prev.shape != pts.shape:
            return depth, obj, 0.0, -1
        d = pts - prev
        sq = np.einsum("ij,ij->i", d, d)
        k = int(np.argmax(sq))
        return depth, obj, float(np.sqrt(sq[k])) / self.dt, k

    def update(self, rec: Any) -> list[Implausible]:
        """Measure step ``rec``; the episodes that ended with it. Most steps take the quick path: no
        contact deeper than its bound, and no point moved farther along any axis than the speed
        bound allows over the step divided by sqrt(3)."""
        pts, prev = rec.points, self._prev
        arrays = rec.contact_arrays
        if (
            not self._open and prev is not None and prev.shape == pts.shape
            and (not len(arrays) or -float(arrays.dist.min()) <= self.bounds["penetration"])
            and float(np.abs(pts - prev).max()) * _SQRT3 <= self.bounds["speed"] * self.dt
        ):  # fmt: skip
            self._prev = pts
            return []
        depth, obj, speed, point = self.measure(rec)
        t, step = float(rec.time), int(rec.step)
        names = rec.contact_arrays.names[0] if obj >= 0 else ()
        where: dict[Kind, str] = {
            "penetration": names[obj] if 0 <= obj < len(names) else "", "speed": f"point {point}"
        }  # fmt: skip
        ended = []
        measured: tuple[tuple[Kind, float], ...] = (("penetration", depth), ("speed", speed))
        for kind, value in measured:
            ep = self._open.get(kind)
            if value > self.bounds[kind]:
                if ep is None:
                    self._open[kind] = [t, t, step, value, where[kind]]
                else:
                    ep[1] = t
                    if value > ep[3]:
                        ep[3], ep[4] = value, where[kind]
            elif ep is not None and t - ep[1] >= GAP_S:
                ended.append(self._close(kind))
        return ended

    def _close(self, kind: Kind) -> Implausible:
        start, end, step, peak, where = self._open.pop(kind)
        ep = Implausible(kind, start, end, step, peak, self.bounds[kind], where)
        self.episodes.append(ep)
        return ep

    def finish(self) -> list[Implausible]:
        """End the episodes still open (the run ended); return them."""
        return [self._close(k) for k in list(self._open)]
