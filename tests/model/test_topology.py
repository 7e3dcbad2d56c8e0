"""Topological contact model (docs/model.md, paper §III): values, notation, parser, contraction,
successional contacts."""

from __future__ import annotations

import pytest
from hypothesis import given
from hypothesis import strategies as st

from dlovr.model.topology import (
    Contact,
    DloPrimitive,
    EnvPrimitive,
    G,
    N,
    NotationError,
    Situation,
    contract,
    contract_contacts,
    face_object,
    faces,
    parse_contact,
    parse_situation,
    situation_from_points,
    tip_touches,
)

EXAMPLE = Situation(
    (
        Contact(DloPrimitive("VS", 0), (G,)),
        Contact(DloPrimitive("E", 3), (N,)),
        Contact(DloPrimitive("E", 9), (faces("box.F1"), faces("table.F1"))),
        Contact(DloPrimitive("E", 14), (N,)),
        Contact(DloPrimitive("VE", 20), (N,)),
    )
)


def test_example_notation_both_forms_exactly_as_model_md():
    assert EXAMPLE.format() == "VS/G & E3/N & E9/box.F1 + E9/table.F1 & E14/N & VE/N"
    assert EXAMPLE.format(unicode=True) == "V_S/G_z ∧ E_3/N ∧ E_9/box.F1 + E_9/table.F1 ∧ E_14/N ∧ V_E/N"


def test_parse_both_forms_give_the_same_value():
    a = parse_situation("VS/G & E3/N & E9/box.F1 + E9/table.F1 & E14/N & VE/N")
    b = parse_situation("V_S/G_z ∧ E_3/N ∧ E_9/box.F1 + E_9/table.F1 ∧ E_14/N ∧ V_E/N")
    assert a == b == EXAMPLE
    assert a.contacts[2].dlo.index == 9  # the index survives the round trip


def test_edges_and_vertices_are_face_sets_of_one_piece():
    e = faces("box.F2", "box.F1")
    assert e.type == "E" and e.faces == ("box.F1", "box.F2")
    assert faces("b.F1", "b.F2", "b.F10").type == "V"
    assert faces("b.F10", "b.F2", "b.F1").faces == ("b.F1", "b.F2", "b.F10")  # numeric order
    assert e.format() == "(box.F1,box.F2)" and e.format(unicode=True) == "(box.F1∩box.F2)"
    assert parse_contact("E4/(box.F2,box.F1)").env == (e,)
    assert parse_contact("E_4/(box.F1∩box.F2)").env == (e,)
    assert e.objects == frozenset({"box"})
    assert face_object("peg.hole.F3") == "peg.hole"


def test_values_are_hashable_and_compare_by_topology():
    a = Contact(DloPrimitive("E", 3, (2, 4), (1.0, 0.0, 0.0)), (faces("box.F1"),))
    b = Contact(DloPrimitive("E", 5, (4, 6), (0.0, 1.0, 0.0)), (faces("box.F1"),))
    assert a == b and hash(a) == hash(b)  # index, span and DLO vector are annotations
    assert len({EXAMPLE, parse_situation(EXAMPLE.format())}) == 1
    m1 = Contact(DloPrimitive("E"), (faces("b.F1"), faces("a.F2")))
    m2 = Contact(DloPrimitive("E"), (faces("a.F2"), faces("b.F1")))
    assert m1 == m2 and m1.is_multiple


@pytest.mark.parametrize(
    ("text", "message"),
    [
        ("", "empty"),
        ("E3/N & VE/N", "starts with the V_S"),
        ("VS/G & E3/N", "ends with the V_E"),
        ("VS/G & VS/N & VE/N", "interior contacts"),
        ("VS/G & E3 & VE/N", "not a basic contact"),
        ("VS/G & X3/N & VE/N", "not a DLO primitive"),
        ("VS/G & E3/box & VE/N", "bad face name"),
        ("VS/G & E3/(box.F1) & VE/N", "two or more faces"),
        ("VS/G & E3/(box.F1,box.F2 & VE/N", "unclosed"),
        ("VS/G & E3/box.F1 + E4/box.F2 & VE/N", "one DLO point"),
        ("VS/G & E3/N + E3/box.F1 & VE/N", "N (free space)"),
        ("VS3/G & VE/N", "takes no index"),
        ("VS/G & E3/ & VE/N", "missing environment primitive"),
    ],
)
def test_parse_errors_say_what_is_wrong(text, message):
    with pytest.raises(NotationError, match=message.replace("(", r"\(").replace(")", r"\)")):
        parse_situation(text)


def test_contraction_merges_equal_interior_points_indexed_by_the_middle():
    f1, f2 = faces("table.F1"), faces("box.F1", "box.F2")
    point_env = [[G], [], [], [f1], [f1], [f1], [f1], [f1], [f2], [], [f1]]
    vecs = [(float(i), 0.0, 0.0) for i in range(len(point_env))]
    s = contract(point_env, vecs)
    assert s.format() == "VS/G & E1/N & E5/table.F1 & E8/(box.F1,box.F2) & E9/N & VE/table.F1"
    run = s.contacts[2].dlo
    assert run.span == (3, 7) and run.index == 5 and run.vector == (5.0, 0.0, 0.0)


def test_contract_contacts_merges_neighbours_that_became_equal():
    """Contacts made equal after contraction (internal faces dropped) are contracted again: the run
    keeps its middle contact's DLO primitive and the union of the spans; ends are never merged."""
    f1 = faces("table.F1")
    cs = [
        Contact(DloPrimitive("VS", 0, (0, 0)), (N,)),
        Contact(DloPrimitive("E", 2, (1, 3), (1.0, 0.0, 0.0)), (N,)),
        Contact(DloPrimitive("E", 5, (4, 6), (2.0, 0.0, 0.0)), (N,)),
        Contact(DloPrimitive("E", 8, (7, 9)), (f1,)),
        Contact(DloPrimitive("VE", 10, (10, 10)), (N,)),
    ]
    s = contract_contacts(cs)
    assert s.format() == "VS/N & E2/N & E8/table.F1 & VE/N"
    assert s.contacts[1].dlo.span == (1, 6) and s.contacts[1].dlo.vector == (1.0, 0.0, 0.0)
    typed = parse_situation("VS/N & E3/N & E8/N & E12/N & VE/N")  # no spans: the middle one's index
    assert contract_contacts(typed.contacts).format() == "VS/N & E8/N & VE/N"
    assert contract_contacts(typed.contacts).contacts[1].dlo.span is None


def test_end_vertices_are_never_contracted_into_edge_contacts():
    f1 = faces("table.F1")
    s = contract([[f1], [f1], [f1], [f1]])
    assert [c.dlo.kind for c in s.contacts] == ["VS", "E", "VE"]
    assert s.contacts[1].dlo.span == (1, 2)


def test_successional_contacts_are_runs_between_free_contacts():
    s = parse_situation("VS/G & E1/N & E3/a.F1 & E5/(a.F1,a.F2) & E7/N & E9/b.F1 & VE/N")
    assert s.successional() == [(2, 3), (5,)]
    s2 = parse_situation("VS/G & E2/a.F1 & VE/b.F2")
    assert s2.successional() == [(1, 2)]  # the gripper contact is not part of one


# --------------------------------------------------------------------------------------------------
# parse(format(x)) == x for every value (hypothesis)
# --------------------------------------------------------------------------------------------------

obj_names = st.sampled_from(["box", "table", "hole_block", "peg.hole", "a-1"])
face_names = st.builds(lambda o, k: f"{o}.F{k}", obj_names, st.integers(0, 40))
face_prims = st.lists(face_names, min_size=1, max_size=4, unique=True).map(
    lambda fs: EnvPrimitive("faces", tuple(fs))
)
env_lists = st.one_of(
    st.just((N,)),
    st.just((G,)),
    st.lists(st.one_of(face_prims, st.just(G)), min_size=1, max_size=3, unique=True).map(tuple),
)


@st.composite
def situations(draw):
    n = draw(st.integers(0, 6))
    idx = draw(st.one_of(st.none(), st.integers(1, 200)))
    interior = [Contact(DloPrimitive("E", idx), draw(env_lists)) for _ in range(n)]
    return Situation(
        (
            Contact(DloPrimitive("VS"), draw(env_lists)),
            *interior,
            Contact(DloPrimitive("VE"), draw(env_lists)),
        )
    )


@given(situations())
def test_parse_format_roundtrip_ascii(s):
    back = parse_situation(s.format())
    assert back == s
    assert [c.dlo.index for c in back.contacts] == [c.dlo.index for c in s.contacts]


@given(situations())
def test_parse_format_roundtrip_unicode(s):
    assert parse_situation(s.format(unicode=True)) == s


@given(situations())
def test_format_is_canonical(s):
    assert parse_situation(s.format()).format() == s.format()


# --------------------------------------------------------------------------------------------------
# End-vertex rule (docs/model.md, paper §III)
# --------------------------------------------------------------------------------------------------


def _down(deg):
    """A DLO vector pointing into the floor (normal +z) at ``deg`` below the horizontal."""
    import math

    a = math.radians(deg)
    return (math.cos(a), 0.0, -math.sin(a))


def test_tip_pointing_into_a_face_touches():
    assert tip_touches(_down(45), [(0, 0, 1)])
    assert tip_touches(_down(15.5), [(0, 0, 1)], tip_angle_deg=15)


def test_last_segment_lying_on_a_face_is_not_a_tip_contact():
    assert not tip_touches(_down(0), [(0, 0, 1)])
    assert not tip_touches(_down(14.5), [(0, 0, 1)], tip_angle_deg=15)
    assert not tip_touches(_down(-30), [(0, 0, 1)])  # pointing away


def test_tip_into_one_face_of_a_groove_touches():
    # lying flat on the floor but pushing into the wall (normal -x) at 20°
    import math

    a = math.radians(20)
    assert tip_touches((math.sin(a), math.cos(a), 0.0), [(0, 0, 1), (-1, 0, 0)])
    assert not tip_touches((0.0, 1.0, 0.0), [(0, 0, 1), (-1, 0, 0)])  # along the groove: an E contact


def test_situation_from_points_applies_gripper_and_end_vertex_rule():
    floor = faces("t.F1")
    normals = {"t.F1": (0.0, 0.0, 1.0)}
    env = [[floor], [], [floor], [floor], [floor]]
    flat = [(1.0, 0.0, 0.0)] * 4
    s = situation_from_points(env, flat, normals.__getitem__, gripper_z=(0.0, 0.0, 1.0))
    # last segment lies on the face: V_E free; the held V_S touches G, and its face is E_1's
    assert s.format() == "VS/G & E2/t.F1 & VE/N"
    assert s.contacts[0].env[0].z == (0.0, 0.0, 1.0)
    down = [*flat[:3], (0.7, 0.0, -0.7)]
    s = situation_from_points(env, down, normals.__getitem__)
    assert s.format() == "VS/G & E2/t.F1 & VE/t.F1"  # the tip points into the face
    s = situation_from_points(env, flat, normals.__getitem__, gripped=False)
    assert s.contacts[0].is_free  # V_S lying flat, not gripped: not a tip contact
    with pytest.raises(ValueError, match="DLO vectors"):
        situation_from_points(env, flat[:2], normals.__getitem__)


def test_a_shallow_tip_contact_is_never_dropped_it_is_an_E_contact_of_the_last_segment():
    floor, wall = faces("t.F1"), faces("w.F2")
    normals = {"t.F1": (0.0, 0.0, 1.0), "w.F2": (-1.0, 0.0, 0.0)}
    flat = [(1.0, 0.0, 0.0)] * 4
    env = [[], [], [], [], [floor]]  # only the tip touches, the last segment lies on the floor
    s = situation_from_points(env, flat, normals.__getitem__)
    assert s.format() == "VS/G & E1/N & E3/t.F1 & VE/N"
    assert s.contacts[2].dlo.span == (3, 3)
    shallow = [*flat[:3], _down(10)]  # at the tip angle or less: still the segment's contact
    assert situation_from_points(env, shallow, normals.__getitem__).format() == "VS/G & E1/N & E3/t.F1 & VE/N"
    # the last interior point touches a wall itself: one multiple contact there
    env = [[], [], [], [wall], [floor]]
    s = situation_from_points(env, flat, normals.__getitem__)
    assert s.format() == "VS/G & E1/N & E3/t.F1 + E3/w.F2 & VE/N"
    # the same for V_S when it is not gripped
    env = [[floor], [], [], [], []]
    s = situation_from_points(env, flat, normals.__getitem__, gripped=False)
    assert s.format() == "VS/N & E1/t.F1 & E2/N & VE/N"
    # a tip pointing into the face keeps its own contact
    s = situation_from_points([[], [], [], [], [floor]], [*flat[:3], _down(45)], normals.__getitem__)
    assert s.format() == "VS/G & E2/N & VE/t.F1"


def test_leaning_past_the_tip_angle_makes_the_tip_the_contact_on_the_side_face():
    """docs/model.md 4.4 (Fig. 11, step 6): a cable hanging along a side face (normal +x) lays its last
    segment on it (E contact, V_E free); bent further so that the last segment points into the face by
    more than the tip angle, the tip is the contact (V_E/F), reachable from E/F."""
    import math

    side = faces("block.F3")
    normals = {"block.F3": (1.0, 0.0, 0.0)}
    env = [[], [], [], [side], [side]]
    down = [(1.0, 0.0, 0.0), (1.0, 0.0, -1.0), (0.0, 0.0, -1.0), (0.0, 0.0, -1.0)]
    s = situation_from_points(env, down, normals.__getitem__)
    assert s.format() == "VS/G & E1/N & E3/block.F3 & VE/N"
    leaning = [*down[:3], (-math.sin(math.radians(20)), 0.0, -math.cos(math.radians(20)))]
    s = situation_from_points([[], [], [], [], [side]], leaning, normals.__getitem__)
    assert s.format() == "VS/G & E2/N & VE/block.F3"


def test_the_gripped_vertex_is_VG_and_what_it_touches_is_a_contact_of_the_first_segment():
    """docs/model.md, section 2 (issue 27, item 4): point 0 pressed into a face is not replaced by the
    gripper: its contact is an E contact at E_1, merged with what point 1 touches itself."""
    flank, other = faces("v.F1"), faces("v.F2")
    normals = {"v.F1": (0.5, 0.0, 0.866), "v.F2": (-0.5, 0.0, 0.866)}
    flat = [(1.0, 0.0, 0.0)] * 5
    s = situation_from_points([[flank], [], [], [other], [], []], flat, normals.__getitem__)
    assert s.format() == "VS/G & E1/v.F1 & E2/N & E3/v.F2 & E4/N & VE/N"
    assert s.contacts[0].env == (G,) and s.contacts[1].dlo.span == (1, 1)
    s = situation_from_points([[flank], [flank], [flank], [], [], []], flat, normals.__getitem__)
    assert s.format() == "VS/G & E1/v.F1 & E3/N & VE/N"  # one run with the points that touch too
    s = situation_from_points([[flank], [other], [], [], [], []], flat, normals.__getitem__)
    assert s.format() == "VS/G & E1/v.F1 + E1/v.F2 & E3/N & VE/N"
    s = situation_from_points([[flank], [], [], [], [], []], flat, normals.__getitem__, gripped=False)
    assert s.format() == "VS/v.F1 & E2/N & VE/N"  # not gripped, pointing into the flank: V_S's own
