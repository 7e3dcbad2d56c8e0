"""Topological contact model (paper §III; docs/model.md, section 2).

Pure values: no simulator, no geometry. A *contact situation* is the ordered sequence of single or
multiple contacts from the gripped start vertex ``V_S`` to the end vertex ``V_E``.

Identity of a value is its topology: the DLO primitive's kind (``VS``, ``VE``, ``E``) and the
environment primitives. The point index, the index range and the DLO vector of a DLO primitive are
annotations (they do not take part in ``==`` or ``hash``), so that a contact zone sliding along the
cable is still the same contact situation.

Notation (docs/model.md, section 2), ASCII for files and terminals and Unicode for people::

    VS/G & E3/N & E9/box.F1 + E9/table.F1 & E14/N & VE/N
    V_S/G_z ∧ E_3/N ∧ E_9/box.F1 + E_9/table.F1 ∧ E_14/N ∧ V_E/N

An edge or vertex of one convex piece is written as its faces in parentheses:
``(box.F1,box.F2)`` in ASCII, ``(box.F1∩box.F2)`` in Unicode.
"""

from __future__ import annotations

import math
import re
from collections.abc import Callable, Iterable, Sequence
from dataclasses import dataclass, field
from itertools import groupby
from typing import Any, Literal, Protocol, cast

from dlovr.inputs import InputError

Vec3 = tuple[float, float, float]


class ToList(Protocol):
    """An array (numpy's ``ndarray``) read through ``tolist()``: this module does not import numpy."""

    def tolist(self) -> Any: ...


def as_vec3(v: Iterable[float]) -> Vec3:
    """A 3-vector (a sequence or numpy array of three numbers) as a tuple of three Python floats."""
    x, y, z = v
    return (float(x), float(y), float(z))

DloKind = Literal["VS", "VE", "E"]

FACE_NAME_RE = re.compile(r"^[A-Za-z_][A-Za-z0-9_\-]*(\.[A-Za-z_][A-Za-z0-9_\-]*)*\.F[0-9]+$")


class NotationError(InputError):
    """A string is not valid contact notation; the message says what is wrong and where."""


def face_object(face: str) -> str:
    """Name of the environment object that owns face ``face`` (``"box.F3"`` -> ``"box"``)."""
    obj, sep, _ = face.rpartition(".")
    if not sep:
        raise ValueError(f"face name {face!r} has no object part (expected OBJECT.F<k>)")
    return obj


def _face_sort_key(face: str) -> tuple[str, int]:
    obj, _, local = face.rpartition(".")
    return (obj, int(local[1:]) if local[1:].isdigit() else -1)


def sort_faces(faces: Iterable[str]) -> tuple[str, ...]:
    """Distinct face names in canonical (object, number) order."""
    return tuple(sorted(set(faces), key=_face_sort_key))


def check_face_name(face: str) -> str:
    if not FACE_NAME_RE.match(face):
        raise NotationError(f"bad face name {face!r}: expected OBJECT.F<number>, e.g. box.F3")
    return face


# --------------------------------------------------------------------------------------------------
# Environment primitives
# --------------------------------------------------------------------------------------------------


@dataclass(frozen=True, order=True)
class EnvPrimitive:
    """An environment primitive ``N``, ``G_z``, ``F_i``, ``E_ij`` or ``V_ij…k`` (paper §III).

    ``kind`` is ``"N"`` (empty space), ``"G"`` (the gripper), or ``"faces"``: a face, an edge or a
    vertex of **one** convex piece, given as the set of its face names (1, 2, or >= 3 faces).
    ``z`` is the gripper's z axis in the world frame (annotation, only for ``G``).
    """

    kind: Literal["N", "G", "faces"]
    faces: tuple[str, ...] = ()
    z: Vec3 | None = field(default=None, compare=False)

    def __post_init__(self) -> None:
        if self.kind == "faces":
            if not self.faces:
                raise ValueError("a face primitive needs at least one face")
            object.__setattr__(self, "faces", sort_faces(check_face_name(f) for f in self.faces))
        elif self.faces:
            raise ValueError(f"primitive {self.kind} has no faces")

    @property
    def type(self) -> Literal["N", "G", "F", "E", "V"]:
        """Primitive type by face count: 1 -> ``F``, 2 -> ``E`` (edge), >= 3 -> ``V`` (vertex)."""
        if self.kind != "faces":
            return self.kind
        return ("F", "E", "V")[min(len(self.faces), 3) - 1]

    @property
    def objects(self) -> frozenset[str]:
        return frozenset(face_object(f) for f in self.faces)

    def format(self, unicode: bool = False) -> str:
        if self.kind == "N":
            return "N"
        if self.kind == "G":
            return "G_z" if unicode else "G"
        if len(self.faces) == 1:
            return self.faces[0]
        return "(" + ("∩" if unicode else ",").join(self.faces) + ")"

    def __str__(self) -> str:
        return self.format()


N = EnvPrimitive("N")
G = EnvPrimitive("G")


def faces(*names: str) -> EnvPrimitive:
    """Convenience constructor: ``faces("box.F1", "box.F2")`` is the edge F1 ∩ F2 of ``box``."""
    return EnvPrimitive("faces", tuple(names))


# --------------------------------------------------------------------------------------------------
# DLO primitives and contacts
# --------------------------------------------------------------------------------------------------


@dataclass(frozen=True)
class DloPrimitive:
    """A DLO primitive: ``VS`` (point 0), ``VE`` (point n) or ``E`` (an interior point or run).

    Annotations (not compared): ``index`` is the representative point (the middle of a contracted
    run, printed as ``E9``), ``span`` the inclusive range of point indices covered, ``vector`` the
    DLO vector D_i = p_{i+1} - p_i at ``index`` (world frame, metres).
    """

    kind: DloKind
    index: int | None = field(default=None, compare=False)
    span: tuple[int, int] | None = field(default=None, compare=False)
    vector: Vec3 | None = field(default=None, compare=False)

    @property
    def dim(self) -> int:
        """dim_DLO of eq. 3: 0 for a vertex, 1 for an edge."""
        return 0 if self.kind in ("VS", "VE") else 1

    def format(self, unicode: bool = False) -> str:
        if self.kind == "E":
            if self.index is None:
                return "E"
            return f"E_{self.index}" if unicode else f"E{self.index}"
        return ("V_S" if self.kind == "VS" else "V_E") if unicode else self.kind

    def __str__(self) -> str:
        return self.format()


@dataclass(frozen=True)
class Contact:
    """A single contact (one primitive) or a multiple contact (several, joined by ``+``).

    All basic contacts of a multiple contact share one DLO point. ``env`` is kept in canonical order.
    ``N`` never appears together with another primitive.
    """

    dlo: DloPrimitive
    env: tuple[EnvPrimitive, ...]

    def __post_init__(self) -> None:
        if not self.env:
            raise ValueError("a contact needs at least one environment primitive")
        if type(self.env) is tuple and len(self.env) == 1:
            return  # canonical already (most contacts)
        env = tuple(sorted(set(self.env)))
        if len(env) > 1 and N in env:
            raise ValueError("N (free space) cannot be part of a multiple contact")
        object.__setattr__(self, "env", env)

    @property
    def is_free(self) -> bool:
        return self.env == (N,)

    @property
    def is_multiple(self) -> bool:
        return len(self.env) > 1

    @property
    def faces(self) -> tuple[str, ...]:
        """All face names of all primitives of this contact."""
        return sort_faces(f for e in self.env for f in e.faces)

    @property
    def objects(self) -> frozenset[str]:
        return frozenset(face_object(f) for f in self.faces)

    @property
    def touches_environment(self) -> bool:
        """True when the contact involves at least one face (not only N or the gripper)."""
        return any(e.kind == "faces" for e in self.env)

    def format(self, unicode: bool = False) -> str:
        d = self.dlo.format(unicode)
        return " + ".join(f"{d}/{e.format(unicode)}" for e in self.env)

    def __str__(self) -> str:
        return self.format()


@dataclass(frozen=True)
class Situation:
    """A topological contact situation: contacts ordered from ``V_S`` to ``V_E`` (joined by ∧)."""

    contacts: tuple[Contact, ...]

    def __post_init__(self) -> None:
        c = self.contacts
        if len(c) < 2:
            raise ValueError("a situation has at least the V_S and the V_E contact")
        if c[0].dlo.kind != "VS":
            raise ValueError(f"a situation starts with the V_S contact, not {c[0]}")
        if c[-1].dlo.kind != "VE":
            raise ValueError(f"a situation ends with the V_E contact, not {c[-1]}")
        for x in c[1:-1]:
            if x.dlo.kind != "E":
                raise ValueError(f"interior contacts are E contacts, not {x}")

    def format(self, unicode: bool = False) -> str:
        return (" ∧ " if unicode else " & ").join(x.format(unicode) for x in self.contacts)

    def __str__(self) -> str:
        return self.format()

    def successional(self) -> list[tuple[int, ...]]:
        """Successional contacts: maximal runs of environment contacts between free ones (§III).

        Returns the runs as tuples of indices into ``contacts``. Contacts with ``N`` and contacts
        with only the gripper delimit runs (the gripper is not an environment object).
        """
        return successional_runs([x.touches_environment for x in self.contacts])


def successional_runs(touching: Sequence[bool]) -> list[tuple[int, ...]]:
    """Maximal runs of ``True`` in ``touching`` as tuples of indices."""
    runs: list[tuple[int, ...]] = []
    cur: list[int] = []
    for i, t in enumerate(touching):
        if t:
            cur.append(i)
        elif cur:
            runs.append(tuple(cur))
            cur = []
    if cur:
        runs.append(tuple(cur))
    return runs


# --------------------------------------------------------------------------------------------------
# Contraction: per-point contacts -> situation
# --------------------------------------------------------------------------------------------------


def contract(
    point_env: Sequence[Iterable[EnvPrimitive]],
    vectors: Sequence[Sequence[float]] | None = None,
) -> Situation:
    """Build a contact situation from the contacts of every DLO point ``P_0 … P_n`` (§III).

    ``point_env[i]`` holds the environment primitives that point ``i`` touches (empty = ``N``).
    Adjacent interior points with the same contact become one ``E`` contact indexed by the middle
    point of the run; ``V_S`` (point 0) and ``V_E`` (point n) are never contracted into it.
    ``vectors[i]`` is the DLO vector D_i (for the last point, the last segment's vector).
    """
    n_points = len(point_env)
    if n_points < 2:
        raise ValueError("a DLO has at least two points")
    free = (N,)
    # a list of one primitive or none (most points) is canonical already
    envs = [
        (tuple(e) or free) if type(e) is list and len(e) < 2 else (tuple(sorted(set(e))) or free)
        for e in point_env
    ]

    def vec(i: int) -> Vec3 | None:
        if vectors is None:
            return None
        v = vectors[i]
        return (float(v[0]), float(v[1]), float(v[2]))  # only for the few contacts made

    out = [Contact(DloPrimitive("VS", 0, (0, 0), vec(0)), envs[0])]
    i = 1
    last = n_points - 1
    for env, run in groupby(envs[1:last]):  # the runs of equal interior contacts
        j = i + len(list(run)) - 1
        mid = (i + j) // 2
        out.append(Contact(DloPrimitive("E", mid, (i, j), vec(mid)), env))
        i = j + 1
    out.append(Contact(DloPrimitive("VE", last, (last, last), vec(last)), envs[last]))
    return Situation(tuple(out))


def contract_contacts(contacts: Sequence[Contact]) -> Situation:
    """The situation of ``contacts`` (``V_S`` first, ``V_E`` last) with neighbouring interior contacts
    that touch the same primitives contracted into one (§III), as :func:`contract` does for points.

    For contacts that became equal after they were made (e.g. once internal faces are dropped from a
    typed situation: ``E3/N & E8/box.F9`` with ``box.F9`` internal is one ``E/N``). A contracted run
    keeps the DLO primitive (index and vector) of its middle contact and covers the union of the
    runs' spans when all are known.
    """
    out = [contacts[0]]
    inner = list(contacts[1:-1])
    k = 0
    for env, group in groupby(inner, key=lambda c: c.env):
        run = list(group)
        k += len(run)
        if len(run) == 1:
            out.append(run[0])
            continue
        mid = run[(len(run) - 1) // 2].dlo
        spans = [c.dlo.span for c in run]
        span = None if any(x is None for x in spans) else (
            min(x[0] for x in spans if x is not None), max(x[1] for x in spans if x is not None)
        )
        out.append(Contact(DloPrimitive("E", mid.index, span, mid.vector), env))
    out.append(contacts[-1])
    return Situation(tuple(out))


def tip_touches(
    last_vector: Iterable[float], normals: Iterable[Iterable[float]], tip_angle_deg: float = 15.0
) -> bool:
    """End-vertex rule (docs/model.md, paper §III): is the tip itself the contact?

    ``last_vector`` is the DLO vector of the last segment pointing towards the tip (for ``V_S``: the
    first segment reversed), ``normals`` the outward unit normals of the faces at the tip's contact
    (world frame). The tip touches when it points into one of the surfaces at more than
    ``tip_angle_deg`` from that surface; a last segment lying on a face is an ``E`` contact instead,
    with ``V_E/N`` after it. (The caller checks that the contact lies at the end cap.)
    """
    d0, d1, d2 = last_vector
    d0, d1, d2 = float(d0), float(d1), float(d2)
    # sums from 0 as sum() adds them (this runs on most steps of a simulation)
    norm = (0 + d0 * d0 + d1 * d1 + d2 * d2) ** 0.5
    if norm == 0.0:
        raise ValueError("zero-length DLO vector at the tip")
    sin_tip = math.sin(math.radians(tip_angle_deg))
    for n in normals:
        n0, n1, n2 = n
        n0, n1, n2 = float(n0), float(n1), float(n2)
        nn = (0 + n0 * n0 + n1 * n1 + n2 * n2) ** 0.5
        if -(0 + d0 * n0 + d1 * n1 + d2 * n2) / (norm * nn) > sin_tip:
            return True
    return False


def situation_from_points(
    point_env: Sequence[Iterable[EnvPrimitive]],
    vectors: Sequence[Sequence[float]] | ToList,
    face_normal: Callable[[str], Iterable[float]],
    *,
    tip_angle_deg: float = 15.0,
    gripped: bool = True,
    gripper_z: Vec3 | None = None,
) -> Situation:
    """Contact situation from the primitives every point touches, with the end-vertex rule.

    ``vectors[i]`` is D_i = p_{i+1} - p_i for i < n (len n or n+1); ``face_normal`` gives a face's
    outward unit normal. A cable end is in contact itself only when :func:`tip_touches` says the tip
    is the contact (``V_S`` too when not ``gripped``); a gripped ``V_S`` touches ``G_z``, and what
    point 0 touches besides is a contact of the first segment, written at ``E_1`` with what that
    point touches itself (docs/model.md: every contact that carries force appears).

    A contact that the rule takes away from a tip is never dropped: the last segment touches at a
    shallow angle, so it is an ``E`` contact of that segment, written at the last interior point
    (``… ∧ E_{n-1}/F ∧ V_E/N``; ``E_1`` for ``V_S``), together with what that point touches itself.
    (A DLO of two points has no interior point: its tip keeps the contact.)
    """
    env = [e if type(e) is list else list(e) for e in point_env]  # entries replaced below, not changed
    n = len(env) - 1
    to_list = getattr(vectors, "tolist", None)
    rows = cast("Sequence[Sequence[float]]", vectors)  # when it has no tolist()
    vecs: list[Sequence[float]] = to_list() if to_list is not None else list(rows)
    if len(vecs) not in (n, n + 1):
        raise ValueError(f"{len(env)} points need {n} DLO vectors, got {len(vecs)}")
    ends = [(n, n - 1, vecs[n - 1])]
    if not gripped:
        ends.append((0, 1, tuple(-x for x in vecs[0])))
    for i, inner, d in ends:
        names = sort_faces(f for e in env[i] for f in e.faces)
        if names and n >= 2 and not tip_touches(d, [face_normal(f) for f in names], tip_angle_deg):
            env[inner] = _merge_primitives(env[inner], env[i])
            env[i] = []
    if gripped:  # the held vertex is V_S/G; what it touches is a contact of the first segment, at E_1
        if n >= 2 and any(e.kind == "faces" for e in env[0]):
            env[1] = _merge_primitives(env[1], env[0])
        env[0] = [EnvPrimitive("G", (), gripper_z)]
    full = vecs if len(vecs) == n + 1 else [*vecs, vecs[-1]]
    return contract(env, full)


def _merge_primitives(a: Iterable[EnvPrimitive], b: Iterable[EnvPrimitive]) -> list[EnvPrimitive]:
    """The primitives of ``a`` and ``b``, once each (:func:`distinct_primitives`)."""
    return distinct_primitives((*a, *b))


def distinct_primitives(env: Iterable[EnvPrimitive]) -> list[EnvPrimitive]:
    """The primitives of ``env`` but ``N``, once each and sorted; a primitive whose faces are a proper
    subset of another's adds nothing and is left out (as for the contacts of one point)."""
    s = {e for e in env if e.kind != "N"}
    return sorted(
        e for e in s if not (e.kind == "faces" and any(o != e and set(e.faces) < set(o.faces) for o in s))
    )


# --------------------------------------------------------------------------------------------------
# Parsing
# --------------------------------------------------------------------------------------------------

_UNICODE_TO_ASCII = {"∧": "&", "∩": ",", "V_S": "VS", "V_E": "VE", "G_z": "G"}


def normalise_notation(text: str) -> str:
    """Map the Unicode notation onto the ASCII one (the parser reads both)."""
    for u, a in _UNICODE_TO_ASCII.items():
        text = text.replace(u, a)
    return re.sub(r"\bE_(\d+)", r"E\1", text)


_DLO_RE = re.compile(r"^(VS|VE|E)(\d*)$")


def _parse_env(text: str, where: str) -> EnvPrimitive:
    t = text.strip()
    if t == "N":
        return N
    if t == "G":
        return G
    if t.startswith("("):
        if not t.endswith(")"):
            raise NotationError(f"{where}: unclosed parenthesis in {t!r}")
        names = [s.strip() for s in t[1:-1].split(",")]
        if len(names) < 2 or any(not s for s in names):
            raise NotationError(f"{where}: an edge or vertex lists two or more faces, got {t!r}")
        return EnvPrimitive("faces", tuple(check_face_name(s) for s in names))
    if not t:
        raise NotationError(f"{where}: missing environment primitive after '/'")
    try:
        return EnvPrimitive("faces", (check_face_name(t),))
    except NotationError as e:
        raise NotationError(f"{where}: {e}") from None


def parse_contact(text: str, where: str = "contact") -> Contact:
    """Parse one single or multiple contact, e.g. ``E9/box.F1 + E9/table.F1``."""
    parts = [p.strip() for p in normalise_notation(text).split("+")]
    dlo: DloPrimitive | None = None
    env: list[EnvPrimitive] = []
    for p in parts:
        if "/" not in p:
            raise NotationError(f"{where}: {p!r} is not a basic contact DLO/ENV")
        d, _, e = p.partition("/")
        m = _DLO_RE.match(d.strip())
        if not m:
            raise NotationError(f"{where}: {d.strip()!r} is not a DLO primitive (VS, VE, E or E<index>)")
        kind, idx = m.group(1), m.group(2)
        if kind != "E" and idx:
            raise NotationError(f"{where}: vertex {kind} takes no index")
        this = DloPrimitive(cast("DloKind", kind), int(idx) if idx else None)  # _DLO_RE: VS, VE or E
        if dlo is None:
            dlo = this
        elif this.kind != dlo.kind or this.index != dlo.index:
            raise NotationError(f"{where}: the parts of a multiple contact name one DLO point, got {text!r}")
        env.append(_parse_env(e, where))
    assert dlo is not None
    try:
        return Contact(dlo, tuple(env))
    except ValueError as err:
        raise NotationError(f"{where}: {err}") from None


def parse_situation(text: str) -> Situation:
    """Parse a topological contact situation in ASCII (or Unicode) notation."""
    t = normalise_notation(text).strip()
    if not t:
        raise NotationError("empty situation")
    contacts = [parse_contact(p, f"contact {k + 1}") for k, p in enumerate(t.split("&"))]
    try:
        return Situation(tuple(contacts))
    except ValueError as err:
        raise NotationError(str(err)) from None
