"""Program generation (paper §VI, docs/model.md): a demonstration becomes a sequence of macros.

Pure Python + numpy. Input: the demonstration's kept contact situations with their times (see
:class:`dlovr.model.transitions.Debouncer`) and the gripper pose trajectory. Each transition that has a
class becomes a **macro**: a guarded motion of the gripper (the demonstrated displacement over that
stretch) that ends when the detection algorithm of its class sees the expected transition. It names
the principal contacts that change (from and to, with faces) and its risk. The motion after the last
classed transition is a final macro to the demonstrated end pose, without detection.

Frames and units: positions in metres and quaternions ``wxyz`` in the world frame; the relative motion
is expressed in the gripper frame at the macro's start; times in seconds; forces in newtons.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, replace
from typing import Any, cast

import numpy as np

from dlovr.model.derivation import DerivationRules, WrenchSeries, derive
from dlovr.model.discrete import DiscreteContact, DiscreteSituation
from dlovr.model.program_format import (
    PROGRAM_VERSION,
    RISK_LEVELS,
    RISK_OF_CLASS,
    RISKY,
    ContactChange,
    ContactSpec,
    Detection,
    Macro,
    Motion,
    Program,
    ProgramError,
    Runnable,
    program_schema,
    readable_versions,
    risk,
    summarize,
)
from dlovr.model.transitions import (
    CLASS_ORDER,
    changes,
    classify_change,
    classify_step,
    contact_objects,
    is_instable,
    principal,
    successional_contacts,
)
from dlovr.transforms import matrix_to_rotvec, quat_to_matrix

__all__ = [  # the program format's names, importable from here too (dlovr.model.program_format)
    "DETECTORS",
    "PROGRAM_VERSION",
    "RISKY",
    "RISK_LEVELS",
    "RISK_OF_CLASS",
    "ChatterRules",
    "ContactChange",
    "ContactSpec",
    "Detection",
    "Macro",
    "Motion",
    "PoseTrack",
    "Program",
    "ProgramError",
    "Runnable",
    "TimedSituation",
    "compile_program",
    "detections",
    "motion_between",
    "program_schema",
    "readable_versions",
    "remove_chatter",
    "risk",
    "summarize",
]

_Vec3 = tuple[float, float, float]
_Quat = tuple[float, float, float, float]


@dataclass(frozen=True)
class TimedSituation:
    """A kept contact situation: when it began (s), how long it held (s), and optionally the
    topological notation it came from, the largest normal force on the cable then (N), and whether
    it was reached by a flight (:attr:`dlovr.model.transitions.Kept.through_free`)."""

    t: float
    duration: float
    situation: DiscreteSituation
    topological: str | None = None
    force: float | None = None
    through_free: bool = False


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


def motion_between(track: PoseTrack, t0: float, t1: float) -> Motion:
    p0, q0 = track.at(t0)
    p1, q1 = track.at(t1)
    r0, r1 = quat_to_matrix(q0), quat_to_matrix(q1)
    d = p1 - p0

    def tup(a: np.ndarray) -> tuple[float, ...]:
        return tuple(round(float(x), 9) + 0.0 for x in a)

    return Motion(
        cast(_Vec3, tup(d)), cast(_Vec3, tup(r0.T @ d)), cast(_Vec3, tup(matrix_to_rotvec(r0.T @ r1))),
        round(t1 - t0, 9), cast(_Vec3, tup(p0)), cast(_Quat, tup(q0)),
    )


# --------------------------------------------------------------------------------------------------
# Chatter: a situation left and re-entered without the task moving on (docs/model.md, section 6)
# --------------------------------------------------------------------------------------------------


@dataclass(frozen=True)
class ChatterRules:
    """When ``A -> B -> A`` is chatter, not two transitions (``B`` one situation or several): ``B`` held
    less than ``max_s`` (s) and the
    gripper moved less than ``max_m`` (m, straight-line distance from entering ``B`` to leaving it)
    and turned less than ``max_deg`` (degrees). A hand hovering at a threshold (the shallow-tip angle,
    a contact distance) flips there for tens to hundreds of milliseconds while barely moving; laying
    a cable down, dragging it and lifting it again takes seconds and centimetres.

    ``settle_s``: a landing after a flight (``S,E``) that holds less than this (s) before the cable
    bounces off again or its landed contact changes (without a new contact: no ``E``) is the impact,
    not a situation: the landing is the one it settles in; and an instable situation held less than
    it between an instable one and a flight is the slip into the flight."""

    max_s: float = 1.0
    max_m: float = 0.05
    max_deg: float = 20.0
    settle_s: float = 0.1


def _is_chatter(t0: float, t1: float, poses: PoseTrack, rules: ChatterRules) -> bool:
    """Is an excursion from ``t0`` to ``t1`` (s) short and still enough to be chatter?"""
    if t1 - t0 >= rules.max_s:
        return False
    p0, q0 = poses.at(t0)
    p1, q1 = poses.at(t1)
    moved = float(np.linalg.norm(np.asarray(p1) - np.asarray(p0)))
    turn = abs(float(np.dot(np.asarray(q0), np.asarray(q1))))
    turned = float(np.degrees(2.0 * np.arccos(min(turn, 1.0))))
    return moved < rules.max_m and turned < rules.max_deg


def _return(out: Sequence[TimedSituation], i: int, poses: PoseTrack, rules: ChatterRules) -> int | None:
    """The last ``j > i`` at which the situation before ``i`` comes back after an excursion
    ``out[i:j]`` that is chatter (:func:`_is_chatter`), or None."""
    a, found = out[i - 1], None
    for j in range(i + 1, len(out)):
        if out[j].t - out[i].t >= rules.max_s:
            break
        if out[j].situation == a.situation and _is_chatter(out[i].t, out[j].t, poses, rules):
            found = j
    return found


def _settles(b: TimedSituation, c: TimedSituation, rules: ChatterRules) -> bool:
    """Is ``b`` the impact of a landing that settles into ``c``: reached by a flight, held less than
    ``rules.settle_s``, and left either by another flight (a bounce) or by a change of the landed
    contact (no ``E``: a new contact made after the landing is a transition of its own)?"""
    if not (b.through_free and b.duration < rules.settle_s and successional_contacts(c.situation)):
        return False
    return c.through_free or "E" not in classify_step(b.situation, c.situation, False)


def _free(s: TimedSituation) -> bool:
    """Does the cable touch nothing but the gripper in ``s``?"""
    return not successional_contacts(s.situation)


def _swings(a: TimedSituation, b: TimedSituation, c: TimedSituation, poses: PoseTrack,
            rules: ChatterRules) -> bool:
    """Is ``a -> b -> c`` a swing through free space (docs/model.md, section 6): the cable left every
    contact (``b`` free), none of them instable, and landed again within the chatter limits
    (:func:`_is_chatter`, from leaving ``a`` to landing in ``c``) on nothing ``a`` did not touch
    (``c``'s objects among ``a``'s)?"""
    if not _free(b) or _free(a) or _free(c) or is_instable(a.situation.contacts):
        return False  # from an instable contact it is a flight (section 5), a transition of its own
    if not _is_chatter(b.t, c.t, poses, rules):
        return False
    before, after = (contact_objects([x for run in successional_contacts(s.situation) for x in run])
                     for s in (a, c))
    return before is not None and after is not None and after <= before


def remove_chatter(
    states: Sequence[TimedSituation], poses: PoseTrack, rules: ChatterRules | None = None
) -> list[TimedSituation]:
    """``states`` with every chattering ``A -> B -> A`` (:class:`ChatterRules`; ``B`` may be several
    situations, ``A -> B1 -> ... -> Bk -> A``, the whole excursion within the rules' time and motion)
    made one ``A`` (it begins when the first began and holds through all), repeated until none is left: a flip
    back and forth is a hand at a threshold, not two transitions. Anything else is kept: ``A -> B ->
    C`` always (but for a swing, below), and ``E, C, C, E`` (laid down, dragged, lifted) whenever
    the drag is real motion.
    A swing through free space, ``A -> N -> C`` within the same limits onto nothing ``A`` did not
    touch (:func:`_swings`), is the step ``A -> C``: the cable swung off what it lay on and landed
    back on it while the hand barely moved, a detour the task did not take (a release and a landing
    elsewhere, or after seconds or centimetres, stay ``E``, ``E``).
    A landing after a flight that settles within ``rules.settle_s`` into another contact situation
    (a bounce, or a change of the landed contact without a new one, :func:`_settles`) lands there
    (``S,E`` into the settled situation, not ``S,E`` then ``C``); the other way round, a brief
    instable situation between an instable one and a flight is the cable slipping off (``I, S,E``,
    not ``I, I, S,E``)."""
    r = rules or ChatterRules()
    out = list(states)
    i = 1
    while i + 1 < len(out):
        a, b, c = out[i - 1], out[i], out[i + 1]
        j = _return(out, i, poses, r)
        if j is not None:
            c = out[j]
            merged = TimedSituation(a.t, round(c.t + c.duration - a.t, 9), a.situation, a.topological,
                                    max(x.force or 0.0 for x in (a, c)), a.through_free)
            out[i - 1 : j + 1] = [merged]
            i = max(i - 1, 1)
        elif c.through_free and b.duration < r.settle_s and is_instable(a.situation.contacts) \
                and is_instable(b.situation.contacts):
            # slipping off: a brief instable contact on the way from an instable one into a flight
            out[i - 1 : i + 1] = [replace(a, duration=round(a.duration + b.duration, 9))]
        elif _swings(a, b, c, poses, r):
            # swung off and landed again on what it had left: a hand's wobble, not a release and a landing
            out[i - 1 : i + 1] = [replace(a, duration=round(c.t - a.t, 9))]
            i = max(i - 1, 1)
        elif _settles(b, c, r):
            # the impact of a landing: the flight lands where the cable settles
            out[i : i + 2] = [TimedSituation(b.t, round(b.duration + c.duration, 9), c.situation,
                                             c.topological, c.force, True)]
        else:
            i += 1
    return out


# --------------------------------------------------------------------------------------------------
# Detection algorithms, one per class (§V.B, docs/model.md)
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


def _spec(c: DiscreteContact) -> ContactSpec:
    def tup(v: tuple[float, ...] | None) -> _Vec3 | None:
        return None if v is None else cast(_Vec3, tuple(round(float(x), 9) + 0.0 for x in v))

    return ContactSpec(c.format(), tup(c.vector), tup(c.axis))


def _principals(s: DiscreteSituation) -> tuple[ContactSpec, ...]:
    return tuple(_spec(c) for run in successional_contacts(s) for c in principal(run))


def detections(
    classes: Sequence[str],
    prev: TimedSituation,
    cur: TimedSituation,
    wrench: WrenchSeries | None,
    rules: DerivationRules | None,
) -> tuple[Detection, ...]:
    """The detections of a transition ``prev -> cur`` of these classes, parameters derived from the
    wrench around it (defaults without one)."""
    fr, to = _principals(prev.situation), _principals(cur.situation)
    ends = [c for c in fr if c.state not in {x.state for x in to}]
    begins = [c for c in to if c.state not in {x.state for x in fr}]
    released, established = [c.vector for c in ends], [c.vector for c in begins]
    axes = [c.axis for c in (*ends, *begins) if c.axis is not None]  # pinches (docs/model.md)
    out = []
    for c in classes:
        d = derive(c, released, established, wrench, prev.t, cur.t, cur.t + cur.duration, rules, axes)
        out.append(Detection(c, DETECTORS[c]["algorithm"], d.params, d.derivation))
    return tuple(out)


def _changes(prev: TimedSituation, cur: TimedSituation) -> tuple[ContactChange, ...]:
    out = []
    for ch in changes(prev.situation, cur.situation, cur.through_free):
        classes = classify_change(ch)
        if classes:
            x = _spec(ch.x[0]) if ch.x else None
            y = _spec(ch.y[0]) if ch.y else None
            out.append(ContactChange(tuple(c for c in CLASS_ORDER if c in classes), x, y))
    return tuple(out)


def compile_program(
    states: Sequence[TimedSituation],
    poses: PoseTrack,
    name: str = "program",
    source: str = "",
    wrench: WrenchSeries | None = None,
    rules: DerivationRules | None = None,
    chatter: ChatterRules | None = ChatterRules(),
) -> Program:
    """Compile a demonstration into a program of macros (docs/model.md, Programs).

    Every step between consecutive kept situations that has a transition class becomes a macro;
    steps without one (``-``) extend the motion of the next macro. The motion after the last classed
    transition, to the end of ``poses``, is the final macro. ``wrench``: the demonstration's sensed
    gripper wrench, from which each macro's detection parameters are derived
    (:func:`dlovr.model.derivation.derive`); without it every parameter is its class's default,
    marked as such. ``chatter``: a situation left and re-entered after a short time and little
    motion is one (:func:`remove_chatter`; None keeps every flip).
    """
    if not states:
        raise ValueError("a program needs at least one contact situation")
    if chatter is not None:
        states = remove_chatter(states, poses, chatter)
    macros: list[Macro] = []
    anchor = 0
    for k in range(1, len(states)):
        prev, cur = states[k - 1], states[k]
        classes = classify_step(prev.situation, cur.situation, cur.through_free)
        if not classes:
            continue
        start = states[anchor]
        macros.append(
            Macro(
                index=len(macros) + 1,
                kind="transition",
                classes=classes,
                t=round(cur.t, 9),
                from_situation=prev.situation.format(),
                to_situation=cur.situation.format(),
                changes=_changes(prev, cur),
                from_contacts=_principals(prev.situation),
                to_contacts=_principals(cur.situation),
                motion=motion_between(poses, start.t, cur.t),
                detection=detections(classes, prev, cur, wrench, rules),
                risk=risk(classes),
            )
        )
        anchor = k
    start, last = states[anchor], states[-1]
    end = max(float(poses.t[-1]), start.t)
    macros.append(
        Macro(
            index=len(macros) + 1,
            kind="final",
            classes=(),
            t=round(end, 9),
            from_situation=start.situation.format(),
            to_situation=last.situation.format(),
            changes=(),
            from_contacts=_principals(start.situation),
            to_contacts=_principals(last.situation),
            motion=motion_between(poses, start.t, end),
            detection=(),
            risk="none",
        )
    )
    return Program(name, source, tuple(macros), PROGRAM_VERSION, summarize(macros))
