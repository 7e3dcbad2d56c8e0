"""Transition classes (MODEL.md §4), the Fig. 11 golden case (§4.1) and debouncing (§4.2)."""

from __future__ import annotations

import itertools
from pathlib import Path

import pytest

from dlovr.model.discrete import parse_discrete_contact
from dlovr.model.discrete import parse_discrete_situation as P
from dlovr.model.transitions import (
    RULES,
    Change,
    Debouncer,
    classify_change,
    classify_sequence,
    classify_step,
    is_transient,
    match,
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


# (name, change, expected classes with the rules in MODEL.md order)
RULE_CASES = [
    ("appear", ch([], ["E/F[a.F1]"]), ("E",)),
    ("disappear", ch(["E/F[a.F1]"], []), ("E",)),
    ("appear-instable", ch([], ["E/E^LI[a.F1,a.F2]"]), ("E",)),  # E before I
    ("appear-semi", ch([], ["E/E^LT[a.F1,a.F2]"]), ("E",)),
    ("instable-to-free", ch(["E/E^LI[a.F1,a.F2]"], []), ("S",)),  # the exception: S, not E
    ("snap-same-object", ch(["E/E^LI[a.F1,a.F2]"], ["E/F[a.F2]"]), ("S",)),
    ("snap-new-object", ch(["V/VI[b.F2,h.F3,h.F4]"], ["E/E^LS[b.F2,k.F5]"]), ("S", "E")),
    ("snap-through-free", ch(["V/E^LI[a.F1,a.F2]"], ["V/F[a.F2]"], through_free=True), ("S", "E")),
    ("snap-to-instable", ch(["V/E^LI[a.F1,a.F2]"], ["V/VI[a.F1,a.F2,a.F3]"]), ("S",)),  # S before I
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


def run(seq, hold=0.02, dt=0.002):
    """seq: list of (situation, number of steps)."""
    d = Debouncer(hold, is_transient)
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
