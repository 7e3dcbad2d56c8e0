"""Discrete contact state model (paper §IV; docs/model.md, section 3).

Pure Python + numpy. The classifier turns one topological contact into its discrete state from plain
geometric facts (:class:`FaceFact`, :class:`PairFact`) that the geometry module computes from a scene
(or a test writes by hand). All vectors are unit vectors in the world frame; angles are in degrees.

Notation of a discrete situation (docs/model.md, section 3.1), ASCII and Unicode::

    V/G & E/N & E/F[block.F1] & E/E^P[block.F1,block.F2] & V/N
    V/G ∧ E/N ∧ E/F[block.F1] ∧ E/E^P[block.F1,block.F2] ∧ V/N

The face list in brackets is an annotation of which faces are touched; it is optional in the notation
(``V/F`` alone is a valid discrete contact of a hand-written sequence) but, when present, part of the
value.
"""

from __future__ import annotations

import math
import re
from collections.abc import Sequence
from dataclasses import dataclass, field
from enum import Enum
from functools import cached_property
from typing import Any, Literal, cast

import numpy as np

from dlovr.model.facts import ContactFacts, FaceFact, FactBook, ModelParams, PairFact
from dlovr.model.topology import (
    Contact,
    EnvPrimitive,
    N,
    NotationError,
    Situation,
    Vec3,
    check_face_name,
    contract_contacts,
    distinct_primitives,
    face_object,
    normalise_notation,
    parse_situation,
    sort_faces,
    successional_runs,
)
from dlovr.transforms import dot, norm, unit

# --------------------------------------------------------------------------------------------------
# States
# --------------------------------------------------------------------------------------------------


class Stability(Enum):
    """Stability class (§IV.B): stable ``S``, semi-stable ``T``, instable ``I``."""

    STABLE = "S"
    SEMI = "T"
    INSTABLE = "I"


EnvType = Literal["F", "E^P", "E^L", "V", "G", "N"]
StabilityLetter = Literal["", "S", "T", "I"]  # "" for F, E^P, G and N


@dataclass(frozen=True, order=True)
class DiscreteState:
    """A discrete contact state such as ``E/E^LS`` or ``V/VI``.

    ``dlo`` is ``"V"`` or ``"E"``; ``env`` the environment type; ``stability`` ``"S"``, ``"T"``,
    ``"I"`` for edge and vertex types, ``""`` for ``F``, ``E^P`` (always stable), ``G`` and ``N``.
    """

    dlo: Literal["V", "E"]
    env: EnvType
    stability: StabilityLetter = ""

    def __post_init__(self) -> None:
        if self.env in ("E^L", "V"):
            if self.stability not in ("S", "T", "I"):
                raise ValueError(f"{self.dlo}/{self.env} needs a stability class S, T or I")
        elif self.stability:
            raise ValueError(f"{self.dlo}/{self.env} has no stability class")
        if self.dlo == "V" and self.env == "E^P":
            raise ValueError("V/E^P does not exist: tip contacts on an edge are written V/E^L…")

    @property
    def name(self) -> str:
        return f"{self.dlo}/{self.env}{self.stability}"

    def __str__(self) -> str:
        return self.name

    @property
    def dim_dlo(self) -> int:
        """dim_DLO of eq. 3: 0 for the DLO vertex, 1 for a DLO edge."""
        return 0 if self.dlo == "V" else 1

    @property
    def stability_class(self) -> Stability | None:
        """Stability class; ``F`` and ``E^P`` are stable; ``None`` for ``N`` and ``G``."""
        if self.env in ("N", "G"):
            return None
        if self.env in ("F", "E^P"):
            return Stability.STABLE
        return Stability(self.stability)

    @property
    def is_principal_kind(self) -> bool:
        """True for the 15 states of Fig. 8 (``V/G``, ``E/G``, ``V/N``, ``E/N`` are not principal)."""
        return self.env not in ("N", "G")

    @property
    def dof_trans(self) -> int:
        """Translatory degrees of freedom possible without losing the contact (eq. 3)."""
        if self.env in ("N", "G"):
            return 0
        if self.env == "F":
            return 2
        if self.env in ("E^P", "E^L"):
            return 1
        return 0  # V

    @property
    def dof_blocked(self) -> int:
        """Translatory degrees of freedom blocked by the contact (eq. 3).

        A face, a convex edge or corner, and a point crossing of an edge block only the motion into
        the surface (1). A concave groove blocks two directions; a concave corner blocks all three at
        the DLO vertex and the two across the DLO edge passing through it. The gripper holds all three.
        """
        if self.env == "N":
            return 0
        if self.env == "G":
            return 3
        if self.env in ("F", "E^P"):
            return 1
        if self.stability == "I":
            return 1
        if self.env == "E^L":
            return 2
        return 3 - self.dim_dlo  # concave corner V

    @cached_property
    def card(self) -> int:
        """card = dim_DLO + 2·DoF_trans + 3·DoF_blocked (eq. 3); worked out once per object (the
        state is frozen; the transitions ask it many times a step)."""
        return self.dim_dlo + 2 * self.dof_trans + 3 * self.dof_blocked

    @property
    def contact_kind(self) -> Literal["point", "line", "none"]:
        """Point or line contact (§IV.C): ``E/F`` and ``E/E^L…`` are line contacts."""
        if self.env in ("N", "G"):
            return "none"
        if self.dlo == "E" and self.env in ("F", "E^L"):
            return "line"
        return "point"


def _state(name: str) -> DiscreteState:
    m = re.fullmatch(r"([VE])/(F|E\^P|E\^L|V|G|N)([STI]?)", name)
    if not m:
        raise ValueError(f"unknown discrete state {name!r}")
    # the pattern admits only the letters of the three Literal types
    dlo, env, stab = cast("tuple[Literal['V', 'E'], EnvType, StabilityLetter]", m.groups())
    return DiscreteState(dlo, env, stab)


STATES: dict[str, DiscreteState] = {
    n: _state(n)
    for n in (
        "E/F", "E/E^P", "E/E^LS", "E/VS", "V/F", "V/E^LS", "V/VS",
        "E/E^LT", "E/VT", "V/E^LT", "V/VT",
        "E/E^LI", "E/VI", "V/E^LI", "V/VI",
    )
}
"""The 15 discrete contact states of Fig. 8, by name."""

AUX_STATES: dict[str, DiscreteState] = {n: _state(n) for n in ("V/G", "E/G", "V/N", "E/N")}
"""Gripper and free-space states: they appear in situations but are never principal contacts."""


def state(name: str) -> DiscreteState:
    """Look up a discrete state by name (``"E/E^LS"``, ``"V/N"``, ...)."""
    try:
        return STATES.get(name) or AUX_STATES[name]
    except KeyError:
        raise ValueError(
            f"unknown discrete state {name!r}; known: {', '.join([*STATES, *AUX_STATES])}"
        ) from None


# --------------------------------------------------------------------------------------------------
# Contact vector (eq. 2)
# --------------------------------------------------------------------------------------------------


def _pinch_tol(n_faces: int, merge_deg: float) -> float:
    """Below this length the faces' summed normals cancel (normals within ``merge_deg`` count as one
    direction, so a sum of ``n_faces`` unit normals shorter than this is zero)."""
    return max(1e-9, n_faces * float(np.sin(np.radians(merge_deg))))


def contact_vector(facts: ContactFacts, gripper: bool = False, merge_deg: float = 0.01) -> np.ndarray:
    """Contact vector C of eq. 2 as a 3-vector (world frame): unit, or zero.

    Sum of ``-N(F)`` over the distinct real faces (internal ones excluded), normalised. The gripper
    contact gives its z axis; free space gives the zero vector. A **pinch** also gives the zero
    vector: faces whose normals cancel (two opposite faces, the DLO clamped between them; normals
    within ``merge_deg`` degrees count as one direction), see :func:`pinch_axis`.
    """
    if gripper:
        if facts.gripper_z is None:
            raise ValueError("a gripper contact needs the gripper's z axis")
        return _required(unit(facts.gripper_z))
    real = {f.name: f for f in facts.faces if not f.internal}
    if not real:
        return np.zeros(3)
    c = -np.sum([np.asarray(f.normal, dtype=float) for f in real.values()], axis=0)
    u = unit(c, _pinch_tol(len(real), merge_deg))
    return np.zeros(3) if u is None else u  # None: a pinch


def pinch_axis(facts: ContactFacts, merge_deg: float = 0.01) -> np.ndarray | None:
    """The axis of a pinch (unit, world frame), ``None`` when the contact is no pinch or has no axis.

    A pinch is a contact whose real faces' normals cancel (:func:`contact_vector` is zero). When
    they lie on one line (two opposite faces clamping the DLO), the axis is the outward normal of the
    first face in canonical order: a detector compares the force with that line, either sign.
    Normals that cancel around the DLO (three or more faces) leave no axis: only the force's size."""
    real = _real_faces(facts)
    if not real:
        return None
    normals = np.array([_required(unit(f.normal)) for f in real])
    if norm(normals.sum(axis=0)) >= _pinch_tol(len(real), merge_deg):
        return None
    if _rank(normals, merge_deg) != 1:
        return None
    return normals[0]


def _real_faces(facts: ContactFacts) -> list[FaceFact]:
    """Distinct real (not internal) faces of a contact, in canonical order."""
    real: dict[str, FaceFact] = {}
    for f in facts.faces:
        if not f.internal:
            real.setdefault(f.name, f)
    return [real[n] for n in sort_faces(real)]


# --------------------------------------------------------------------------------------------------
# The classifier (docs/model.md, section 3.2)
# --------------------------------------------------------------------------------------------------


def _required(u: np.ndarray | None) -> np.ndarray:
    """A direction the classifier needs: ``None`` (:func:`dlovr.transforms.unit` of a zero vector,
    which has none) is an error."""
    if u is None:
        raise ValueError("zero-length vector")
    return u


def normal_clusters(normals: np.ndarray, merge_deg: float) -> list[int]:
    """Cluster label for each normal: normals within ``merge_deg`` of a cluster's first one join it."""
    cos_tol = np.cos(np.radians(merge_deg))
    reps: list[np.ndarray] = []
    labels: list[int] = []
    for n in normals:
        for k, r in enumerate(reps):
            if float(n @ r) >= cos_tol:
                labels.append(k)
                break
        else:
            reps.append(n)
            labels.append(len(reps) - 1)
    return labels


def _rank(normals: np.ndarray, merge_deg: float) -> int:
    """Rank of a set of unit normals, with directions closer than ``merge_deg`` merged."""
    if len(normals) == 0:
        return 0
    s = np.linalg.svd(normals, compute_uv=False)
    tol = np.sin(np.radians(max(merge_deg, 1e-6)))
    return int(np.sum(s > tol * s[0]))


def _null_direction(normals: np.ndarray) -> np.ndarray:
    """Unit direction orthogonal to every normal as far as possible (the crease of an edge)."""
    _, _, vt = np.linalg.svd(normals)
    return vt[-1]


def classify_contact(
    dlo: Literal["V", "E"],
    facts: ContactFacts,
    params: ModelParams = ModelParams(),
    gripper: bool = False,
) -> DiscreteState:
    """Discrete state of one (single or multiple) contact at a DLO point (docs/model.md, 3.2).

    1. Environment type from the rank of the real faces' normals (1 -> F, 2 -> E, 3 -> V).
    2. Concave or convex per pair of faces with distinct normals, from ``facts.pairs``.
    3. Stability: F and E^P stable; E^L and V instable if any pair is convex, semi-stable if all are
       concave but some opening angle is at or above the critical angle, else stable.
    4. Point or line for an E contact on an edge: line when the DLO vector is within the parallel
       tolerance of the crease.
    """
    got = _classify_faces(dlo, facts, params, gripper)
    if isinstance(got, DiscreteState):
        return got
    stab, normals = got
    if facts.dlo_vector is None:
        raise ValueError(_NO_VECTOR)
    return _point_or_line(stab, _crease(facts, normals).tolist(), facts.dlo_vector, params)


def _classify_faces(
    dlo: Literal["V", "E"], facts: ContactFacts, params: ModelParams, gripper: bool
) -> DiscreteState | tuple[StabilityLetter, np.ndarray]:
    """Steps 1-3 of :func:`classify_contact`: the state, or for an E contact on an edge (whose point
    or line decision needs the DLO vector, step 4) its stability class and the real faces' normals."""
    if gripper:
        return DiscreteState(dlo, "G")
    real: dict[str, FaceFact] = {}
    for f in facts.faces:
        if not f.internal:
            real.setdefault(f.name, f)
    if not real:
        return DiscreteState(dlo, "N")
    names = list(real)
    normals = np.array([_required(unit(real[n].normal)) for n in names])
    rank = _rank(normals, params.normal_merge_deg)
    if rank == 1:
        return DiscreteState(dlo, "F")

    labels = normal_clusters(normals, params.normal_merge_deg)
    pair_by_key = {p.key: p for p in facts.pairs}
    relevant: list[PairFact] = []
    for i, a in enumerate(names):
        for j in range(i + 1, len(names)):
            b = names[j]
            if labels[i] == labels[j]:
                continue  # same direction (e.g. one face split across pieces): not a crease
            p = pair_by_key.get(frozenset((a, b)))
            if p is None:
                raise ValueError(f"no pair fact for faces {a} and {b} (concave or convex?)")
            relevant.append(p)

    stab: StabilityLetter
    if any(not p.concave for p in relevant):
        stab = "I"
    elif any(p.opening_deg >= params.critical_angle_deg for p in relevant):
        stab = "T"
    else:
        stab = "S"

    if rank >= 3:
        return DiscreteState(dlo, "V", stab)
    if dlo == "V":
        return DiscreteState("V", "E^L", stab)
    return stab, normals


def _crease(facts: ContactFacts, normals: np.ndarray) -> np.ndarray:
    """The unit direction of an edge contact's crease (world frame): the caller's, else from the
    real faces' ``normals``."""
    return _required(unit(facts.crease)) if facts.crease is not None else _null_direction(normals)


_NO_VECTOR = "an E contact on an edge needs the DLO vector (point or line contact?)"


def _point_or_line(
    stab: StabilityLetter, crease: list[float], dlo_vector: Vec3, params: ModelParams, band_deg: float = 0.0
) -> DiscreteState:
    """Step 4 of :func:`classify_contact`: an E contact on an edge (stability ``stab``, unit
    ``crease``, world frame, as Python floats) is a line contact when the DLO vector is within the
    parallel tolerance of the crease; ``band_deg`` (degrees) widens that tolerance for a contact that
    was a line contact a moment ago (the decision's hysteresis, :class:`Discretizer`).

    In Python floats (:func:`dlovr.transforms.dot`, summed left to right: the same on every machine,
    and a few µs where numpy's calls on 3-vectors took some 30): a simulation makes it for every
    E contact on an edge whenever its situation is made again."""
    v = dlo_vector if type(dlo_vector) is tuple else np.asarray(dlo_vector, dtype=float).tolist()
    if len(v) == 3 and len(crease) == 3:  # dot and norm written out, summed in the same order
        x0, x1, x2 = v
        n = math.sqrt(x0 * x0 + x1 * x1 + x2 * x2)
        if n == 0.0:
            raise ValueError("zero-length vector")
        c0, c1, c2 = crease
        cos = abs(x0 / n * c0 + x1 / n * c1 + x2 / n * c2)  # abs: a zero's sign does not matter
    else:
        n = norm(v)
        if n == 0.0:
            raise ValueError("zero-length vector")
        cos = abs(dot([x / n for x in v], crease))
    angle = math.acos(min(1.0, cos)) * _DEG_PER_RAD
    if angle <= params.parallel_tol_deg + band_deg:
        return _LINE_STATES[stab]
    return _POINT_STATE


_DEG_PER_RAD = 180.0 / math.pi
"""Degrees per radian (as ``np.degrees`` multiplies)."""

_LINE_STATES = {s: DiscreteState("E", "E^L", s) for s in ("S", "T", "I")}
"""The line contacts on an edge by stability class (frozen: one object each, made once)."""

_POINT_STATE = DiscreteState("E", "E^P")
"""A point contact on an edge."""


# --------------------------------------------------------------------------------------------------
# Discrete contacts and situations
# --------------------------------------------------------------------------------------------------


@dataclass(frozen=True)
class DiscreteContact:
    """A discrete contact: its state and (annotation, part of the value) the faces it touches.

    Annotations (not compared): ``vector`` is the contact vector of eq. 2 (unit, world frame; zero
    for free space and for a pinch); ``axis`` the axis of a pinch between two opposite faces (unit,
    world frame, see :func:`pinch_axis`); ``span`` the inclusive range of DLO point indices the
    contact covers, when known (a simulation knows it, a hand-written sequence does not).
    """

    state: DiscreteState
    faces: tuple[str, ...] = ()
    vector: Vec3 | None = field(default=None, compare=False)
    span: tuple[int, int] | None = field(default=None, compare=False)
    axis: Vec3 | None = field(default=None, compare=False)

    def __post_init__(self) -> None:
        object.__setattr__(self, "faces", sort_faces(self.faces))

    @property
    def is_pinch(self) -> bool:
        """A contact with faces whose contact vector is zero: the DLO is clamped between opposite
        faces (the normals cancel), so no single direction of force is expected."""
        return bool(self.faces) and self.vector is not None and not any(self.vector)

    @property
    def card(self) -> int:
        return self.state.card

    @cached_property
    def objects(self) -> frozenset[str]:
        """The objects of its faces; worked out once per object (the contact is frozen)."""
        return frozenset(face_object(f) for f in self.faces)

    def format(self, unicode: bool = False) -> str:
        if not self.faces:
            return self.state.name
        return f"{self.state.name}[{','.join(self.faces)}]"

    def __str__(self) -> str:
        return self.format()


@dataclass(frozen=True)
class DiscreteSituation:
    """A discrete contact situation: discrete contacts from ``V_S`` to ``V_E`` (joined by ∧)."""

    contacts: tuple[DiscreteContact, ...]

    def __post_init__(self) -> None:
        c = self.contacts
        if not c or c[0].state.dlo != "V" or c[-1].state.dlo != "V":
            raise ValueError("a discrete situation starts and ends with a V contact")
        if len(c) < 3:
            raise ValueError(
                "a discrete situation has the V_S contact, at least one E contact (the DLO's interior "
                "points) and the V_E contact, e.g. V/G & E/N & V/N"
            )
        if any(x.state.dlo != "E" for x in c[1:-1]):
            raise ValueError("interior contacts of a discrete situation are E contacts (V only at the ends)")

    def format(self, unicode: bool = False) -> str:
        return (" ∧ " if unicode else " & ").join(x.format(unicode) for x in self.contacts)

    def __str__(self) -> str:
        return self.format()

    def successional(self) -> list[tuple[int, ...]]:
        """Runs of environment contacts between free / gripper contacts (indices into contacts)."""
        return successional_runs([x.state.is_principal_kind for x in self.contacts])


#: What a contact's discrete contact takes from the scene facts alone: the state (for an E contact on
#: an edge, its stability class), the crease of such an edge (else ``None``), the real faces, the
#: contact vector and the pinch axis.
_Parts = tuple[DiscreteState | StabilityLetter, list[float] | None, tuple[str, ...], Vec3 | None, Vec3 | None]


def _contact_parts(contact: Contact, book: FactBook, params: ModelParams) -> _Parts:
    """A contact's :data:`_Parts`: all of its discrete contact but the span and, for an E contact on
    an edge, the point or line decision from the DLO vector."""
    dlo: Literal["V", "E"] = "E" if contact.dlo.kind == "E" else "V"
    gripper = any(e.kind == "G" for e in contact.env)
    if contact.is_free:
        return DiscreteState(dlo, "N"), None, (), (0.0, 0.0, 0.0), None
    facts = book.for_contact(contact)
    got = _classify_faces(dlo, facts, params, gripper)
    st, crease = (got, None) if isinstance(got, DiscreteState) else (got[0], _crease(facts, got[1]).tolist())
    try:
        c = contact_vector(facts, gripper=gripper, merge_deg=params.normal_merge_deg)
        vec: Vec3 | None = (float(c[0]), float(c[1]), float(c[2]))
    except ValueError:  # a gripper contact without its z axis
        vec = None
    a = None if gripper else pinch_axis(facts, params.normal_merge_deg)
    axis: Vec3 | None = None if a is None else (float(a[0]), float(a[1]), float(a[2]))
    real = sort_faces(f.name for f in facts.faces if not f.internal)  # as DiscreteContact keeps them
    return st, crease, real, vec, axis


def _from_parts(
    parts: _Parts, contact: Contact, params: ModelParams, band_deg: float = 0.0
) -> DiscreteContact:
    """The discrete contact of ``contact`` from its :data:`_Parts` (``band_deg``: the point or line
    decision's band, for a contact that was a line contact a moment ago; see :func:`_point_or_line`)."""
    _, _, real, vec, axis = parts
    return DiscreteContact(_state_of(parts, contact, params, band_deg), real, vec, contact.dlo.span, axis)


def _state_of(parts: _Parts, contact: Contact, params: ModelParams, band_deg: float = 0.0) -> DiscreteState:
    """The state of :func:`_from_parts`' discrete contact (the point or line decision made here)."""
    st, crease = parts[0], parts[1]
    if not isinstance(st, DiscreteState):  # an E contact on an edge: its stability class and crease
        if contact.dlo.vector is None:
            raise ValueError(_NO_VECTOR)
        assert crease is not None
        st = _point_or_line(st, crease, contact.dlo.vector, params, band_deg)
    return st


def discretize_contact(
    contact: Contact, book: FactBook, params: ModelParams = ModelParams()
) -> DiscreteContact:
    """Discrete contact of one topological contact, using the scene facts in ``book``."""
    return _from_parts(_contact_parts(contact, book, params), contact, params)


def discretize(
    situation: Situation, book: FactBook, params: ModelParams = ModelParams()
) -> DiscreteSituation:
    """Discrete situation of a topological one (docs/model.md, 3.2, for every contact), after
    :func:`without_internal` (internal faces dropped, neighbours that became equal contracted)."""
    real = without_internal(situation, book)
    return DiscreteSituation(tuple(discretize_contact(c, book, params) for c in real.contacts))


def without_internal(situation: Situation, book: FactBook) -> Situation:
    """``situation`` without the faces that ``book`` marks internal (§II: never contact faces), then
    contracted again (:func:`dlovr.model.topology.contract_contacts`): a primitive keeps its real
    faces (an edge of a real and an internal face is that face), a contact with none left is ``N``,
    and neighbouring interior contacts that became equal are one. ``situation`` itself when it names
    no internal face (faces unknown to ``book`` are left for the classifier to report)."""
    internal = {f for c in situation.contacts for f in c.faces if f in book.faces and book.faces[f].internal}
    if not internal:
        return situation
    contacts = []
    for c in situation.contacts:
        if not internal.intersection(c.faces):
            contacts.append(c)
            continue
        env = [e for e in c.env if e.kind != "faces"]
        for e in c.env:
            real = tuple(f for f in e.faces if f not in internal)
            if real:
                env.append(EnvPrimitive("faces", real))
        contacts.append(Contact(c.dlo, tuple(distinct_primitives(env)) or (N,)))
    return contract_contacts(contacts)


class Discretizer:
    """:func:`discretize` for many situations of one scene (``book``), as a simulation's steps give:
    what a contact takes from the scene facts alone is kept by its topology (DLO kind, environment
    primitives and the gripper's z axis, an annotation of ``G`` that its contact vector takes), so a
    contact seen before costs only its span and, on an edge, the point or line decision from its DLO
    vector; a contact that comes out as the last one of its topology and span did is that one again. At most
    ``size`` topologies are kept (then forgotten all at once). Same results as :func:`discretize`
    when ``line_band_deg`` is 0.

    ``line_band_deg`` is the hysteresis of the point-or-line decision (docs/model.md, section 3.2):
    an E contact on an edge that was a line contact in the last situation given (the same edge,
    the same DLO kind) stays one until its DLO vector is more than the parallel tolerance plus this
    band (degrees) from the crease; one that was not must come within the tolerance itself. The
    decisions are remembered from one call to the next, the way a simulation's steps come;
    :meth:`forget` starts afresh."""

    def __init__(
        self, book: FactBook, params: ModelParams = ModelParams(), size: int = 4096,
        line_band_deg: float = 0.0,
    ):
        if not 0.0 <= line_band_deg < 90.0:
            raise ValueError(f"line_band_deg must be in [0, 90), got {line_band_deg}")
        self.book, self.params, self.size, self.line_band_deg = book, params, size, line_band_deg
        # key -> [parts, the last discrete contact made of them by span, key]
        self._memo: dict[tuple[Any, ...], list[Any]] = {}
        # the memo's entries of an E and of a V contact by the identity of an environment (the tuple
        # itself kept beside them; one with the gripper holds its z): a simulation's situations share
        # these tuples
        self._by_env: dict[int, list[Any]] = {}
        self._lines: frozenset[tuple[Any, ...]] = frozenset()  # edge contacts that were line contacts
        self._gripper: dict[tuple[Any, ...], _Parts] = {}  # a gripper contact's parts by its topology
        self._now: set[tuple[Any, ...]] | None = None  # those of the situation being made

    def __call__(self, situation: Situation) -> DiscreteSituation:
        self._now = set()
        try:
            contact = self.contact
            out = DiscreteSituation(tuple([contact(c) for c in situation.contacts]))
            self._lines = frozenset(self._now)
        finally:
            self._now = None
        return out

    def again(self, last: DiscreteSituation, situation: Situation, redo: Sequence[int]) -> DiscreteSituation:
        """``self(situation)`` for a situation whose contacts are, but for the annotations at ``redo``,
        those of a situation that this discretizer made ``last`` from (at the last call or before):
        the same DLO kinds, spans and environment tuples, the same parameters. Only the contacts at
        ``redo`` are made again (those whose state or vector can follow an annotation: the E contacts
        on edges, from their DLO vector; the gripper's, from its ``z``); each other one is ``last``'s,
        which is what the call would give (its state and vector come from the facts alone, by its
        topology and span). ``last`` itself when every contact made again is the one it had. The
        point-or-line decisions are remembered as by a call."""
        self._now = set()
        try:
            contact, cs = self.contact, situation.contacts
            out = list(last.contacts)
            changed = False
            for k in redo:
                dc = contact(cs[k])
                if dc is not out[k]:
                    out[k] = dc
                    changed = True
            self._lines = frozenset(self._now)
        finally:
            self._now = None
        return DiscreteSituation(tuple(out)) if changed else last

    def forget(self) -> None:
        """Forget the last situation's point-or-line decisions (the next situation starts afresh)."""
        self._lines = frozenset()

    def contact(self, contact: Contact) -> DiscreteContact:
        """:func:`discretize_contact` of ``contact`` with this scene's facts and parameters (and, for an
        E contact on an edge within a call of the discretizer, the band of its point-or-line decision)."""
        env, dlo = contact.env, contact.dlo
        ent = self._by_env.get(id(env))
        got = ent[1 if dlo.kind == "E" else 2] if ent is not None and ent[0] is env else None
        if got is None:
            got = self._entry(contact)
        parts, span = got[0], dlo.span
        last = got[1].get(span)
        if parts[1] is None:  # the state comes from the facts alone
            if last is not None:
                return last
            st = parts[0]
        else:  # an E contact on an edge: point or line, from its DLO vector
            key = got[2]
            st = _state_of(parts, contact, self.params, self.line_band_deg if key in self._lines else 0.0)
            if self._now is not None and st.env == "E^L":
                self._now.add(key)
            if last is not None and (last.state is st or last.state == st):  # `is`: the states are shared
                return last  # what _from_parts would make, without making it
        made = got[1]
        if len(made) >= _SPANS_KEPT:
            made.clear()
        dc = made[span] = _discrete_contact(st, parts[2], parts[3], span, parts[4])
        return dc

    def _entry(self, contact: Contact) -> list[Any]:
        """The memo's entry of ``contact``'s topology (DLO kind, environment, the gripper's z):
        ``[parts, the last discrete contact made of it, key]``, made when new."""
        env = contact.env
        z = env[0].z if len(env) == 1 else tuple(e.z for e in env)
        e_kind = contact.dlo.kind == "E"
        key = (e_kind, env, z)
        got = self._memo.get(key)
        if got is None:
            if len(self._memo) >= self.size:
                self._memo.clear()
                self._by_env.clear()
                self._gripper.clear()
            got = self._memo[key] = [self._parts(contact, e_kind), {}, key]
        ent = self._by_env.get(id(env))  # a tuple holds its z (the gripper's) for its life
        if ent is None or ent[0] is not env:
            if len(self._by_env) >= self.size:
                self._by_env.clear()
            ent = self._by_env[id(env)] = [env, None, None]
        ent[1 if e_kind else 2] = got
        return got


    def _parts(self, contact: Contact, e_kind: bool) -> _Parts:
        """:func:`_contact_parts` of ``contact``: for a gripper contact, whose parts but the contact
        vector (the gripper's z made a unit vector) come from its topology alone, those kept by its
        DLO kind and environment (the gripper's z left out), the vector made the way
        :func:`_contact_parts` makes it."""
        env = contact.env
        if contact.is_free or not any(e.kind == "G" for e in env):
            return _contact_parts(contact, self.book, self.params)
        key = (e_kind, env)  # an EnvPrimitive compares (and hashes) without its z
        base = self._gripper.get(key)
        if base is None:
            base = self._gripper[key] = _contact_parts(contact, self.book, self.params)
            return base
        z = next(e.z for e in env if e.kind == "G")
        try:
            c = contact_vector(ContactFacts((), (), None, None, z), gripper=True)
            vec: Vec3 | None = (float(c[0]), float(c[1]), float(c[2]))
        except ValueError:  # a gripper contact without its z axis
            vec = None
        return base[0], base[1], base[2], vec, base[4]


_SPANS_KEPT = 256
"""How many spans' discrete contacts :class:`Discretizer` keeps per topology (then none again)."""


def _discrete_contact(
    state: DiscreteState, faces: tuple[str, ...], vector: Vec3 | None, span: tuple[int, int] | None,
    axis: Vec3 | None,
) -> DiscreteContact:
    """``DiscreteContact(state, faces, vector, span, axis)`` for ``faces`` already in canonical order
    (:data:`_Parts`' real faces), without the dataclass's ``__init__`` (which sets a frozen field at
    a time) and its sorting: a simulation's discretizer makes one whenever a contact's span moves."""
    dc = object.__new__(DiscreteContact)
    dc.__dict__.update(state=state, faces=faces, vector=vector, span=span, axis=axis)
    return dc


# --------------------------------------------------------------------------------------------------
# Parsing
# --------------------------------------------------------------------------------------------------

_DC_RE = re.compile(r"^([VE]/(?:F|E\^P|E\^L[STI]|V[STI]|G|N))(?:\[([^\]]*)\])?$")

#: Distinct faces a written discrete contact may name, by environment type: a face (or coplanar
#: faces of several objects, as many as there are), an edge (its two faces, up to two edges side by
#: side in a groove: ``E/(F1∩F3) + E/(F2∩F4)``), a vertex (three faces, or four where four meet).
#: Fewest and most faces a contact names: an edge two faces of a piece, a vertex three or more, and a
#: contact with several pieces the faces of each (the groove's end in peg_in_hole: a holeblock vertex
#: of three faces and a block edge of two, five faces); no upper bound.
FACE_COUNTS: dict[str, tuple[int, int | None]] = {
    "F": (1, None), "E^P": (2, None), "E^L": (2, None), "V": (3, None)
}
#: What a contact on each kind of environment is, for messages.
CONTACT_KIND = {"F": "a face", "E^P": "an edge", "E^L": "an edge", "V": "a vertex"}


def parse_discrete_contact(text: str, where: str = "contact") -> DiscreteContact:
    t = text.strip()
    m = _DC_RE.match(t)
    if not m:
        raise NotationError(f"{where}: {t!r} is not a discrete contact (e.g. E/F[box.F1], V/E^LS, E/N)")
    st = state(m.group(1))
    names: tuple[str, ...] = ()
    if m.group(2) is not None:
        parts = [s.strip() for s in m.group(2).split(",")]
        if any(not s for s in parts):
            raise NotationError(f"{where}: empty face name in {t!r}")
        try:
            names = tuple(check_face_name(s) for s in parts)
        except NotationError as e:
            raise NotationError(f"{where}: {e}") from None
        if st.env in ("N", "G"):
            raise NotationError(f"{where}: {st.name} touches no faces")
        twice = sorted({f for f in names if names.count(f) > 1})
        if twice:
            raise NotationError(f"{where}: face {twice[0]} is listed twice in {t!r}")
        lo, hi = FACE_COUNTS[st.env]
        if len(names) < lo or (hi is not None and len(names) > hi):
            what = CONTACT_KIND[st.env]
            want = f"{lo} to {hi}" if hi is not None else f"at least {lo}"
            raise NotationError(
                f"{where}: {st.name} is {what} contact and names {want} faces, got {len(names)} in {t!r}"
            )
    return DiscreteContact(st, names)


def parse_discrete_situation(text: str) -> DiscreteSituation:
    """Parse a discrete situation in ASCII (or Unicode) notation."""
    t = normalise_notation(text).strip()
    if not t:
        raise NotationError("empty situation")
    contacts = [parse_discrete_contact(p, f"contact {k + 1}") for k, p in enumerate(t.split("&"))]
    try:
        return DiscreteSituation(tuple(contacts))
    except ValueError as err:
        raise NotationError(str(err)) from None


def is_discrete_notation(text: str) -> bool:
    """True for a discrete situation (``V/…`` first), False for a topological one (``VS/…``)."""
    return normalise_notation(text).lstrip().startswith("V/")


def parse_any(text: str) -> Situation | DiscreteSituation:
    """Parse a discrete or a topological situation, telling them apart by the first contact."""
    return parse_discrete_situation(text) if is_discrete_notation(text) else parse_situation(text)


__all__ = [
    "AUX_STATES", "CONTACT_KIND", "FACE_COUNTS", "STATES", "ContactFacts", "DiscreteContact",
    "DiscreteSituation", "DiscreteState", "Discretizer", "FaceFact", "FactBook", "ModelParams", "PairFact",
    "Stability", "classify_contact", "contact_vector", "discretize", "discretize_contact", "face_object",
    "parse_any",
    "parse_discrete_contact", "parse_discrete_situation", "pinch_axis", "state",
]
