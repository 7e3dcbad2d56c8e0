"""Scripted demonstrations: gripper waypoints in a TOML file (pure Python + numpy).

Format::

    scene = "peg_in_hole"         # default scene: a built-in name, or a path relative to this file
    [[waypoints]]
    pos = [0.1, 0.0, 0.75]        # m, world
    quat = [1, 0, 0, 0]           # optional, wxyz (default: keep the previous orientation)
    duration = 1.5                # s to get here from the previous waypoint (> 0)
    hold = 0.2                    # optional s to wait here (>= 0)

The first waypoint is reached from the gripper's start pose (the scene's gripper pose, or whatever
pose the simulator is in) over its ``duration``. Between waypoints the position is interpolated
linearly and the orientation by slerp. Bad files raise :class:`ScriptError` with a one-line message
naming the file, the waypoint and the key.

Limits (:data:`dlovr.inputs.LIMITS`): at most ``script_waypoints`` waypoints and
``script_duration_s`` seconds in all (moves and holds), so that no script runs for hours.
"""

from __future__ import annotations

import bisect
import math
import re
from collections.abc import Sequence
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any

import numpy as np

from dlovr.inputs import LIMITS, Fields, InputError, read_toml
from dlovr.transforms import quat_normalize, slerp

_TOP_KEYS = {"scene", "waypoints", "description"}
_WP_KEYS = {"pos", "quat", "duration", "hold", "note"}


class ScriptError(InputError):
    """A script file is invalid; the message is one line: ``file: waypoints[i].key: what is wrong``."""


# -- scripts ----------------------------------------------------------------------------------------


@dataclass(frozen=True)
class Waypoint:
    pos: tuple[float, float, float]
    quat: tuple[float, float, float, float] | None
    duration: float
    hold: float = 0.0


@dataclass(frozen=True)
class Script:
    """A demonstration script. ``scene``: the default scene name (or None)."""

    waypoints: tuple[Waypoint, ...]
    scene: str | None = None
    source: str = "<script>"

    @property
    def total_duration(self) -> float:
        return float(sum(w.duration + w.hold for w in self.waypoints))

    def target_at(
        self,
        t: float,
        start_pos: Sequence[float] | None = None,
        start_quat: Sequence[float] | None = None,
    ) -> tuple[np.ndarray, np.ndarray]:
        """Gripper target (pos, quat wxyz) at time ``t`` s after the script starts.

        Without a start pose the first waypoint is the start (held until it is "reached").
        Before 0 the start pose, after the end the last waypoint. For many calls from one start pose
        build the :meth:`plan` once.
        """
        return self.plan(start_pos, start_quat).at(t)

    def plan(
        self, start_pos: Sequence[float] | None = None, start_quat: Sequence[float] | None = None
    ) -> Plan:
        """The script's legs from a start pose (see :meth:`target_at`), precomputed for lookups."""
        w0 = self.waypoints[0]
        p_prev = np.asarray(start_pos if start_pos is not None else w0.pos, dtype=float).copy()
        if start_quat is not None:
            q_prev = quat_normalize(start_quat)
        else:
            q_prev = quat_normalize(w0.quat if w0.quat is not None else (1.0, 0.0, 0.0, 0.0))
        ends: list[float] = []
        legs: list[_Leg] = []
        tc = 0.0
        for w in self.waypoints:
            p = np.asarray(w.pos, dtype=float)
            q = q_prev if w.quat is None else quat_normalize(w.quat)
            legs.append(_Leg(tc, w.duration, p_prev, p, q_prev, q))
            tc += w.duration
            ends.append(tc)  # the move ends (its hold starts) here
            tc += w.hold
            ends.append(tc)
            p_prev, q_prev = p, q
        return Plan(tuple(ends), tuple(legs))


@dataclass(frozen=True)
class _Leg:
    """The move to one waypoint: from ``(p0, q0)`` at ``t0`` s to ``(p1, q1)`` over ``duration`` s."""

    t0: float
    duration: float
    p0: np.ndarray
    p1: np.ndarray
    q0: np.ndarray
    q1: np.ndarray


@dataclass(frozen=True, eq=False)
class Plan:
    """A script's legs from one start pose, for O(log n) lookups of the gripper target.

    ``ends``: the times (s) at which each waypoint's move and then its hold end, in order; ``legs``:
    one per waypoint (a script has at least one). Before 0 the first leg's start pose holds, after the
    last end the last waypoint.
    """

    ends: tuple[float, ...]
    legs: tuple[_Leg, ...]

    def at(self, t: float) -> tuple[np.ndarray, np.ndarray]:
        """Gripper target (pos m world, quat wxyz; fresh arrays) at time ``t`` s (see Script.target_at)."""
        if t <= 0.0:
            first = self.legs[0]
            return first.p0.copy(), first.q0.copy()
        j = bisect.bisect_right(self.ends, t)  # the first phase that ends after t
        leg = self.legs[j // 2] if j < len(self.ends) else self.legs[-1]
        if j % 2 or j == len(self.ends):  # holding at the waypoint, or past the last one
            return leg.p1.copy(), leg.q1.copy()
        s = (t - leg.t0) / leg.duration
        return leg.p0 + s * (leg.p1 - leg.p0), slerp(leg.q0, leg.q1, s)


def parse_script(data: dict[str, Any], source: str = "<script>") -> Script:
    """Validate a parsed TOML table as a script; every problem is a :class:`ScriptError`,
    ``<source>: <where>: <problem>``."""
    f = Fields(source, ScriptError)
    f.table(data, "", _TOP_KEYS)
    scene = data.get("scene")
    if scene is not None and (not isinstance(scene, str) or not scene):
        raise f.err("scene", f"must be a scene name or path (a non-empty string), got {scene!r}")
    wps = f.require(data, "waypoints")
    if not isinstance(wps, list) or not wps:
        raise f.err("waypoints", "must be at least one [[waypoints]] table")
    f.at_most(len(wps), "script_waypoints", "waypoints", "waypoints")
    out = [_waypoint(f, w, f"waypoints[{i}]") for i, w in enumerate(wps)]
    total = sum(w.duration + w.hold for w in out)
    if total > LIMITS["script_duration_s"]:
        raise f.err(
            "waypoints",
            f"the script lasts {total:.6g} s (durations and holds), "
            f"at most {LIMITS['script_duration_s']:g} s allowed",
        )
    return Script(waypoints=tuple(out), scene=scene, source=source)


def _waypoint(f: Fields, raw: Any, where: str) -> Waypoint:
    """One ``[[waypoints]]`` table: pos (m, world), optional quat (wxyz), duration and hold (s)."""
    w = f.table(raw, where, _WP_KEYS)
    for key in ("pos", "duration"):
        f.require(w, key, where)
    x, y, z = f.vec(w["pos"], f"{where}.pos", 3)
    quat = None
    if "quat" in w:
        q = f.vec(w["quat"], f"{where}.quat", 4)
        if math.sqrt(sum(c * c for c in q)) < 1e-9:
            raise f.err(f"{where}.quat", "must not be all zeros")
        qw, qx, qy, qz = (float(c) for c in quat_normalize(q))
        quat = (qw, qx, qy, qz)
    duration = f.number(w["duration"], f"{where}.duration", positive=True)
    hold = f.number(w.get("hold", 0.0), f"{where}.hold", nonneg=True)
    return Waypoint(pos=(x, y, z), quat=quat, duration=duration, hold=hold)


def _is_scene_name(ref: str) -> bool:
    """A built-in scene's name (``peg_in_hole``), not a path (``my_scene.toml``, ``../x.toml``)."""
    return re.fullmatch(r"[A-Za-z_][A-Za-z0-9_\-]*", ref) is not None


def load_script(path: str | Path) -> Script:
    """Read and validate a script file. Raises :class:`ScriptError` (one line) on any problem.

    A ``scene`` that is a path (not a built-in scene's name) is taken relative to the script's folder.
    """
    p = Path(path)
    script = parse_script(read_toml(p, ScriptError, "script file"), str(p))
    if script.scene is not None and not _is_scene_name(script.scene):
        script = replace(script, scene=str(p.parent / Path(script.scene).expanduser()))
    return script
