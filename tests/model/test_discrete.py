"""Discrete contact states (docs/model.md, paper §IV): card (eq. 3), stability, contact vector (eq. 2),
classifier, pinches."""

from __future__ import annotations

import math
import re
from typing import Literal

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st

from dlovr.model.discrete import (
    AUX_STATES,
    FACE_COUNTS,
    STATES,
    ContactFacts,
    DiscreteContact,
    DiscreteSituation,
    DiscreteState,
    Discretizer,
    FaceFact,
    FactBook,
    ModelParams,
    PairFact,
    Stability,
    classify_contact,
    contact_vector,
    discretize,
    parse_discrete_situation,
    pinch_axis,
    state,
    without_internal,
)
from dlovr.model.topology import NotationError, parse_situation

# Fig. 8 as printed in the paper: state -> (card, stability)
FIG8 = {
    "E/F": (8, "S"), "E/E^P": (6, "S"), "E/E^LS": (9, "S"), "E/VS": (7, "S"),
    "V/F": (7, "S"), "V/E^LS": (8, "S"), "V/VS": (9, "S"),
    "E/E^LT": (9, "T"), "E/VT": (7, "T"), "V/E^LT": (8, "T"), "V/VT": (9, "T"),
    "E/E^LI": (6, "I"), "E/VI": (4, "I"), "V/E^LI": (5, "I"), "V/VI": (3, "I"),
}


def test_there_are_exactly_the_15_states_of_fig8():
    assert set(STATES) == set(FIG8)


@pytest.mark.parametrize("name", list(FIG8))
def test_card_of_every_state_matches_fig8(name):
    assert STATES[name].card == FIG8[name][0]


@pytest.mark.parametrize("name", list(FIG8))
def test_card_is_eq3_from_dim_and_dofs(name):
    s = STATES[name]
    assert s.card == s.dim_dlo + 2 * s.dof_trans + 3 * s.dof_blocked
    assert s.dim_dlo == (0 if name.startswith("V") else 1)


def test_eq3_worked_example_of_the_paper():
    s = STATES["E/E^LS"]  # card(E/E^LS) = 1 + 2·1 + 3·2 = 9
    assert (s.dim_dlo, s.dof_trans, s.dof_blocked, s.card) == (1, 1, 2, 9)


@pytest.mark.parametrize("name", list(FIG8))
def test_stability_class_of_every_state_matches_fig8(name):
    assert STATES[name].stability_class == Stability(FIG8[name][1])


def test_point_and_line_kinds():
    line = {n for n, s in STATES.items() if s.contact_kind == "line"}
    assert line == {"E/F", "E/E^LS", "E/E^LT", "E/E^LI"}  # vertex states and E^P are point contacts


def test_aux_states_are_not_principal_kinds():
    assert set(AUX_STATES) == {"V/G", "E/G", "V/N", "E/N"}
    assert all(not s.is_principal_kind and s.stability_class is None for s in AUX_STATES.values())
    assert all(s.is_principal_kind for s in STATES.values())
    assert AUX_STATES["V/N"].card < min(s.card for s in STATES.values())


def test_invalid_states_are_rejected():
    with pytest.raises(ValueError, match="stability"):
        DiscreteState("E", "V")
    with pytest.raises(ValueError, match="no stability"):
        DiscreteState("E", "F", "S")  # face contacts are always stable: E/FS does not exist
    with pytest.raises(ValueError, match="V/E\\^P"):
        DiscreteState("V", "E^P")
    with pytest.raises(ValueError, match="unknown"):
        state("E/X")


# --------------------------------------------------------------------------------------------------
# Contact vector, eq. 2
# --------------------------------------------------------------------------------------------------


def ff(name, normal, internal=False):
    n = np.asarray(normal, float)
    n = n / np.linalg.norm(n)
    return FaceFact(name, name.rpartition(".")[0], tuple(n), internal)


UP, X, Y = (0, 0, 1), (1, 0, 0), (0, 1, 0)


def test_contact_vector_face():
    np.testing.assert_allclose(contact_vector(ContactFacts((ff("t.F1", UP),))), [0, 0, -1])


def test_contact_vector_edge_sums_and_normalises():
    c = contact_vector(ContactFacts((ff("b.F1", UP), ff("b.F2", X))))
    np.testing.assert_allclose(c, np.array([-1, 0, -1]) / math.sqrt(2))


def test_contact_vector_vertex():
    c = contact_vector(ContactFacts((ff("b.F1", UP), ff("b.F2", X), ff("b.F3", Y))))
    np.testing.assert_allclose(c, -np.ones(3) / math.sqrt(3))


def test_contact_vector_multiple_contact_counts_each_face_once_and_drops_internal():
    # E/(b.F1 ∩ b.F2) + E/(b.F1 ∩ c.F4): b.F1 appears twice, c.F9 is an internal cut face
    facts = ContactFacts(
        (ff("b.F1", UP), ff("b.F2", X), ff("b.F1", UP), ff("c.F4", Y), ff("c.F9", (0, 0, -1), True))
    )
    np.testing.assert_allclose(contact_vector(facts), -np.ones(3) / math.sqrt(3))


def test_contact_vector_gripper_is_its_z_axis():
    np.testing.assert_allclose(contact_vector(ContactFacts((), gripper_z=(0, 0, 2)), gripper=True), [0, 0, 1])


def test_contact_vector_free_space_is_zero():
    np.testing.assert_array_equal(contact_vector(ContactFacts(())), np.zeros(3))
    assert pinch_axis(ContactFacts(())) is None


def test_a_pinch_between_opposite_faces_is_a_defined_case():
    # the DLO clamped between a floor (b.F1, up) and a ceiling (a.F2, down): the normals cancel
    floor, ceiling = ff("b.F1", UP), ff("a.F2", (0, 0, -1))
    facts = ContactFacts((floor, ceiling))
    np.testing.assert_array_equal(contact_vector(facts), np.zeros(3))  # eq. 2 sums to zero
    np.testing.assert_array_equal(pinch_axis(facts), [0, 0, -1])  # the first face's (a.F2) normal
    assert classify_contact("E", facts) == STATES["E/F"]  # one normal direction: a face contact
    book = FactBook({f.name: f for f in (floor, ceiling)})
    (_, c, _) = discretize(parse_situation("VS/G & E3/a.F2 + E3/b.F1 & VE/N"), book).contacts
    assert c.format() == "E/F[a.F2,b.F1]" and c.is_pinch
    assert c.vector == (0.0, 0.0, 0.0) and c.axis == (0.0, 0.0, -1.0)
    # within the merge angle of opposite still pinches; a wedge does not
    tilt = ff("a.F2", (math.sin(math.radians(0.005)), 0, -1))
    assert pinch_axis(ContactFacts((floor, tilt))) is not None
    wedge = ContactFacts((floor, ff("a.F2", (0.3, 0, -1))))
    assert pinch_axis(wedge) is None and abs(np.linalg.norm(contact_vector(wedge)) - 1) < 1e-9
    # normals that cancel around the DLO (three faces at 120°): zero vector, no axis
    angles = (0.0, 2 * math.pi / 3, 4 * math.pi / 3)
    ring = ContactFacts(tuple(ff(f"r.F{k}", (math.cos(a), math.sin(a), 0)) for k, a in enumerate(angles)))
    assert pinch_axis(ring) is None and np.linalg.norm(contact_vector(ring)) < 1e-4
    # a face contact is no pinch
    (_, one, _) = discretize(parse_situation("VS/G & E3/b.F1 & VE/N"), book).contacts
    assert not one.is_pinch and one.axis is None


@given(
    st.lists(
        st.tuples(*[st.floats(-1, 1)] * 3).filter(lambda v: np.linalg.norm(v) > 0.1), min_size=1, max_size=4
    )
)
def test_contact_vector_is_unit(normals):
    facts = ContactFacts(tuple(ff(f"o.F{i}", n) for i, n in enumerate(normals)))
    c = contact_vector(facts)
    if not c.any():  # faces whose normals cancel: a pinch
        assert np.linalg.norm(np.sum([f.normal for f in facts.faces], axis=0)) < 1e-3
        return
    assert abs(np.linalg.norm(c) - 1) < 1e-9


# --------------------------------------------------------------------------------------------------
# The §3.3 classifier, built from plain geometric facts
# --------------------------------------------------------------------------------------------------


def rot_x(deg):
    """Unit normal of a face tilted from the floor (+z) about the x axis by deg."""
    a = math.radians(deg)
    return (0.0, -math.sin(a), math.cos(a))


def pair(a, b, concave, opening):
    return PairFact(a, b, concave, opening)


# Grooves along x (crease direction x): floor t.F1 (+z) and a wall at the given opening angle.
def groove(opening_deg, concave=True):
    """Floor + wall meeting along the x axis with the given free-space opening angle."""
    alpha = 180.0 - opening_deg if concave else opening_deg - 180.0
    # concave: the wall rises on +y side facing -y-ish; convex: the second face bends down
    wall = ff("w.F2", rot_x(alpha if concave else -alpha))
    if not concave:
        wall = ff("w.F2", (0.0, math.sin(math.radians(alpha)), math.cos(math.radians(alpha))))
    return (ff("t.F1", UP), wall), (pair("t.F1", "w.F2", concave, opening_deg),)


def groove_facts(opening, concave=True, vec=X):
    fs, ps = groove(opening, concave)
    return ContactFacts(fs, ps, vec)


def corner_facts(concave=True, vec=(1, 1, 1), third_opening=90.0):
    """Three faces around a corner: concave (inside a box-shaped pocket) or convex (a box corner)."""
    if concave:
        fs = (ff("t.F1", UP), ff("w.F2", (-1, 0, 0)), ff("w.F3", rot_x(180 - third_opening)))
        ps = (
            pair("t.F1", "w.F2", True, 90),
            pair("t.F1", "w.F3", True, third_opening),
            pair("w.F2", "w.F3", True, 90),
        )
    else:
        fs = (ff("b.F1", UP), ff("b.F2", X), ff("b.F3", Y))
        ps = tuple(pair(a, b, False, 270) for a, b in (("b.F1", "b.F2"), ("b.F1", "b.F3"), ("b.F2", "b.F3")))
    return ContactFacts(fs, ps, vec)


CASES: dict[str, tuple[Literal["V", "E"], ContactFacts]] = {
    # 90° groove (table top + box side), DLO along it
    "E/E^LS": ("E", groove_facts(90)),
    "V/E^LS": ("V", groove_facts(90)),
    # 175° groove: concave but nearly flat
    "E/E^LT": ("E", groove_facts(175)),
    "V/E^LT": ("V", groove_facts(175)),
    # 270° ridge (box edge), DLO along it; crossing it is E/E^P
    "E/E^LI": ("E", groove_facts(270, concave=False)),
    "V/E^LI": ("V", groove_facts(270, concave=False)),
    "E/E^P": ("E", groove_facts(270, concave=False, vec=Y)),
    # face
    "E/F": ("E", ContactFacts((ff("t.F1", UP),), (), X)),
    "V/F": ("V", ContactFacts((ff("t.F1", UP),), (), X)),
    # corners
    "E/VS": ("E", corner_facts(True)),
    "V/VS": ("V", corner_facts(True)),
    "E/VT": ("E", corner_facts(True, third_opening=175)),
    "V/VT": ("V", corner_facts(True, third_opening=175)),
    "E/VI": ("E", corner_facts(False)),
    "V/VI": ("V", corner_facts(False)),
}


def test_every_state_has_a_geometric_case():
    assert set(CASES) == set(STATES)


@pytest.mark.parametrize("name", list(CASES))
def test_classifier_reaches_each_of_the_15_states(name):
    dlo, facts = CASES[name]
    assert classify_contact(dlo, facts).name == name


def test_crossing_a_concave_groove_at_a_point_is_EP_and_stable():
    assert classify_contact("E", groove_facts(90, vec=Y)).name == "E/E^P"


def test_critical_angle_boundary():
    p = ModelParams(critical_angle_deg=170)
    assert classify_contact("E", groove_facts(169.9), p).name == "E/E^LS"
    assert classify_contact("E", groove_facts(170.0), p).name == "E/E^LT"  # at the angle: semi-stable
    assert classify_contact("E", groove_facts(175), ModelParams(critical_angle_deg=176)).name == "E/E^LS"
    assert classify_contact("E", groove_facts(179.9)).name == "E/E^LT"


def test_semi_stable_needs_concavity_convex_stays_instable():
    assert classify_contact("V", groove_facts(185, concave=False)).name == "V/E^LI"
    assert classify_contact("E", groove_facts(185, concave=False)).name == "E/E^LI"


def _tilted(deg):
    a = math.radians(deg)
    return (math.cos(a), math.sin(a), 0.0)  # a DLO vector deg away from the crease (x) in the floor


def test_parallel_tolerance_boundary():
    p = ModelParams(parallel_tol_deg=10)
    assert classify_contact("E", groove_facts(90, vec=_tilted(9.99)), p).name == "E/E^LS"
    assert classify_contact("E", groove_facts(90, vec=_tilted(10.01)), p).name == "E/E^P"
    assert classify_contact("E", groove_facts(90, vec=_tilted(-170)), p).name == "E/E^LS"  # sign-free
    assert classify_contact(
        "E", groove_facts(270, False, vec=_tilted(15)), ModelParams(parallel_tol_deg=20)
    ).name == ("E/E^LI")


def test_given_crease_direction_is_used():
    fs, ps = groove(90)
    facts = ContactFacts(fs, ps, X, crease=Y)  # the caller says the edge runs along y
    assert classify_contact("E", facts).name == "E/E^P"


def test_internal_faces_are_dropped_from_a_situation_before_contraction():
    """docs/model.md 1 and 3.2: internal faces are never contact faces. A contact of internal faces
    alone is N and contracts with a free neighbour; an edge of a real and an internal face is the real
    face."""
    book = FactBook({
        "box.F1": ff("box.F1", UP), "box.F2": ff("box.F2", X), "box.F9": ff("box.F9", X, internal=True)
    })  # fmt: skip
    sit = parse_situation("VS/G & E3/N & E8/box.F9 & VE/N")
    assert without_internal(sit, book).format() == "VS/G & E3/N & VE/N"
    assert discretize(sit, book).format() == "V/G & E/N & V/N"
    sit = parse_situation("VS/G & E3/N & E6/(box.F1,box.F9) & E8/box.F1 + E8/box.F9 & E10/box.F9 & VE/box.F9")
    assert without_internal(sit, book).format() == "VS/G & E3/N & E6/box.F1 & E10/N & VE/N"
    real = parse_situation("VS/G & E3/N & E8/box.F1 & VE/N")
    assert without_internal(real, book) is real  # nothing internal: the situation itself


def test_rank_merges_nearly_equal_normals_and_drops_internal_faces():
    split = ContactFacts((ff("a.F1", UP), ff("a.F2", rot_x(0.005))), (), X)  # one face over two pieces
    assert classify_contact("E", split).name == "E/F"
    half_degree = ContactFacts((ff("a.F1", UP), ff("a.F2", rot_x(0.5))), (), X)
    assert classify_contact("E", half_degree, ModelParams(normal_merge_deg=1.0)).name == "E/F"
    with pytest.raises(ValueError, match="no pair fact"):  # with the default merge angle they are two faces
        classify_contact("E", half_degree)
    internal = ContactFacts((ff("a.F1", UP), ff("a.F7", X, internal=True)), (), X)
    assert classify_contact("E", internal).name == "E/F"
    only_internal = ContactFacts((ff("a.F7", X, internal=True),), (), X)
    assert classify_contact("E", only_internal).name == "E/N"


def test_four_faces_in_a_corner_are_still_a_vertex():
    fs = (*corner_facts(True).faces, ff("w.F4", (-0.70710678, 0, 0.70710678)))
    ps = (*corner_facts(True).pairs, pair("w.F4", "t.F1", True, 135), pair("w.F4", "w.F2", True, 135),
          pair("w.F4", "w.F3", True, 90))
    assert classify_contact("V", ContactFacts(fs, ps, X)).name == "V/VS"


def test_missing_facts_are_errors():
    fs, _ = groove(90)
    with pytest.raises(ValueError, match="no pair fact"):
        classify_contact("E", ContactFacts(fs, (), X))
    with pytest.raises(ValueError, match="DLO vector"):
        classify_contact("E", ContactFacts(*groove(90)))


def test_params_are_validated():
    with pytest.raises(ValueError, match="critical_angle"):
        ModelParams(critical_angle_deg=200)
    with pytest.raises(ValueError, match="parallel_tol"):
        ModelParams(parallel_tol_deg=-1)


# --------------------------------------------------------------------------------------------------
# Topological -> discrete situation, notation
# --------------------------------------------------------------------------------------------------


def test_discretize_a_whole_situation():
    book = FactBook(
        {
            "box.F1": ff("box.F1", UP),
            "box.F2": ff("box.F2", X),
            "table.F1": ff("table.F1", UP),
        },
        [PairFact("box.F1", "box.F2", False, 270)],
    )
    topo = parse_situation("VS/G & E3/N & E9/(box.F1,box.F2) & E12/box.F1 & VE/table.F1")
    import dataclasses

    c = list(topo.contacts)
    c[2] = dataclasses.replace(
        c[2], dlo=dataclasses.replace(c[2].dlo, vector=(1.0, 0.0, 0.0))
    )  # across the edge (along y)
    d = discretize(type(topo)(tuple(c)), book)
    assert d.format() == "V/G & E/N & E/E^P[box.F1,box.F2] & E/F[box.F1] & V/F[table.F1]"
    assert d.contacts[2].vector is not None
    np.testing.assert_allclose(d.contacts[2].vector, np.array([-1, 0, -1]) / math.sqrt(2))
    assert d.contacts[1].vector == (0.0, 0.0, 0.0)


def test_discretizer_gives_what_discretize_gives_annotations_and_all():
    """The memoizing Discretizer (a simulation's per-step path) against discretize: same states,
    faces, contact vectors, axes and spans, the point/line decision of an edge contact made again
    from each DLO vector, gripper contacts with each step's z axis, the same errors."""
    import dataclasses

    book = FactBook(
        {"box.F1": ff("box.F1", UP), "box.F2": ff("box.F2", X), "a.F1": ff("a.F1", UP),
         "b.F1": ff("b.F1", (0.0, 0.0, -1.0))},
        [PairFact("box.F1", "box.F2", False, 270)],
    )
    d = Discretizer(book)
    topo = parse_situation("VS/G & E3/N & E9/(box.F1,box.F2) & E12/a.F1 + E12/b.F1 & VE/box.F1")
    for k, vec in enumerate([(1.0, 0.0, 0.0), (0.0, 1.0, 0.0), (0.3, 1.0, 0.01), (1.0, 0.0, 0.0)]):
        c = list(topo.contacts)
        c[0] = dataclasses.replace(c[0], env=(dataclasses.replace(c[0].env[0], z=(0.0, 0.1 * k, 1.0)),))
        c[2] = dataclasses.replace(c[2], dlo=dataclasses.replace(c[2].dlo, vector=vec, span=(8, 8 + k)))
        sit = type(topo)(tuple(c))
        want, got = discretize(sit, book), d(sit)
        assert repr(got) == repr(want)
    assert {c.state.name for c in d(sit).contacts} >= {"E/E^P", "V/G"}
    with pytest.raises(ValueError, match="DLO vector"):
        d(topo)  # the edge contact without its vector, though the edge's facts are kept
    with pytest.raises(KeyError, match="no facts"):
        d(parse_situation("VS/G & E3/c.F1 & VE/N"))


def test_the_discretizer_makes_again_only_the_contacts_that_follow_annotations():
    """Discretizer.again (a situation refreshed from the same contraction, the tracker's per-step
    path): the same discrete situation as a full call, through the line band's hysteresis, with the
    gripper's z and the edge contact's DLO vector changing and the other contacts kept as they were;
    the last discrete situation itself when nothing it holds changed."""
    import dataclasses

    book = FactBook(
        {"box.F1": ff("box.F1", UP), "box.F2": ff("box.F2", X), "a.F1": ff("a.F1", UP)},
        [PairFact("box.F1", "box.F2", False, 270)],
    )
    topo = parse_situation("VS/G & E3/N & E9/(box.F1,box.F2) & E12/a.F1 & VE/box.F1")
    full, fast = Discretizer(book, line_band_deg=3.0), Discretizer(book, line_band_deg=3.0)
    last, names = None, []
    for k, x in enumerate([0.0, 0.0, 0.2, 0.3, 0.2, 0.1]):  # off the crease (y): 0-16.7 deg
        vec = (x, 1.0, 0.0)
        c = list(topo.contacts)
        z = (0.0, 0.1 * (k // 2), 1.0)
        c[0] = dataclasses.replace(c[0], env=(dataclasses.replace(c[0].env[0], z=z),))
        c[2] = dataclasses.replace(c[2], dlo=dataclasses.replace(c[2].dlo, vector=vec, span=(8, 9)))
        sit = type(topo)(tuple(c))
        want = full(sit)
        got = fast(sit) if last is None else fast.again(last, sit, [0, 2])
        assert repr(got) == repr(want) and [x.span for x in got.contacts] == [x.span for x in want.contacts]
        if k == 1:
            assert got is last  # nothing changed: the same z, the same decision
        last = got
        names.append(got.contacts[2].state.name[:5])
    assert names == ["E/E^L", "E/E^L", "E/E^L", "E/E^P", "E/E^P", "E/E^L"]  # 11.3: held by the band, then not


def test_the_discretizer_holds_a_line_contact_by_its_band():
    """docs/model.md 3.2 step 4: hysteresis on the point-or-line decision. A line contact on an edge stays one
    until its DLO vector is more than the parallel tolerance plus the band from the crease (10 + 3 deg);
    a point contact (or an edge contact that was not there a situation ago) must come within 10 deg."""
    import dataclasses

    book = FactBook({"box.F1": ff("box.F1", UP), "box.F2": ff("box.F2", X)},
                    [PairFact("box.F1", "box.F2", False, 270)])
    topo = parse_situation("VS/G & E3/N & E9/(box.F1,box.F2) & E12/N & VE/N")
    free = parse_situation("VS/G & E3/N & VE/N")  # its third contact: the free tip

    def on_edge(deg):  # the DLO vector deg from the crease (y)
        a = math.radians(deg)
        c = list(topo.contacts)
        vec = (math.sin(a), math.cos(a), 0.0)
        c[2] = dataclasses.replace(c[2], dlo=dataclasses.replace(c[2].dlo, vector=vec))
        return type(topo)(tuple(c))

    def states(d, steps):
        return [d(on_edge(x) if x is not None else free).contacts[2].state.name for x in steps]

    line, point, n = "E/E^LI", "E/E^P", "V/N"
    angles = [5, 11.5, 12.5, 14, 11.5, 8, 12.5]
    held = states(Discretizer(book, line_band_deg=3.0), angles)
    assert held == [line, line, line, point, point, line, line]
    assert states(Discretizer(book), angles) == [line, point, point, point, point, line, point]
    pure = [discretize(on_edge(x), book).contacts[2].state.name for x in angles]
    assert pure == states(Discretizer(book), angles)
    d = Discretizer(book, line_band_deg=3.0)
    assert states(d, [5, None, 11.5]) == [line, n, point]  # the edge contact left in between
    assert states(d, [5]) == [line]
    d.forget()
    assert states(d, [11.5]) == [point]
    with pytest.raises(ValueError, match="line_band_deg"):
        Discretizer(book, line_band_deg=-1.0)


def test_discrete_notation_roundtrip_and_errors():
    text = "V/G & E/N & E/E^P[block.F1,block.F2] & V/N"
    s = parse_discrete_situation(text)
    assert s.format() == text
    assert s.format(unicode=True) == "V/G ∧ E/N ∧ E/E^P[block.F1,block.F2] ∧ V/N"
    assert parse_discrete_situation(s.format(unicode=True)) == s
    with pytest.raises(NotationError, match="not a discrete contact"):
        parse_discrete_situation("V/G & E/FS & V/N")
    with pytest.raises(NotationError, match="touches no faces"):
        parse_discrete_situation("V/G & E/N[a.F1] & V/N")
    with pytest.raises(NotationError, match="start"):
        parse_discrete_situation("E/N & V/N")


@pytest.mark.parametrize(
    ("text", "message"),
    [
        ("V/G & E/N & V/E^LS[a.F1]", "an edge contact and names at least 2 faces, got 1"),
        ("V/G & E/E^P[a.F1] & V/N", "an edge contact and names at least 2 faces, got 1"),
        ("V/G & E/N & V/VI[a.F1,a.F2]", "a vertex contact and names at least 3 faces, got 2"),
        ("V/G & E/N & V/F[a.F1,a.F1]", "face a.F1 is listed twice"),
        ("V/G & V/N", "at least one E contact"),
        ("V/G & E/N & V/N & E/N & V/N", "V only at the ends"),
    ],
)
def test_discrete_notation_refuses_wrong_face_counts_and_structure(text, message):
    with pytest.raises(NotationError, match=re.escape(message)):
        parse_discrete_situation(text)


def test_discrete_notation_accepts_the_face_counts_of_each_type():
    for text in (
        "V/G & E/F[a.F1,b.F1,c.F1] & V/F[a.F1]",  # coplanar faces of several objects
        "V/G & E/E^LS[a.F1,a.F3,b.F2,b.F4] & V/E^LI[a.F1,a.F2]",  # a groove of two edges; an edge
        "V/G & E/VS[a.F1,a.F2,a.F3] & V/VS[a.F1,a.F2,a.F3,a.F4]",  # corners of three and four faces
        # a vertex of one object on an edge of another (peg_in_hole's groove end, seen in a run)
        "V/G & E/N & V/VI[block.F3,block.F5,holeblock.F2,holeblock.F9,holeblock.F11]",
        "V/G & E/E^P & V/VT",  # faces are optional
    ):
        assert parse_discrete_situation(text).format() == text


all_names = st.sampled_from([*STATES, *AUX_STATES])


@st.composite
def discrete_situations(draw):
    def contact(dlo):
        name = draw(all_names.filter(lambda n: n.startswith(dlo)))
        lo, hi = FACE_COUNTS.get(state(name).env, (0, 0))
        n = draw(st.sampled_from([0, *range(lo, (hi or 5) + 1)])) if lo else 0  # faces are optional
        fs = tuple(draw(st.lists(
            st.builds(lambda o, k: f"{o}.F{k}", st.sampled_from(["a", "box", "hole_b"]), st.integers(0, 20)),
            min_size=n, max_size=n, unique=True)))
        return DiscreteContact(state(name), fs)

    return DiscreteSituation(
        (contact("V"), *[contact("E") for _ in range(draw(st.integers(1, 5)))], contact("V"))
    )


@given(discrete_situations())
def test_discrete_parse_format_roundtrip(s):
    assert parse_discrete_situation(s.format()) == s
    assert parse_discrete_situation(s.format(unicode=True)) == s
