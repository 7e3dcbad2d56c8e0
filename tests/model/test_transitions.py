"""Transition classes (docs/model.md, paper §V): rules, matching, ties, the Fig. 11 golden case, and
debouncing (flicker, brief intermediate states, flights)."""

from __future__ import annotations

import itertools
from dataclasses import replace
from pathlib import Path

import pytest

from dlovr.model.discrete import parse_discrete_contact
from dlovr.model.discrete import parse_discrete_situation as P
from dlovr.model.transitions import (
    DEFAULT_FLIGHT_S,
    RULES,
    Change,
    Debouncer,
    changes,
    classify_change,
    classify_sequence,
    classify_step,
    is_transient,
    kept_classes,
    match,
    pair_principals,
    principal,
    successional_contacts,
)

FIG11 = Path(__file__).parents[1] / "data" / "fig11.txt"
FIG11_CLASSES = ["-", "E", "C", "-", "C", "C", "E", "I", "S,E", "E"]


def fig11_situations():
    return [P(line) for line in FIG11.read_text().splitlines() if line.strip() and not line.startswith("#")]


def test_fig11_golden_case_all_ten_steps():
    steps = classify_sequence(fig11_situations())
    assert [s.label for s in steps] == FIG11_CLASSES


def test_principal_contacts_are_highest_card_per_successional_contact():
    s = P("V/G & E/N & E/VS[b.F2,h.F5,h.F6] & E/E^LS[b.F2,h.F5] & V/E^LS[b.F2,h.F5]")
    (run,) = successional_contacts(s)
    assert [c.format() for c in principal(run)] == ["E/E^LS[b.F2,h.F5]"]
    tie = P("V/G & E/N & E/E^LS[b.F2,h.F5] & E/VS[b.F2,h.F5,h.F6] & V/VS[b.F2,h.F5,c.F7]")
    assert [c.state.name for c in principal(successional_contacts(tie)[0])] == ["E/E^LS", "V/VS"]


def test_gripper_and_free_contacts_are_not_principal():
    s = P("V/G & E/F[t.F1] & E/N & V/N")
    assert [[c.format() for c in r] for r in successional_contacts(s)] == [["E/F[t.F1]"]]


def test_matching_by_shared_objects_and_order():
    a = successional_contacts(P("V/G & E/F[a.F1] & E/N & E/F[b.F1] & V/N"))
    b = successional_contacts(P("V/G & E/N & E/F[b.F1] & E/N & E/F[c.F1] & V/N"))
    assert match(a, b) == [(0, None), (1, 0), (None, 1)]
    # without names, order decides
    a2 = successional_contacts(P("V/G & E/F & E/N & V/F"))
    b2 = successional_contacts(P("V/G & E/E^P & E/N & V/N"))
    assert match(a2, b2) == [(0, 0), (1, None)]


def test_no_principal_change_is_dash():
    a = P("V/G & E/N & E/F[block.F1] & V/N")
    b = P("V/G & E/N & E/F[block.F1] & E/E^P[block.F1,block.F2] & V/N")
    assert classify_step(a, b) == ()


def test_multi_class_step_from_two_successional_contacts():
    a = P("V/G & E/F[a.F1] & E/N & E/E^LI[b.F1,b.F2] & E/N & V/N")
    b = P("V/G & E/F[a.F1] & E/E^LS[a.F1,z.F2] & E/N & E/F[b.F2] & E/N & V/N")
    assert classify_step(a, b) == ("S", "E")  # first one hits a new object z, second snaps from a ridge


# --------------------------------------------------------------------------------------------------
# Each rule, and that its place in the order matters
# --------------------------------------------------------------------------------------------------


def ch(x, y, y_run=None, through_free=False):
    xs, ys = tuple(map(parse_discrete_contact, x)), tuple(map(parse_discrete_contact, y))
    yr = tuple(map(parse_discrete_contact, y_run)) if y_run is not None else ys
    return Change(xs, ys, xs, yr, through_free)


# (name, change, expected classes with the rules in the documented order)
RULE_CASES = [
    ("appear", ch([], ["E/F[a.F1]"]), ("E",)),
    ("disappear", ch(["E/F[a.F1]"], []), ("E",)),
    ("appear-instable", ch([], ["E/E^LI[a.F1,a.F2]"]), ("E",)),  # E before I
    ("appear-semi", ch([], ["E/E^LT[a.F1,a.F2]"]), ("E",)),
    ("instable-to-free", ch(["E/E^LI[a.F1,a.F2]"], []), ("S",)),  # the exception: S, not E
    ("snap-same-object", ch(["E/E^LI[a.F1,a.F2]"], ["E/F[a.F2]"]), ("S",)),
    ("snap-new-object", ch(["V/VI[b.F2,h.F3,h.F4]"], ["E/E^LS[b.F2,k.F5]"]), ("S", "E")),
    ("snap-through-free", ch(["V/E^LI[a.F1,a.F2]"], ["V/F[a.F2]"], through_free=True), ("S", "E")),
    ("instable-to-instable", ch(["V/E^LI[a.F1,a.F2]"], ["V/VI[a.F1,a.F2,a.F3]"]), ("I",)),  # still held
    (
        "flight-to-instable",
        ch(["V/E^LI[a.F1,a.F2]"], ["V/VI[a.F1,a.F2,a.F3]"], through_free=True),
        ("S", "E"),
    ),
    ("enter-instable", ch(["V/E^LS[b.F2,h.F3]"], ["V/VI[b.F2,h.F3,h.F4]"]), ("I",)),
    ("semi-to-instable", ch(["E/E^LT[a.F1,a.F2]"], ["E/E^LI[a.F2,a.F3]"]), ("I",)),  # I before T
    ("into-semi", ch(["E/F[a.F1]"], ["E/E^LT[a.F1,a.F2]"]), ("T",)),
    ("out-of-semi", ch(["E/E^LT[a.F1,a.F2]"], ["E/F[a.F2]"]), ("T",)),
    ("semi-new-object", ch(["E/E^LT[a.F1,a.F2]"], ["E/F[b.F1]"]), ("T",)),  # T before E
    ("new-obstacle", ch(["V/F[b.F2]"], ["V/E^LS[b.F2,h.F3]"]), ("E",)),
    ("lost-obstacle", ch(["V/E^LS[b.F2,h.F3]"], ["V/F[b.F2]"]), ("E",)),
    ("fig10a", ch(["E/F[A.F1]"], ["E/VS[A.F2,A.F3,A.F5]"]), ("C",)),  # one non-convex object
    ("fig10b", ch(["E/F[A.F1]"], ["E/VS[A.F1,B.F4,B.F5]"]), ("E",)),  # a second object is hit
    ("stable", ch(["V/F[a.F1]"], ["E/F[a.F1]"]), ("C",)),
    ("stable-edge", ch(["E/F[a.F1]"], ["E/E^P[a.F1,a.F2]"]), ("C",)),
    ("fallback-E", ch(["E/F"], ["E/VS"], y_run=["E/E^LI", "E/VS", "E/E^LI"]), ("E",)),
    ("fallback-C", ch(["E/F"], ["E/VS"], y_run=["E/F", "E/VS"]), ("C",)),
    (  # the new situation, not only the new run, holds the E/E^LI
        "fallback-E-elsewhere",
        replace(
            ch(["E/F"], ["E/VS"], y_run=["E/VS"]),
            after=tuple(map(parse_discrete_contact, ["V/G", "E/N", "E/VS", "E/N", "E/E^LI", "V/N"])),
        ),
        ("E",),
    ),
    ("no-names-stable", ch(["V/F"], ["E/F"]), ("C",)),
    ("unchanged", ch(["E/F[a.F1]"], ["E/F[a.F1]"]), ()),
]


@pytest.mark.parametrize(("name", "change", "expected"), RULE_CASES, ids=[c[0] for c in RULE_CASES])
def test_rule_cases(name, change, expected):
    assert classify_change(change) == expected


def _mismatches(rules):
    return [name for name, c, exp in RULE_CASES if classify_change(c, rules) != exp]


@pytest.mark.parametrize("k", range(len(RULES)), ids=[r.name for r in RULES])
def test_removing_any_rule_breaks_a_case(k):
    rules = RULES[:k] + RULES[k + 1 :]
    assert _mismatches(rules), f"no case depends on rule {RULES[k].name}"


@pytest.mark.parametrize(
    "k", range(len(RULES) - 1), ids=[f"{a.name}<->{b.name}" for a, b in itertools.pairwise(RULES)]
)
def test_swapping_adjacent_rules_breaks_a_case(k):
    rules = list(RULES)
    rules[k], rules[k + 1] = rules[k + 1], rules[k]
    assert _mismatches(rules), f"no case depends on the order of {RULES[k].name} and {RULES[k + 1].name}"


def test_rule_order_is_the_documented_one():
    assert [r.name for r in RULES] == ["S", "E-free", "I", "T", "E-object", "C"]


def test_fig10_pair_in_whole_situations():
    before = P("V/G & E/N & E/F[A.F1] & V/N")
    a = P("V/G & E/N & E/VS[A.F1,A.F2,A.F3] & V/N")
    b = P("V/G & E/N & E/E^LI[A.F1,A.F4] & E/VS[A.F1,B.F5,B.F6] & E/E^LI[A.F1,A.F7] & V/N")
    assert classify_step(before, a) == ("C",)
    assert classify_step(before, b) == ("E",)


def test_discrete_only_fallback_in_whole_situations():
    before = P("V/G & E/N & E/F & V/N")
    assert classify_step(before, P("V/G & E/N & E/VS & V/N")) == ("C",)
    assert classify_step(before, P("V/G & E/N & E/E^LI & E/VS & E/E^LI & V/N")) == ("E",)


# --------------------------------------------------------------------------------------------------
# Debouncing (§4.2)
# --------------------------------------------------------------------------------------------------

A = P("V/G & E/N & E/F[a.F1] & V/N")
B_STABLE = P("V/G & E/N & E/E^P[a.F1,a.F2] & V/N")
B_SEMI = P("V/G & E/N & E/E^LT[a.F1,a.F2] & V/N")
B_INST = P("V/G & E/N & E/E^LI[a.F1,a.F2] & V/N")
C = P("V/G & E/N & E/F[a.F2] & V/N")


def run(seq, hold=0.02, dt=0.002, debouncer=None):
    """seq: list of (situation, number of steps)."""
    d = debouncer or Debouncer(hold, is_transient)
    t = 0.0
    for sit, n in seq:
        for _ in range(n):
            d.push(round(t, 9), sit)
            t += dt
    return d.kept


def test_flicker_is_suppressed():
    kept = run([(A, 50), (B_INST, 3), (A, 50)])
    assert [k.situation for k in kept] == [A]
    assert kept[0].start == 0.0 and kept[0].end == pytest.approx(0.204)


def test_brief_unstable_intermediate_states_are_kept():
    for b in (B_INST, B_SEMI):
        kept = run([(A, 50), (b, 2), (C, 50)])
        assert [k.situation for k in kept] == [A, b, C]
        assert kept[1].duration == pytest.approx(0.004)


def test_brief_stable_intermediate_state_is_noise():
    kept = run([(A, 50), (B_STABLE, 3), (C, 50)])
    assert [k.situation for k in kept] == [A, C]
    assert kept[0].end == kept[1].start


def test_long_states_are_kept_with_times():
    kept = run([(A, 50), (B_STABLE, 20), (A, 50)])
    assert [k.situation for k in kept] == [A, B_STABLE, A]
    assert [round(k.start, 3) for k in kept] == [0.0, 0.1, 0.14]


def test_is_transient_uses_principal_contacts():
    assert is_transient(B_INST) and is_transient(B_SEMI)
    assert not is_transient(P("V/G & E/N & E/F[a.F1] & E/E^LI[a.F1,a.F2] & V/N"))  # principal E/F stable
    with pytest.raises(ValueError):
        Debouncer(-1.0, is_transient)


def test_flicker_through_several_states_is_suppressed():
    # A -> Bi (2 ms) -> Bs (2 ms) -> A: one excursion back to A within the hold time
    kept = run([(A, 50), (B_INST, 1), (B_STABLE, 1), (A, 50)], hold=0.01)
    assert [k.situation for k in kept] == [A]
    kept = run([(A, 50), (B_INST, 2), (B_SEMI, 2), (B_STABLE, 2), (A, 50)], hold=0.02)
    assert [k.situation for k in kept] == [A]
    # measured from leaving A: a longer excursion is kept (the brief stable state as noise)
    kept = run([(A, 50), (B_INST, 5), (B_STABLE, 2), (A, 50)], hold=0.01)
    assert [k.situation for k in kept] == [A, B_INST, A]


# --------------------------------------------------------------------------------------------------
# Matching (which successional contact continues which) and ties (several principal contacts)
# --------------------------------------------------------------------------------------------------

RIDGE_TIP = "V/E^LI[table.F1,table.F2]"
BOTH = P(f"V/G & E/N & E/F[table.F1] & E/N & {RIDGE_TIP}")


def test_matching_keeps_the_unchanged_instable_run_when_the_near_run_lifts():
    near_lifts = P(f"V/G & E/N & {RIDGE_TIP}")
    a, b = successional_contacts(BOTH), successional_contacts(near_lifts)
    assert match(a, b) == [(0, None), (1, 0)]
    assert classify_step(BOTH, near_lifts) == ("E",)
    far_lifts = P("V/G & E/N & E/F[table.F1] & E/N & V/N")  # the mirror case: the tip snaps off
    assert classify_step(BOTH, far_lifts) == ("S",)


def test_matching_prefers_shared_faces_then_objects_and_never_pairs_strangers():
    a = successional_contacts(P("V/G & E/F[t.F1] & E/N & E/F[t.F2] & V/N"))
    b = successional_contacts(P("V/G & E/N & E/E^P[t.F2,t.F3] & V/N"))
    assert match(a, b) == [(0, None), (1, 0)]  # shares t.F2, although the first run comes first
    c = successional_contacts(P("V/G & E/N & E/F[u.F1] & V/N"))
    assert match(a, c) == [(0, None), (1, None), (None, 0)]


def _with_spans(sit, spans):
    return type(sit)(tuple(replace(c, span=s) for c, s in zip(sit.contacts, spans, strict=True)))


def test_matching_ties_go_to_the_most_overlapping_stretch_of_the_dlo():
    before = P("V/G & E/N & E/F[t.F1] & E/N & E/F[t.F1] & E/N & V/N")
    after = P("V/G & E/N & E/E^P[t.F1,t.F2] & E/N & V/N")
    # the new crossing lies where the second run lay: that run changed (C), the first lifted (E)
    b = _with_spans(before, [(0, 0), (1, 4), (5, 10), (11, 19), (20, 26), (27, 39), (40, 40)])
    a = _with_spans(after, [(0, 0), (1, 21), (22, 24), (25, 39), (40, 40)])
    pairs = [(ch.x, ch.y) for ch in changes(b, a)]
    assert [tuple(c.format() for c in x + y) for x, y in pairs] == [
        ("E/F[t.F1]",),
        ("E/F[t.F1]", "E/E^P[t.F1,t.F2]"),
    ]
    assert pairs[1][0][0].span == (20, 26)
    a = _with_spans(after, [(0, 0), (1, 6), (7, 9), (10, 39), (40, 40)])
    assert changes(b, a)[0].x[0].span == (5, 10)  # now the first run's stretch
    # overlap wins over nearness: a long run overlapping the new stretch, a short one nearer to it
    before = P("V/G & E/F[t.F1] & E/N & E/F[t.F1] & E/N & V/N")
    b = _with_spans(before, [(0, 0), (1, 30), (31, 33), (34, 36), (37, 39), (40, 40)])
    a = _with_spans(after, [(0, 0), (1, 27), (28, 33), (34, 39), (40, 40)])
    assert [c.x[0].span for c in changes(b, a)] == [(1, 30), (34, 36)]
    assert [c.y for c in changes(b, a)][1] == ()


def test_matching_without_overlap_goes_to_the_nearest_stretch_then_to_shared_objects():
    # neither old run overlaps the new one: the nearer (the second) continues, the first lifted
    before = P("V/G & E/N & E/F[t.F1] & E/N & E/F[t.F1] & E/N & V/N")
    after = P("V/G & E/N & E/E^P[t.F1,t.F2] & E/N & V/N")
    b = _with_spans(before, [(0, 0), (1, 1), (2, 5), (6, 19), (20, 25), (26, 39), (40, 40)])
    a = _with_spans(after, [(0, 0), (1, 26), (27, 29), (30, 39), (40, 40)])
    assert [(c.x[0].span, c.y[0].span if c.y else None) for c in changes(b, a)] == [
        ((2, 5), None),
        ((20, 25), (27, 29)),
    ]
    # a run without face names may match anything; a run sharing an object is preferred to it,
    # although the unnamed one overlaps the new run and the named one does not
    a = successional_contacts(P("V/G & E/F & E/N & E/F[t.F1] & E/N & V/N"))
    b = successional_contacts(P("V/G & E/E^P[t.F2,t.F3] & E/N & V/N"))
    assert match(a, b, [(1 / 6, 2 / 6), (3 / 6, 4 / 6)], [(1 / 4, 2 / 4)]) == [(0, None), (1, 0)]


def test_ties_pair_principal_contacts_as_sets():
    # principals {E/E^P, E/E^LI} (card 6 both): E/E^P becomes E/F, E/E^LI stays -> C, not S
    before = P("V/G & E/N & E/E^P[a.F1,a.F2] & E/E^LI[a.F3,a.F4] & V/N")
    after = P("V/G & E/N & E/F[a.F1] & E/E^LI[a.F3,a.F4] & V/N")
    (run_b,), (run_a,) = successional_contacts(before), successional_contacts(after)
    assert [c.state.name for c in principal(run_b)] == ["E/E^P", "E/E^LI"]
    pairs = pair_principals(principal(run_b), principal(run_a), before.contacts, after.contacts)
    assert [(x.format(), y.format()) for x, y in pairs] == [("E/E^P[a.F1,a.F2]", "E/F[a.F1]")]
    assert classify_step(before, after) == ("C",)
    # a principal contact that vanishes altogether pairs with N
    gone = P("V/G & E/N & E/F[a.F1] & V/N")
    assert classify_step(before, gone) == ("S", "C")


def test_ties_prefer_contacts_absent_from_the_other_situation():
    # E/E^P[b] was there before (not principal): pair the vanished E/F with it anyway (Fig. 11, step 5)
    x = P("V/G & E/N & E/F[b.F1] & E/E^P[b.F1,b.F2] & V/N")
    y = P("V/G & E/N & E/E^P[b.F1,b.F2] & V/N")
    assert classify_step(x, y) == ("C",)
    # both principals share a face with the new E/F and the ridge lies nearer to it, but the ridge
    # is still there: E/E^P -> E/F (C), not E/E^LI -> E/F (S) with E/E^P -> N (E)
    x = P("V/G & E/N & E/E^LI[a.F1,a.F3] & E/E^P[a.F1,a.F2] & V/N")
    y = P("V/G & E/N & E/F[a.F1] & E/E^LI[a.F1,a.F3] & V/N")
    assert classify_step(x, y) == ("C",)
    # a new principal beside one that stays (Fig. 11, step 10): the new one pairs with N
    x = P("V/G & E/N & E/E^LS[b.F2,h.F5] & V/E^LS[b.F2,h.F5]")
    y = P("V/G & E/N & E/E^LS[b.F2,h.F5] & V/VS[b.F2,h.F5,c.F7]")
    assert [(ch.x, [c.format() for c in ch.y]) for ch in changes(x, y)] == [((), ["V/VS[b.F2,c.F7,h.F5]"])]


def test_ties_a_contact_that_joins_the_principal_set_is_unchanged():
    # E/E^P[a.F1,a.F2] was there before (below the principal E/F) and is principal now, unchanged:
    # it merely joined the principal set, so it is no N -> E/E^P (E); the vanished E/F pairs with
    # the new E/E^P[a.F2,a.F3] (absent before): C only
    x = P("V/G & E/N & E/F[a.F1] & E/E^P[a.F1,a.F2] & V/N")
    y = P("V/G & E/N & E/E^P[a.F1,a.F2] & E/E^P[a.F2,a.F3] & V/N")
    assert [(c.x[0].format(), c.y[0].format()) for c in changes(x, y)] == [("E/F[a.F1]", "E/E^P[a.F2,a.F3]")]
    assert classify_step(x, y) == ("C",)


def test_ties_prefer_shared_objects_then_the_nearest_contact():
    # two principal crossings vanish, one new crossing on b: it continues the crossing on b (C),
    # although the one on a lies nearer to it; the one on a lifted (E)
    x = P("V/G & E/N & E/E^P[b.F1,b.F2] & E/E^P[a.F1,a.F2] & V/N")
    y = P("V/G & E/N & E/E^P[b.F3,b.F4] & V/N")
    assert [c.x[0].format() for c in changes(x, y)] == ["E/E^P[b.F1,b.F2]", "E/E^P[a.F1,a.F2]"]
    assert classify_step(x, y) == ("E", "C")
    # all else equal, the nearest along the DLO: the second crossing continues, the first lifted
    x = P("V/G & E/N & E/E^P[a.F1,a.F2] & E/E^P[a.F3,a.F4] & V/N")
    y = P("V/G & E/N & E/E^P[a.F5,a.F6] & V/N")
    x = _with_spans(x, [(0, 0), (1, 4), (5, 6), (7, 8), (9, 40)])
    y = _with_spans(y, [(0, 0), (1, 7), (8, 9), (10, 40)])
    pairs = [(c.x[0].span, c.y[0].span if c.y else None) for c in changes(x, y)]
    assert pairs == [((5, 6), None), ((7, 8), (8, 9))]


def test_instable_to_instable_is_I_in_whole_situations():
    a = P("V/G & E/N & V/E^LI[h.F2,h.F5]")
    assert classify_step(a, P("V/G & E/N & V/VI[h.F2,h.F3,h.F5]")) == ("I",)
    assert classify_step(a, P("V/G & E/N & V/E^LI[h.F3,h.F5]")) == ("I",)  # faces alone changed
    assert classify_step(a, P("V/G & E/N & V/F[h.F2]")) == ("S",)


# --------------------------------------------------------------------------------------------------
# Flight (S,E through N)
# --------------------------------------------------------------------------------------------------

RIDGE = P("V/G & E/N & V/E^LI[a.F1,a.F2]")
FREE = P("V/G & E/N & V/N")
LANDED = P("V/G & E/N & V/F[a.F2]")


def test_a_short_flight_is_one_S_E_transition():
    for n_free in (3, 30, 140):  # 6 ms (shorter than the hold time), 60 ms, 280 ms
        d = Debouncer(0.02, is_transient, flight=0.3)
        kept = run([(RIDGE, 50), (FREE, n_free), (LANDED, 50)], debouncer=d)
        assert [k.situation for k in kept] == [RIDGE, LANDED], n_free
        assert kept[1].through_free and not kept[0].through_free
        assert kept[0].end == pytest.approx(0.1) and kept[1].start == pytest.approx(0.1 + 0.002 * n_free)
        assert kept_classes(kept) == [(), ("S", "E")]
    assert Debouncer(0.02, is_transient).flight == DEFAULT_FLIGHT_S == 0.3


def test_a_flight_that_lands_through_a_brief_contact_keeps_its_times():
    """Leaving the ridge through a 4 ms stable contact, then 200 ms free, then 4 ms on another face
    before the landing that holds (peg_in_hole's drop into the hole): one S,E step, and the ridge
    still ends when the cable left it, not when it landed (the flight lies between them)."""
    brief_on, brief_off = P("V/G & E/N & E/F[a.F3] & V/N"), P("V/G & E/N & E/F[a.F4] & V/N")
    kept = run([(RIDGE, 50), (brief_on, 2), (FREE, 100), (brief_off, 2), (LANDED, 50)], hold=0.02)
    assert [k.situation for k in kept] == [RIDGE, LANDED]
    assert kept_classes(kept) == [(), ("S", "E")] and kept[1].through_free
    assert kept[0].end == pytest.approx(0.104) and kept[1].start == pytest.approx(0.308)


def test_a_long_free_interval_is_kept_S_then_E():
    kept = run([(RIDGE, 50), (FREE, 160), (LANDED, 50)], hold=0.02)  # 320 ms > 0.3 s
    assert [k.situation for k in kept] == [RIDGE, FREE, LANDED]
    assert kept_classes(kept) == [(), ("S",), ("E",)]
    kept = run([(RIDGE, 50), (FREE, 30), (LANDED, 50)], debouncer=Debouncer(0.02, is_transient, flight=0.05))
    assert [k.situation for k in kept] == [RIDGE, FREE, LANDED]


def test_no_flight_without_an_instable_release_or_a_landing():
    lying = P("V/G & E/N & V/F[a.F1]")
    kept = run([(lying, 50), (FREE, 30), (LANDED, 50)], hold=0.02)  # lifted off a stable contact
    assert [k.situation for k in kept] == [lying, FREE, LANDED]
    ridge = P("V/G & E/F[b.F1] & E/N & V/E^LI[a.F1,a.F2]")
    off = P("V/G & E/F[b.F1] & E/N & V/N")
    kept = run([(ridge, 50), (off, 30), (FREE, 50)], hold=0.02)  # then the other run lifts: no landing
    assert [k.situation for k in kept] == [ridge, off, FREE]
    elsewhere = P("V/G & E/F[b.F1] & E/N & V/N")  # landing with another part of the cable is a landing
    kept = run([(RIDGE, 50), (FREE, 30), (elsewhere, 50)], hold=0.02)
    assert [k.situation for k in kept] == [RIDGE, elsewhere] and kept_classes(kept)[1] == ("S", "E")
    with pytest.raises(ValueError, match="flight"):
        Debouncer(0.01, is_transient, flight=-1.0)


# --------------------------------------------------------------------------------------------------
# Runs without a partner; the flight belongs to the run that flew (issue 27)
# --------------------------------------------------------------------------------------------------


def test_an_unmatched_run_pairs_with_N_whatever_the_other_runs_hold():
    """A split, a merge, an equal-state run appearing or leaving: the run without a partner is E, even
    when an equal contact lies in another run of the other situation (docs/model.md 4.2)."""
    one = P("V/G & E/N & E/F[table.F1] & V/N")
    two = P("V/G & E/N & E/F[table.F1] & E/N & E/F[table.F1] & V/N")
    assert classify_step(one, two) == ("E",) and classify_step(two, one) == ("E",)
    [c] = changes(one, two)
    assert not c.x and [str(y) for y in c.y] == ["E/F[table.F1]"]
    three = P("V/G & E/N & E/F[table.F1] & E/N & E/E^LI[table.F1,table.F2] & E/N & E/F[table.F1] & V/N")
    assert classify_step(two, three) == ("E",)  # a ridge run appears between the two


def test_a_flight_flags_only_the_changes_that_flew():
    ridge_and_tip = P("V/G & E/N & E/E^LI[box.F1,box.F2] & E/N & V/E^LI[crate.F1,crate.F2]")
    landed = P("V/G & E/N & E/E^LI[box.F2,box.F3] & E/N & V/F[crate.F2]")
    got = {(str(c.x[0]), c.through_free) for c in changes(ridge_and_tip, landed, through_free=True)}
    assert got == {("E/E^LI[box.F1,box.F2]", False), ("V/E^LI[crate.F1,crate.F2]", True)}
    assert classify_step(ridge_and_tip, landed, through_free=True) == ("S", "I", "E")
    # released to N and landed elsewhere: the pair is S and E; the other run's change keeps its class
    table = P("V/G & E/N & E/E^LI[box.F2,box.F3] & E/N & V/F[table.F1]")
    assert not any(c.through_free for c in changes(ridge_and_tip, table, through_free=True))
    assert classify_step(ridge_and_tip, table, through_free=True) == ("S", "I", "E")
    # landing on a ridge or corner: the instable -> instable change flew
    assert classify_step(RIDGE, P("V/G & E/N & V/VI[a.F1,a.F2,a.F3]"), through_free=True) == ("S", "E")
    assert classify_step(RIDGE, P("V/G & E/N & V/VI[a.F1,a.F2,a.F3]")) == ("I",)


def test_the_flight_test_remembers_changes_by_the_very_same_situations_only():
    """is_flight keeps the changes of the last few pairs of situation objects (the per-step path asks
    twice of the same pair): a pair asked again, reversed, or of equal but other objects gives what
    :func:`changes` gives, and so does is_flight."""
    from dlovr.model.transitions import _changes_of, is_flight

    ridge, free, landed = RIDGE, FREE, LANDED
    assert _changes_of(ridge, free) == tuple(changes(ridge, free))
    assert _changes_of(ridge, free) is _changes_of(ridge, free)  # remembered
    assert _changes_of(free, ridge) == tuple(changes(free, ridge)) != _changes_of(ridge, free)
    twin = P(ridge.format())
    assert twin == ridge and twin is not ridge
    assert _changes_of(twin, free) == tuple(changes(ridge, free))
    assert is_flight(ridge, free, landed) and is_flight(twin, P(free.format()), landed)
    assert not is_flight(landed, free, ridge) and not is_flight(ridge, free, free)
    state = ridge.contacts[-1].state
    assert state.card == state.dim_dlo + 2 * state.dof_trans + 3 * state.dof_blocked
    assert ridge.contacts[-1].objects == frozenset({"a"})


def test_extend_is_push_of_the_situation_pushed_last():
    """Debouncer.extend (the tracker's step whose discrete situation equals the last one) does what
    push does with an equal situation, flicker and flights unchanged."""
    samples = [(RIDGE, 50), (FREE, 30), (LANDED, 50), (RIDGE, 3), (LANDED, 40)]
    a, b = Debouncer(0.02, is_transient), Debouncer(0.02, is_transient)
    t = 0.0
    for sit, n in samples:
        for k in range(n):
            t += 0.002
            a.push(t, P(sit.format()))
            if k:
                b.extend(t)
            else:
                b.push(t, sit)
    assert a.kept == b.kept and [k.situation for k in a.kept] == [RIDGE, LANDED]


def test_the_debouncer_asks_transient_once_per_situation_object():
    """``transient`` is asked once of a situation object however often a flicker brings it back
    (kept by identity); equal but other objects are asked again; the kept situations are the same."""
    from dlovr.model.transitions import Debouncer

    def run(fresh: bool) -> tuple[list[object], list[object]]:
        asked: list[object] = []

        def transient(s: object) -> bool:
            asked.append(s)
            return s == ("T",)

        deb = Debouncer(0.05, transient, flight=0.0, lands=lambda *_: False)
        shared = {name: (name,) for name in "ABCT"}
        for k, name in enumerate("ABCTABCTBCTB" * 3 + "A"):  # brief ones, transient or not
            deb.push(0.02 * k, tuple([name]) if fresh else shared[name])  # tuple([...]): a new object
        return [(k.situation, k.start, k.end) for k in deb.kept], asked

    kept, asked = run(fresh=False)
    kept_fresh, asked_fresh = run(fresh=True)
    assert kept == kept_fresh and len(kept) > 3
    assert len(asked) == len({id(s) for s in asked}) <= 4 < len(asked_fresh)
