"""Program generation (paper §VI, MODEL.md §5): a demonstration becomes a sequence of macros.

Pure Python + numpy. Input: the demonstration's kept contact situations with their times (see
:class:`dlovr.model.transitions.Debouncer`) and the gripper pose trajectory. Each transition that has a
class becomes a **macro**: a guarded motion of the gripper (the demonstrated displacement over that
stretch) that ends when the detection algorithm of its class sees the expected transition.

Frames and units: positions in metres and quaternions ``wxyz`` in the world frame; the relative motion
is expressed in the gripper frame at the macro's start; times in seconds; forces in newtons.
"""

from __future__ import annotations

import json
import math
from collections.abc import Sequence
from dataclasses import asdict, dataclass, field
from importlib import resources
from typing import Any

import numpy as np

from dlovr.model.discrete import DiscreteContact, DiscreteSituation
from dlovr.model.transitions import (
    CLASS_NAMES,
    classify_step,
    format_classes,
    principal,
    successional_contacts,
)
from dlovr.transforms import matrix_to_rotvec, quat_to_matrix

PROGRAM_VERSION = 1
"""Version of the program JSON format (``version`` field); bump on incompatible changes."""


@dataclass(frozen=True)
class TimedSituation:
    """A kept contact situation: when it began (s), how long it held (s), and optionally the
    topological notation it came from and the largest normal force on the cable then (N)."""

    t: float
    duration: float
    situation: DiscreteSituation
    topological: str | None = None
    force: float | None = None


@dataclass(frozen=True)
class PoseTrack:
    """Gripper pose trajectory: times ``t`` (k,), positions ``pos`` (k, 3) m, quaternions ``quat``
    (k, 4) wxyz, all world frame, times increasing."""

    t: np.ndarray
    pos: np.ndarray
    quat: np.ndarray

    def __post_init__(self) -> None:
        t, p, q = np.asarray(self.t, float), np.asarray(self.pos, float), np.asarray(self.quat, float)
        if t.ndim != 1 or p.shape != (len(t), 3) or q.shape != (len(t), 4) or len(t) == 0:
            raise ValueError("pose track needs t (k,), pos (k, 3), quat (k, 4) with k >= 1")
        if np.any(np.diff(t) < 0):
            raise ValueError("pose track times must not decrease")
        object.__setattr__(self, "t", t)
        object.__setattr__(self, "pos", p)
        object.__setattr__(self, "quat", q)

    def at(self, t: float) -> tuple[np.ndarray, np.ndarray]:
        """Pose at time ``t`` (the last sample at or before ``t``; the first one before the track)."""
        i = max(int(np.searchsorted(self.t, t, side="right")) - 1, 0)
        return self.pos[i], self.quat[i]


@dataclass(frozen=True)
class Motion:
    """The demonstrated gripper motion of one macro.

    ``world``: displacement in the world frame (m); ``relative``: the same in the gripper frame at
    the start; ``rotation``: rotation vector (rad) from the start orientation, gripper frame;
    ``duration`` s; ``start_pos``/``start_quat`` the pose where it starts (world, wxyz).
    """

    world: tuple[float, float, float]
    relative: tuple[float, float, float]
    rotation: tuple[float, float, float]
    duration: float
    start_pos: tuple[float, float, float]
    start_quat: tuple[float, float, float, float]


def motion_between(track: PoseTrack, t0: float, t1: float) -> Motion:
    p0, q0 = track.at(t0)
    p1, q1 = track.at(t1)
    r0, r1 = quat_to_matrix(q0), quat_to_matrix(q1)
    d = p1 - p0

    def tup(a: np.ndarray) -> tuple[float, ...]:
        return tuple(round(float(x), 9) + 0.0 for x in a)

    return Motion(
        tup(d), tup(r0.T @ d), tup(matrix_to_rotvec(r0.T @ r1)), round(t1 - t0, 9), tup(p0), tup(q0)
    )  # type: ignore[arg-type]


# --------------------------------------------------------------------------------------------------
# Detection algorithms, one per class (§V.B, MODEL.md §5)
# --------------------------------------------------------------------------------------------------

DETECTORS: dict[str, dict[str, Any]] = {
    "E": {
        "algorithm": "force_along_contact_vector",
        "description": "a contact force appears (or vanishes) along the expected contact vector",
        "params": {"force_threshold_n": 0.5, "max_angle_deg": 30.0},
    },
    "C": {
        "algorithm": "force_direction_turn",
        "description": "the contact force turns from the old contact vector to the new one",
        "params": {"min_turn_fraction": 0.5, "max_angle_deg": 20.0},
    },
    "T": {
        "algorithm": "force_rise_then_change",
        "description": "the force rises while the DLO bends, then its direction changes",
        "params": {"rise_n": 0.5, "max_angle_deg": 20.0},
    },
    "I": {
        "algorithm": "force_enters_instable_vector",
        "description": "the force direction enters the instable state's contact vector",
        "params": {"max_angle_deg": 15.0},
    },
    "S": {
        "algorithm": "force_jump",
        "description": "a sudden jump of the force (needs a high sensing rate)",
        "params": {"jump_n": 0.5, "min_rate_hz": 500.0},
    },
}
RISKY = frozenset({"S", "I"})


@dataclass(frozen=True)
class Detection:
    cls: str
    algorithm: str
    params: dict[str, float]


@dataclass(frozen=True)
class ContactSpec:
    """A principal contact a macro expects: its state with face names and its contact vector."""

    state: str
    vector: tuple[float, float, float] | None


@dataclass(frozen=True)
class Macro:
    index: int
    classes: tuple[str, ...]
    t: float
    from_situation: str
    to_situation: str
    from_contacts: tuple[ContactSpec, ...]
    to_contacts: tuple[ContactSpec, ...]
    motion: Motion
    detection: tuple[Detection, ...]
    risky: bool

    @property
    def label(self) -> str:
        return format_classes(self.classes)


@dataclass(frozen=True)
class Program:
    name: str
    source: str
    macros: tuple[Macro, ...]
    version: int = PROGRAM_VERSION
    summary: dict[str, int] = field(default_factory=dict)

    def to_json(self) -> dict[str, Any]:
        d = asdict(self)
        d = {"version": d.pop("version"), **d}
        return d

    def dumps(self) -> str:
        return json.dumps(self.to_json(), indent=2, sort_keys=False, ensure_ascii=False) + "\n"

    def listing(self) -> str:
        """A readable text listing of the program."""
        lines = [f"program {self.name}  (from {self.source}, format v{self.version})"]
        for m in self.macros:
            risk = "  RISKY" if m.risky else ""
            mv = m.motion
            lines.append(f"{m.index:>3}  {m.label:<4} t={m.t:8.3f}s{risk}")
            lines.append(f"       from {m.from_situation}")
            lines.append(f"       to   {m.to_situation}")
            lines.append(
                "       move {:+.4f} {:+.4f} {:+.4f} m (world) in {:.3f} s, rotate {:.1f} deg".format(
                    *mv.world, mv.duration, math.degrees(float(np.linalg.norm(mv.rotation)))
                )
            )
            for det in m.detection:
                params = ", ".join(f"{k}={v:g}" for k, v in det.params.items())
                lines.append(f"       until {det.algorithm} ({params})  [{CLASS_NAMES[det.cls]}]")
        s = self.summary
        lines.append(f"{s.get('macros', 0)} macros, {s.get('risky', 0)} risky")
        return "\n".join(lines) + "\n"


def _spec(c: DiscreteContact) -> ContactSpec:
    vec = None if c.vector is None else tuple(round(float(x), 9) + 0.0 for x in c.vector)
    return ContactSpec(c.format(), vec)  # type: ignore[arg-type]


def _principals(s: DiscreteSituation) -> tuple[ContactSpec, ...]:
    return tuple(_spec(c) for run in successional_contacts(s) for c in principal(run))


def _detection(cls: str, force: float | None) -> Detection:
    d = DETECTORS[cls]
    params = dict(d["params"])
    if force is not None and force > 0 and "force_threshold_n" in params:
        params["force_threshold_n"] = round(max(0.05, 0.5 * force), 6)  # half the demonstrated force
    return Detection(cls, d["algorithm"], params)


def compile_program(
    states: Sequence[TimedSituation], poses: PoseTrack, name: str = "program", source: str = ""
) -> Program:
    """Compile a demonstration into a program of macros (MODEL.md §5).

    Every step between consecutive kept situations that has a transition class becomes a macro;
    steps without one (``-``) extend the motion of the next macro.
    """
    macros: list[Macro] = []
    anchor = 0
    for k in range(1, len(states)):
        prev, cur = states[k - 1], states[k]
        classes = classify_step(prev.situation, cur.situation)
        if not classes:
            continue
        start = states[anchor]
        macros.append(
            Macro(
                index=len(macros) + 1,
                classes=classes,
                t=round(cur.t, 9),
                from_situation=prev.situation.format(),
                to_situation=cur.situation.format(),
                from_contacts=_principals(prev.situation),
                to_contacts=_principals(cur.situation),
                motion=motion_between(poses, start.t, cur.t),
                detection=tuple(_detection(c, cur.force if c == "E" else None) for c in classes),
                risky=bool(RISKY & set(classes)),
            )
        )
        anchor = k
    summary = {"macros": len(macros), "risky": sum(m.risky for m in macros)}
    return Program(name, source, tuple(macros), PROGRAM_VERSION, summary)


def program_schema() -> dict[str, Any]:
    """The JSON Schema of the program format, shipped with the package."""
    return json.loads(resources.files("dlovr").joinpath("data/program.schema.json").read_text("utf-8"))
