"""Transition classes between contact situations (paper §V, MODEL.md §4) and debouncing (§4.2).

Pure Python. Between two consecutive discrete situations:

1. each situation's *successional contacts* (runs of environment contacts between free ones) are
   found and their *principal contacts* (highest card, eq. 3) taken;
2. successional contacts of the two situations are matched by shared objects and order along the DLO;
3. each change of principal contact ``X -> Y`` is classified by the first rule of :data:`RULES` that
   applies; a step's classes are the union over its changes (e.g. ``S,E``), ``-`` when none changed.
"""

from __future__ import annotations

from collections.abc import Callable, Hashable, Sequence
from dataclasses import dataclass, field
from typing import Generic, TypeVar

from dlovr.model.discrete import DiscreteContact, DiscreteSituation, Stability

CLASS_ORDER = ("S", "I", "T", "E", "C")
"""Order in which the classes of a multi-class step are written (``S,E``)."""

CLASS_NAMES = {
    "E": "establishing / releasing contact",
    "S": "spontaneous transition",
    "I": "entering instability",
    "T": "transient transition",
    "C": "stable state transition",
}


def principal(contacts: Sequence[DiscreteContact]) -> tuple[DiscreteContact, ...]:
    """Principal contacts of a successional contact: those of highest card (§V.B), in DLO order."""
    if not contacts:
        return ()
    top = max(c.card for c in contacts)
    out: list[DiscreteContact] = []
    for c in contacts:
        if c.card == top and c not in out:
            out.append(c)
    return tuple(out)


def successional_contacts(situation: DiscreteSituation) -> list[tuple[DiscreteContact, ...]]:
    """The successional contacts of a discrete situation, from ``V_S`` to ``V_E``."""
    return [tuple(situation.contacts[i] for i in run) for run in situation.successional()]


def _objects(contacts: Sequence[DiscreteContact]) -> frozenset[str] | None:
    """Objects touched, or ``None`` when some contact carries no face names (discrete-only input)."""
    if any(not c.faces for c in contacts):
        return None
    return frozenset(o for c in contacts for o in c.objects)


def match(
    before: Sequence[Sequence[DiscreteContact]], after: Sequence[Sequence[DiscreteContact]]
) -> list[tuple[int | None, int | None]]:
    """Match successional contacts of two situations by shared objects and order along the DLO.

    Two successional contacts may match when they share an object (or when object names are not
    known); the order along the DLO is kept and as many pairs as possible are made (dynamic
    programming, ties towards the start of the DLO). Returns ``(i, j)`` pairs, with ``None`` on the
    side where a successional contact appears (``(None, j)``) or disappears (``(i, None)``).
    """
    oa = [_objects(r) for r in before]
    ob = [_objects(r) for r in after]

    def ok(i: int, j: int) -> bool:
        return oa[i] is None or ob[j] is None or bool(oa[i] & ob[j])

    n, m = len(before), len(after)
    best = [[0] * (m + 1) for _ in range(n + 1)]
    for i in range(n - 1, -1, -1):
        for j in range(m - 1, -1, -1):
            best[i][j] = max(best[i + 1][j], best[i][j + 1], best[i + 1][j + 1] + 1 if ok(i, j) else 0)
    pairs: list[tuple[int | None, int | None]] = []
    i = j = 0
    while i < n and j < m:
        if ok(i, j) and best[i][j] == best[i + 1][j + 1] + 1:
            pairs.append((i, j))
            i += 1
            j += 1
        elif best[i + 1][j] >= best[i][j + 1]:
            pairs.append((i, None))
            i += 1
        else:
            pairs.append((None, j))
            j += 1
    pairs.extend((k, None) for k in range(i, n))
    pairs.extend((None, k) for k in range(j, m))
    return pairs


# --------------------------------------------------------------------------------------------------
# The rules (MODEL.md §4), first that applies wins
# --------------------------------------------------------------------------------------------------


@dataclass(frozen=True)
class Change:
    """One change of principal contact ``X -> Y`` between matched successional contacts.

    ``x``/``y`` are the principal contacts before/after (empty: free space ``N``); ``x_run``/``y_run``
    the whole successional contacts. ``through_free``: the DLO passed through ``N`` on the way.
    """

    x: tuple[DiscreteContact, ...]
    y: tuple[DiscreteContact, ...]
    x_run: tuple[DiscreteContact, ...] = ()
    y_run: tuple[DiscreteContact, ...] = ()
    through_free: bool = False

    @property
    def changed(self) -> bool:
        return set(self.x) != set(self.y)


def _least_stable(contacts: Sequence[DiscreteContact]) -> Stability | None:
    order = [Stability.INSTABLE, Stability.SEMI, Stability.STABLE]
    found = [c.state.stability_class for c in contacts if c.state.stability_class is not None]
    return min(found, key=order.index) if found else None


def is_instable(contacts: Sequence[DiscreteContact]) -> bool:
    """A set of principal contacts is as stable as its least stable member."""
    return _least_stable(contacts) is Stability.INSTABLE


def is_semi_stable(contacts: Sequence[DiscreteContact]) -> bool:
    return _least_stable(contacts) is Stability.SEMI


def new_obstacle(ch: Change) -> bool:
    """``Y`` touches an object ``X`` does not, or the reverse (Fig. 10b).

    Without face names (discrete-only input) the paper's own rule resolves ``E/F -> E/VS``: a new
    obstacle was hit when the new successional contact holds lower-card ``E/E^LI`` contacts.
    """
    ox, oy = _objects(ch.x), _objects(ch.y)
    if ox is not None and oy is not None:
        return ox != oy
    xs = {c.state.name for c in ch.x}
    ys = {c.state.name for c in ch.y}
    if xs == {"E/F"} and "E/VS" in ys:
        return any(c.state.name == "E/E^LI" for c in ch.y_run)
    return False


def _lands_elsewhere(ch: Change) -> bool:
    ox, oy = _objects(ch.x), _objects(ch.y)
    new = ox is not None and oy is not None and bool(oy - ox)
    return bool(ch.y) and (new or ch.through_free)


@dataclass(frozen=True)
class Rule:
    """One row of MODEL.md §4: a class and when it applies."""

    name: str
    applies: Callable[[Change], bool]
    label: Callable[[Change], str]


def _const(c: str) -> Callable[[Change], str]:
    return lambda ch: c


RULES: tuple[Rule, ...] = (
    Rule("S", lambda ch: bool(ch.x) and is_instable(ch.x), lambda ch: "S,E" if _lands_elsewhere(ch) else "S"),
    Rule("E-free", lambda ch: not ch.x or not ch.y, _const("E")),
    Rule("I", lambda ch: is_instable(ch.y), _const("I")),
    Rule("T", lambda ch: is_semi_stable(ch.x) or is_semi_stable(ch.y), _const("T")),
    Rule("E-object", new_obstacle, _const("E")),
    Rule("C", lambda ch: True, _const("C")),
)
"""The class rules in order; the first that applies to a change gives its class.

MODEL.md lists ``E`` (a successional contact appears or disappears) first "unless rule ``S``
applies"; putting ``S`` first is the same rule without the exception clause.
"""


def classify_change(ch: Change, rules: Sequence[Rule] = RULES) -> tuple[str, ...]:
    """Classes of one change of principal contact (empty when nothing changed)."""
    if not ch.changed:
        return ()
    for r in rules:
        if r.applies(ch):
            return tuple(r.label(ch).split(","))
    return ()


def _sorted_classes(classes: set[str]) -> tuple[str, ...]:
    return tuple(c for c in CLASS_ORDER if c in classes)


def changes(before: DiscreteSituation, after: DiscreteSituation, through_free: bool = False) -> list[Change]:
    """The changes of principal contact between two situations (one per matched pair)."""
    a, b = successional_contacts(before), successional_contacts(after)
    out = []
    for i, j in match(a, b):
        xr = a[i] if i is not None else ()
        yr = b[j] if j is not None else ()
        out.append(Change(principal(xr), principal(yr), xr, yr, through_free))
    return out


def classify_step(
    before: DiscreteSituation,
    after: DiscreteSituation,
    through_free: bool = False,
    rules: Sequence[Rule] = RULES,
) -> tuple[str, ...]:
    """Transition classes of the step ``before -> after``; ``()`` is written ``-``."""
    found: set[str] = set()
    for ch in changes(before, after, through_free):
        found.update(classify_change(ch, rules))
    return _sorted_classes(found)


def format_classes(classes: Sequence[str]) -> str:
    """``("S", "E")`` -> ``"S,E"``; no class -> ``"-"``."""
    return ",".join(classes) if classes else "-"


@dataclass(frozen=True)
class Step:
    """One situation of a sequence with the classes of the transition that led to it."""

    index: int
    situation: DiscreteSituation
    classes: tuple[str, ...]

    @property
    def label(self) -> str:
        return format_classes(self.classes)


def classify_sequence(situations: Sequence[DiscreteSituation], rules: Sequence[Rule] = RULES) -> list[Step]:
    """Classes of every step of a sequence; the first situation has none (``-``)."""
    steps: list[Step] = []
    for k, s in enumerate(situations):
        classes = classify_step(situations[k - 1], s, rules=rules) if k else ()
        steps.append(Step(k, s, classes))
    return steps


# --------------------------------------------------------------------------------------------------
# Debouncing a per-step stream of situations (MODEL.md §4.2)
# --------------------------------------------------------------------------------------------------

S = TypeVar("S", bound=Hashable)

DEFAULT_HOLD_S = 0.01
"""Default flicker hold time (s): NOTES.md measured that about 10 ms keeps real semi-stable states."""


@dataclass
class Kept(Generic[S]):
    """A kept situation: when it began and until when it held (seconds, simulation time)."""

    situation: S
    start: float
    end: float

    @property
    def duration(self) -> float:
        return self.end - self.start


@dataclass
class Debouncer(Generic[S]):
    """Turns a per-step stream of situations into the demonstration's distinct situations.

    - flicker ``A -> B -> A`` with ``B`` shorter than ``hold`` (s) counts as ``A`` throughout;
    - a short ``B`` in ``A -> B -> C`` (``C != A``) is kept when ``transient(B)`` (semi-stable or
      instable: it tells what kind of transition happened), else dropped as noise;
    - every kept situation records its start and end time.

    Feed samples in time order with :meth:`push`; :attr:`kept` is the result so far (its last one
    or two entries may still change while the stream goes on).
    """

    hold: float
    transient: Callable[[S], bool]
    kept: list[Kept[S]] = field(default_factory=list)

    def __post_init__(self) -> None:
        if self.hold < 0:
            raise ValueError(f"hold time must be >= 0 s, got {self.hold}")

    def push(self, t: float, situation: S) -> None:
        k = self.kept
        if k and k[-1].situation == situation:
            k[-1].end = t
            return
        if k:
            k[-1].end = t
        run = Kept(situation, t, t)
        if len(k) >= 2 and k[-1].duration < self.hold:
            a, b = k[-2], k[-1]
            if a.situation == situation:  # flicker A -> B -> A
                k.pop()
                a.end = t
                return
            if not self.transient(b.situation):  # brief stable noise
                k.pop()
                a.end = b.end
        k.append(run)

    def feed(self, samples: Sequence[tuple[float, S]]) -> list[Kept[S]]:
        for t, s in samples:
            self.push(t, s)
        return self.kept


def is_transient(situation: DiscreteSituation) -> bool:
    """True when a principal contact of the situation is semi-stable or instable.

    Such a situation is kept by :class:`Debouncer` however brief: it tells whether a transition was
    transient or spontaneous (§IV.C).
    """
    return any(is_instable(p) or is_semi_stable(p) for p in map(principal, successional_contacts(situation)))
