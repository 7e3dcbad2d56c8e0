"""Transition classes between contact situations (paper §V, docs/model.md) and debouncing.

Pure Python. Between two consecutive discrete situations:

1. each situation's *successional contacts* (runs of environment contacts between free ones) are
   found and their *principal contacts* (highest card, eq. 3) taken;
2. successional contacts of the two situations are matched (:func:`match`): identical principal
   contacts first, then shared faces, then shared objects, ties by overlap along the DLO;
3. within a matched pair the two sets of principal contacts are paired one to one (ties: several
   principal contacts of equal card, :func:`pair_principals`);
4. each changed pair ``X -> Y`` is classified by the first rule of :data:`RULES` that applies; a
   step's classes are the union over its pairs (e.g. ``S,E``), ``-`` when none changed.

A per-step stream of situations is first debounced (:class:`Debouncer`): flicker, brief
intermediate states, flights.
"""

from __future__ import annotations

from collections.abc import Callable, Hashable, Sequence
from dataclasses import dataclass, field, replace
from typing import Any, Generic, Protocol, TypeVar, cast

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


def contact_objects(contacts: Sequence[DiscreteContact]) -> frozenset[str] | None:
    """Objects touched, or ``None`` when some contact carries no face names (discrete-only input)."""
    if any(not c.faces for c in contacts):
        return None
    return frozenset(o for c in contacts for o in c.objects)


def _faces(contacts: Sequence[DiscreteContact]) -> frozenset[str]:
    return frozenset(f for c in contacts for f in c.faces)


# --------------------------------------------------------------------------------------------------
# Positions along the DLO
# --------------------------------------------------------------------------------------------------

Interval = tuple[float, float]
"""A stretch of the DLO, half open ``[lo, hi)``: in DLO point indices when every contact of both
situations carries its index range, else in fractions of the situation's contact sequence."""


def contact_positions(a: DiscreteSituation, b: DiscreteSituation) -> tuple[list[Interval], list[Interval]]:
    """Where each contact of ``a`` and of ``b`` lies along the DLO, in units common to both.

    With index ranges (``span``) on every contact, the points covered; else (a hand-written sequence)
    contact ``k`` of ``L`` covers ``[k/L, (k+1)/L)``, so the two ends of the DLO line up.
    """
    ca, cb = _covered(a), _covered(b)
    if ca is not None and cb is not None:
        return ca, cb
    return _fractions(a), _fractions(b)


def _covered(s: DiscreteSituation) -> list[Interval] | None:
    """The DLO points each contact of ``s`` covers, or ``None`` when a contact carries no span."""
    out = []
    for c in s.contacts:
        if c.span is None:
            return None
        out.append((float(c.span[0]), float(c.span[1]) + 1.0))
    return out


def _fractions(s: DiscreteSituation) -> list[Interval]:
    """Contact ``k`` of ``L`` as ``[k/L, (k+1)/L)``."""
    return [(k / len(s.contacts), (k + 1) / len(s.contacts)) for k in range(len(s.contacts))]


def _hull(ivs: Sequence[Interval]) -> Interval:
    return (min(i[0] for i in ivs), max(i[1] for i in ivs))


def _overlap(p: Interval, q: Interval) -> float:
    return max(0.0, min(p[1], q[1]) - max(p[0], q[0]))


def _distance(p: Interval, q: Interval) -> float:
    return abs((p[0] + p[1]) - (q[0] + q[1])) / 2.0


# --------------------------------------------------------------------------------------------------
# Matching successional contacts, pairing principal contacts (docs/model.md, Matching and Ties)
# --------------------------------------------------------------------------------------------------


def _in_order(n: int) -> list[Interval]:
    """``n`` stretches one after the other along the DLO, in fractions of its length."""
    return [(k / max(n, 1), (k + 1) / max(n, 1)) for k in range(n)]


def _greedy(scored: list[tuple[tuple[float, ...], int, int]]) -> dict[int, int]:
    """One-to-one pairs, best score first (ties: lower indices first)."""
    pairs: dict[int, int] = {}
    used: set[int] = set()
    for _, i, j in sorted(scored, key=lambda s: (tuple(-x for x in s[0]), s[1], s[2])):
        if i not in pairs and j not in used:
            pairs[i] = j
            used.add(j)
    return pairs


def match(
    before: Sequence[Sequence[DiscreteContact]],
    after: Sequence[Sequence[DiscreteContact]],
    pos_before: Sequence[Interval] | None = None,
    pos_after: Sequence[Interval] | None = None,
) -> list[tuple[int | None, int | None]]:
    """Match the successional contacts of two situations (which new one continues which old one).

    Two successional contacts may match only when they share an object (or when object names are not
    known). Preference, best first: identical principal contacts (same states, same faces; matched
    and unchanged); then shared faces; then shared objects; ties go to the pair whose stretches of
    the DLO (``pos_*``, see :func:`contact_positions`; default: the order of the runs) overlap most,
    then lie closest. Returns ``(i, j)`` pairs in the order of ``before``, then ``(None, j)`` for the
    successional contacts that appear, in DLO order; ``(i, None)`` for one that disappears.
    """
    n, m = len(before), len(after)
    pa = list(pos_before) if pos_before is not None else _in_order(n)
    pb = list(pos_after) if pos_after is not None else _in_order(m)
    scored = []
    for i, x in enumerate(before):
        ox, fx, px = contact_objects(x), _faces(x), set(principal(x))
        for j, y in enumerate(after):
            oy = contact_objects(y)
            shared = ox & oy if ox is not None and oy is not None else None  # None: not known
            if shared is not None and not shared:
                continue  # never pairs two successional contacts that share no object
            score = (
                float(px == set(principal(y))),
                float(bool(fx & _faces(y))),
                float(bool(shared)),
                _overlap(pa[i], pb[j]),
                -_distance(pa[i], pb[j]),
            )
            scored.append((score, i, j))
    pairs = _greedy(scored)
    out: list[tuple[int | None, int | None]] = [(i, pairs.get(i)) for i in range(n)]
    taken = set(pairs.values())
    out.extend((None, j) for j in range(m) if j not in taken)
    return out


def pair_principals(
    x: Sequence[DiscreteContact],
    y: Sequence[DiscreteContact],
    before: Sequence[DiscreteContact] = (),
    after: Sequence[DiscreteContact] = (),
    pos_x: Sequence[Interval] | None = None,
    pos_y: Sequence[Interval] | None = None,
) -> list[tuple[DiscreteContact | None, DiscreteContact | None]]:
    """The changed pairs between two sets of principal contacts (ties of equal card, set semantics).

    ``x``/``y``: the principal contacts of a matched pair of successional contacts (either may be
    empty: the successional contact appears or disappears); ``before``/``after``: all contacts of the
    two whole situations; ``pos_*``: where each principal contact lies along the DLO. Identical
    contacts are unchanged. The rest are paired one to one, preferring contacts absent from the other
    situation altogether, then shared faces, then shared objects, then the nearest. A leftover that
    is still present, unchanged, in the other situation (it only left or joined the principal set) is
    unchanged; any other leftover pairs with ``None`` (free space ``N``). Unchanged pairs are left out.
    """
    px = list(pos_x) if pos_x is not None else [(0.0, 0.0)] * len(x)
    py = list(pos_y) if pos_y is not None else [(0.0, 0.0)] * len(y)
    xs = [k for k, c in enumerate(x) if c not in y]
    ys = [k for k, c in enumerate(y) if c not in x]
    scored = []
    for i in xs:
        a = x[i]
        for j in ys:
            b = y[j]
            oa, ob = contact_objects((a,)), contact_objects((b,))
            score = (
                float(a not in after) + float(b not in before),
                float(bool(set(a.faces) & set(b.faces))),
                float(oa is not None and ob is not None and bool(oa & ob)),
                -_distance(px[i], py[j]),
            )
            scored.append((score, i, j))
    pairs = _greedy(scored)
    out: list[tuple[DiscreteContact | None, DiscreteContact | None]] = []
    taken = set(pairs.values())
    for i in xs:
        if i in pairs:
            out.append((x[i], y[pairs[i]]))
        elif x[i] not in after:
            out.append((x[i], None))
    out.extend((None, y[j]) for j in ys if j not in taken and y[j] not in before)
    return out


# --------------------------------------------------------------------------------------------------
# The rules (docs/model.md, Transition classes), first that applies wins
# --------------------------------------------------------------------------------------------------


@dataclass(frozen=True)
class Change:
    """One change of principal contact ``X -> Y`` between matched successional contacts.

    ``x``/``y`` are the principal contacts before/after (empty: free space ``N``); a step's changes
    (:func:`changes`) hold one contact on each side at most. ``x_run``/``y_run`` are the whole
    successional contacts. ``through_free``: this successional contact passed through ``N`` on the
    way (it flew; :func:`changes` gives the flag of a step to the changes that flew). ``after``: all
    contacts of the new situation (the fallback of :func:`new_obstacle` looks at all of them; empty:
    not known, ``y_run`` stands for it).
    """

    x: tuple[DiscreteContact, ...]
    y: tuple[DiscreteContact, ...]
    x_run: tuple[DiscreteContact, ...] = ()
    y_run: tuple[DiscreteContact, ...] = ()
    through_free: bool = False
    after: tuple[DiscreteContact, ...] = ()

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
    obstacle was hit when the new situation (any of its successional contacts, ``ch.after``; the new
    successional contact when the situation is not known) holds lower-card ``E/E^LI`` contacts.
    """
    ox, oy = contact_objects(ch.x), contact_objects(ch.y)
    if ox is not None and oy is not None:
        return ox != oy
    xs = {c.state.name for c in ch.x}
    ys = {c.state.name for c in ch.y}
    if xs == {"E/F"} and "E/VS" in ys:
        return any(c.state.name == "E/E^LI" for c in (ch.after or ch.y_run))
    return False


def snaps(ch: Change) -> bool:
    """Rule ``S``: ``X`` is instable and the DLO left it: ``Y`` is not instable, or it flew there."""
    return is_instable(ch.x) and (not is_instable(ch.y) or (bool(ch.y) and ch.through_free))


def _lands_elsewhere(ch: Change) -> bool:
    ox, oy = contact_objects(ch.x), contact_objects(ch.y)
    new = ox is not None and oy is not None and bool(oy - ox)
    return bool(ch.y) and (new or ch.through_free)


@dataclass(frozen=True)
class Rule:
    """One row of the rule table (docs/model.md): a class and when it applies."""

    name: str
    applies: Callable[[Change], bool]
    label: Callable[[Change], str]


def _const(c: str) -> Callable[[Change], str]:
    return lambda ch: c


RULES: tuple[Rule, ...] = (
    Rule("S", snaps, lambda ch: "S,E" if _lands_elsewhere(ch) else "S"),
    Rule("E-free", lambda ch: not ch.x or not ch.y, _const("E")),
    Rule("I", lambda ch: is_instable(ch.y), _const("I")),
    Rule("T", lambda ch: is_semi_stable(ch.x) or is_semi_stable(ch.y), _const("T")),
    Rule("E-object", new_obstacle, _const("E")),
    Rule("C", lambda ch: True, _const("C")),
)
"""The class rules in order; the first that applies to a change gives its class.

The paper's order lists ``E`` (a successional contact appears or disappears) first "unless rule
``S`` applies"; putting ``S`` first is the same rule without the exception clause. ``I`` covers one
instable state to another (``V/E^LI -> V/VI``: still held at a ridge or corner), except after a
flight through ``N``, which is ``S,E``.
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
    """The changed pairs of principal contacts between two situations, in DLO order.

    Successional contacts are matched (:func:`match`), then their principal contacts paired
    (:func:`pair_principals`); each changed pair is one :class:`Change` (``X -> N`` and ``N -> Y``
    included). A successional contact left without a partner pairs each of its principal contacts
    with ``N``, whatever the rest of the other situation holds (a run that splits, merges, appears
    or leaves). ``through_free`` (the step is a flight) goes to the changes that flew
    (:func:`_flown`). An empty list: no principal contact changed.
    """
    pos_a, pos_b = contact_positions(before, after)
    runs_a, runs_b = before.successional(), after.successional()
    ca, cb = before.contacts, after.contacts

    def principal_at(run: tuple[int, ...], contacts: tuple[DiscreteContact, ...]) -> list[int]:
        top = principal([contacts[k] for k in run])
        seen: list[DiscreteContact] = []
        out = []
        for k in run:
            if contacts[k] in top and contacts[k] not in seen:
                seen.append(contacts[k])
                out.append(k)
        return out

    out: list[Change] = []
    pairs = match(
        [tuple(ca[k] for k in r) for r in runs_a],
        [tuple(cb[k] for k in r) for r in runs_b],
        [_hull([pos_a[k] for k in r]) for r in runs_a],
        [_hull([pos_b[k] for k in r]) for r in runs_b],
    )
    for i, j in pairs:
        ra = runs_a[i] if i is not None else ()
        rb = runs_b[j] if j is not None else ()
        ka, kb = principal_at(ra, ca), principal_at(rb, cb)
        xr, yr = tuple(ca[k] for k in ra), tuple(cb[k] for k in rb)
        # an unmatched run: its principal contacts pair with N, not with contacts of other runs
        whole = (ca, cb) if i is not None and j is not None else ((), ())
        for x, y in pair_principals(
            [ca[k] for k in ka], [cb[k] for k in kb], *whole, [pos_a[k] for k in ka], [pos_b[k] for k in kb]
        ):
            out.append(Change((x,) if x else (), (y,) if y else (), xr, yr, False, cb))
    if through_free:
        flown = _flown(out)
        out = [replace(c, through_free=True) if k in flown else c for k, c in enumerate(out)]
    return out


def _flown(chs: Sequence[Change]) -> set[int]:
    """Which changes of a flight step flew (docs/model.md, 4.1): the flight belongs to the
    successional contact that left an instable contact and landed, not to the others of the step.

    Where an instable contact is released to ``N`` and another contact appears from ``N``, the flight
    is that pair (``S`` and ``E`` already): no matched change flew. Else the changes whose instable
    ``X`` became a contact that is not instable flew; where none did (the cable landed on a ridge or
    a corner), those whose instable ``X`` became another instable contact."""
    if any(not c.y and is_instable(c.x) for c in chs) and any(not c.x and c.y for c in chs):
        return set()
    landed = [k for k, c in enumerate(chs) if c.y and is_instable(c.x)]
    calm = {k for k in landed if not is_instable(chs[k].y)}
    return calm or set(landed)


def classify_step(
    before: DiscreteSituation,
    after: DiscreteSituation,
    through_free: bool = False,
    rules: Sequence[Rule] = RULES,
) -> tuple[str, ...]:
    """Transition classes of the step ``before -> after``; ``()`` is written ``-``.

    ``through_free``: the DLO passed through free space ``N`` on the way (a flight, kept situations
    mark it in :attr:`Kept.through_free`).
    """
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


class _KeptLike(Protocol):
    @property
    def situation(self) -> Any: ...  # read-only: frozen dataclasses (TimedSituation) are kept too


def kept_classes(kept: Sequence[_KeptLike]) -> list[tuple[str, ...]]:
    """Classes of the transition into each kept situation (``()`` for the first), flights included.

    ``kept``: :class:`Kept` entries, or anything with ``situation`` and optionally ``through_free``
    (e.g. :class:`dlovr.model.program.TimedSituation`).
    """
    return [
        classify_step(kept[i - 1].situation, k.situation, bool(getattr(k, "through_free", False)))
        if i
        else ()
        for i, k in enumerate(kept)
    ]


# --------------------------------------------------------------------------------------------------
# Debouncing a per-step stream of situations (docs/model.md, From a simulation to a sequence)
# --------------------------------------------------------------------------------------------------

S = TypeVar("S", bound=Hashable)

DEFAULT_HOLD_S = 0.01
"""Default flicker hold time (s): about 10 ms suppresses flicker and still keeps real semi-stable states."""

DEFAULT_FLIGHT_S = 0.3
"""Default flight time (s): a DLO tip falls 4 cm in about 0.09 s."""


@dataclass
class Kept(Generic[S]):
    """A kept situation: when it began and until when it held (seconds, simulation time).

    ``through_free``: it was reached by a flight (the DLO left an instable contact for free space
    and landed here within the flight time; the flight lasted from the previous kept situation's
    ``end`` to this one's ``start``). ``left``: when the stream first left it (``None`` while it
    holds; bookkeeping for flicker).
    """

    situation: S
    start: float
    end: float
    through_free: bool = False
    left: float | None = field(default=None, compare=False, repr=False)

    @property
    def duration(self) -> float:
        return self.end - self.start


def is_flight(before: DiscreteSituation, free: DiscreteSituation, after: DiscreteSituation) -> bool:
    """Is ``before -> free -> after`` a flight: an instable principal contact released to ``N``, then
    a contact established again?"""
    if not any(c.state.stability_class is Stability.INSTABLE for c in before.contacts):
        return False  # nothing instable to release: what the changes would say, without them
    released = any(is_instable(ch.x) and not ch.y for ch in _changes_of(before, free))
    return released and any(not ch.x and ch.y for ch in _changes_of(free, after))


_CHANGES_KEPT = 4
"""How many pairs' changes :func:`_changes_of` keeps."""

_changes_memo: list[tuple[DiscreteSituation, DiscreteSituation, tuple[Change, ...]]] = []


def _changes_of(a: DiscreteSituation, b: DiscreteSituation) -> tuple[Change, ...]:
    """:func:`changes` of ``a -> b`` (no flight), kept for the last few pairs of the very same objects
    (situations are frozen, so the same objects give the same changes): a debouncer asks
    :func:`is_flight` of the last two kept situations and the new one, so the pair ``free -> after``
    of one step is the pair ``before -> free`` of the next, and a step may ask twice."""
    memo = _changes_memo
    for x, y, got in tuple(memo):  # a copy: another thread may change the list meanwhile
        if x is a and y is b:
            return got
    got = tuple(changes(a, b))
    memo.insert(0, (a, b, got))
    del memo[_CHANGES_KEPT:]
    return got


#: :class:`Debouncer`'s default ``lands``, for S = DiscreteSituation (the debouncer of the tracker, of a
#: sequence and of a recording).
_LANDS_DISCRETE = cast("Callable[[Any, Any, Any], bool]", is_flight)


@dataclass
class Debouncer(Generic[S]):
    """Turns a per-step stream of situations into the demonstration's distinct situations.

    - **flicker**: an excursion ``A -> B1 -> … -> Bk -> A`` that returns to ``A`` within ``hold``
      (s, from leaving ``A`` to coming back) counts as ``A`` throughout, whatever the ``Bi``;
    - a brief ``B`` (shorter than ``hold``) in ``A -> B -> C`` (``C != A``) is kept when
      ``transient(B)`` (semi-stable or instable: it tells what kind of transition happened), else
      dropped as noise;
    - **flight**: ``A -> F -> C`` where ``lands(A, F, C)`` (``A`` releases an instable contact to
      ``N`` in ``F``, ``C`` establishes a contact again) and ``F`` held less than ``flight`` (s):
      ``F`` is not kept, and ``C`` is marked :attr:`Kept.through_free` (the step ``A -> C`` is
      classed ``S,E``); a longer ``F`` is kept;
    - every kept situation records its start and end time.

    Feed samples in time order with :meth:`push`; :attr:`kept` is the result so far (its last
    entries may still change while the stream goes on, for up to ``max(hold, flight)``).
    """

    hold: float
    transient: Callable[[S], bool]
    flight: float = DEFAULT_FLIGHT_S
    lands: Callable[[S, S, S], bool] = _LANDS_DISCRETE
    kept: list[Kept[S]] = field(default_factory=list)
    #: ``transient``'s answers by the situation's identity (the situation kept beside its answer):
    #: a stream's situations are often the same objects again (a simulation's flicker between a few)
    _transient_of: dict[int, tuple[S, bool]] = field(
        default_factory=dict, init=False, repr=False, compare=False
    )

    def __post_init__(self) -> None:
        if self.hold < 0:
            raise ValueError(f"hold time must be >= 0 s, got {self.hold}")
        if self.flight < 0:
            raise ValueError(f"flight time must be >= 0 s, got {self.flight}")

    def push(self, t: float, situation: S) -> None:
        k = self.kept
        if k and (k[-1].situation is situation or k[-1].situation == situation):
            k[-1].end = t
            return
        if k:
            k[-1].end = k[-1].left = t
        # flicker: back to an earlier situation within the hold time of leaving it
        for j in range(len(k) - 2, -1, -1):
            left = k[j].left
            if left is not None and t - left >= self.hold:
                break
            if k[j].situation == situation:
                del k[j + 1 :]
                k[j].end, k[j].left = t, None
                return
        through = False
        flies = self._flies(t, situation)
        if not flies and len(k) >= 2:
            b = k[-1]
            if b.duration < self.hold and not self._is_transient(b.situation):  # brief stable noise
                k.pop()
                if not b.through_free:  # after a flight the one before keeps its end (when it was left)
                    k[-1].end = b.end
                through = b.through_free
                flies = self._flies(t, situation)  # asked again of the kept ones left
        if flies:
            k.pop()  # the free interval; the one before it keeps its end (when it was left)
            through = True
        k.append(Kept(situation, t, t, through))

    def extend(self, t: float) -> None:
        """The situation pushed last holds at ``t`` too: what :meth:`push` does with one equal to it,
        for a caller that knows so already (the tracker compared it with the last step's)."""
        self.kept[-1].end = t

    def _is_transient(self, situation: S) -> bool:
        """``self.transient(situation)``, kept by the situation's identity (at most 256, then none)."""
        memo = self._transient_of
        got = memo.get(id(situation))
        if got is None or got[0] is not situation:
            if len(memo) >= 256:
                memo.clear()
            got = memo[id(situation)] = (situation, self.transient(situation))
        return got[1]

    def _flies(self, t: float, situation: S) -> bool:
        """Does ``situation`` end a flight that began with the last kept situation?"""
        k = self.kept
        return (
            len(k) >= 2
            and t - k[-1].start < self.flight
            and k[-2].situation != situation
            and self.lands(k[-2].situation, k[-1].situation, situation)
        )

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
