"""Transition networks (paper §VI, §VII; docs/networks.md): construction from hand-made situation
sequences, path choice, identification and re-planning, JSON round trips, refusal of mixed scenes."""

from __future__ import annotations

import json
from dataclasses import replace
from fractions import Fraction

import numpy as np
import pytest

from dlovr.model.derivation import WrenchSeries
from dlovr.model.discrete import DiscreteSituation, parse_discrete_situation
from dlovr.model.network import (
    SENSE_DELAY_S,
    SENSE_HOLD_S,
    Demonstration,
    Network,
    NetworkError,
    build_network,
    edge_risk,
    sensed_vectors,
)
from dlovr.model.planning import NetworkProgram, Successor, identify, reference_path
from dlovr.model.program import PoseTrack, TimedSituation

FREE = "V/G & E/N & V/N"
TIP = "V/G & E/N & V/F[box.F1]"
LIE = "V/G & E/N & E/F[box.F1] & V/N"
GROOVE = "V/G & E/N & V/E^LS[box.F1,wall.F2]"

VECTORS = {
    "V/F[box.F1]": (0.0, 0.0, -1.0),
    "E/F[box.F1]": (0.0, 0.0, -1.0),
    "V/F[box.F2]": (-1.0, 0.0, 0.0),
    "V/F[wall.F1]": (0.0, -1.0, 0.0),
    "V/E^LI[box.F1,box.F2]": (-0.6, 0.0, -0.8),
    "V/E^LS[box.F2,floor.F1]": (-0.8, 0.0, -0.6),
}


def S(text: str) -> DiscreteSituation:
    """A situation with the contact vectors of VECTORS (free and gripper contacts get none)."""
    s = parse_discrete_situation(text)
    return DiscreteSituation(tuple(replace(c, vector=VECTORS.get(c.format())) for c in s.contacts))


def still(pos=(0.0, 0.0, 0.3)) -> PoseTrack:
    return PoseTrack(np.array([0.0]), np.array([pos]), np.array([[1.0, 0.0, 0.0, 0.0]]))


def node(net: Network, situation: DiscreteSituation | str) -> str:
    """The id of the node of ``situation``, which the test knows to be in ``net``."""
    found = net.locate(situation)
    assert found is not None, situation
    return found


def demo(name: str, seq, durations=None, poses=None, scene=("box", "abc")) -> Demonstration:
    durations = durations or [1.0] * len(seq)
    t = np.concatenate([[0.0], np.cumsum(durations)[:-1]])
    states = tuple(
        TimedSituation(float(ti), float(d), S(s)) for ti, d, s in zip(t, durations, seq, strict=True)
    )
    return Demonstration(name, states, poses or still(), scene[0], scene[1])


def line_track(speed: float, n: int = 10) -> PoseTrack:
    """Moving along +x at ``speed`` m/s from (0, 0, 0.3); samples every 0.5 s."""
    t = np.arange(n) * 0.5
    pos = np.stack([speed * t, np.zeros(n), np.full(n, 0.3)], axis=1)
    return PoseTrack(t, pos, np.tile([1.0, 0.0, 0.0, 0.0], (n, 1)))


# --------------------------------------------------------------------------------------------------
# Construction
# --------------------------------------------------------------------------------------------------


def small_network() -> Network:
    return build_network(
        [
            demo("A", [FREE, TIP, GROOVE], [1.0, 2.0, 0.5], line_track(0.01)),
            demo("B", [FREE, TIP, LIE, GROOVE], [1.0, 1.0, 1.5, 0.5], line_track(0.02)),
            demo("C", [FREE, LIE, GROOVE], [2.0, 1.0, 0.5], line_track(0.01)),
        ]
    )


def test_nodes_count_visits_and_held_times_exactly():
    net = small_network()
    assert [(n.id, n.situation) for n in net.nodes] == [
        ("n1", FREE), ("n2", TIP), ("n3", GROOVE), ("n4", LIE)
    ]
    by = {n.id: n for n in net.nodes}
    assert [by[k].visits for k in ("n1", "n2", "n3", "n4")] == [3, 2, 3, 2]
    assert by["n1"].total_time == 4.0 and by["n1"].mean_time == pytest.approx(4.0 / 3)
    assert by["n2"].total_time == 3.0 and by["n2"].mean_time == 1.5
    assert by["n4"].total_time == 2.5
    assert by["n1"].stability == "free" and by["n1"].principal == () and by["n1"].vector == (0.0, 0.0, 0.0)
    assert by["n2"].stability == "stable" and by["n2"].principal == ("V/F[box.F1]",)
    assert by["n2"].vector == (0.0, 0.0, -1.0)
    assert by["n3"].vector is None  # the hand-made groove has no vector
    assert net.start == "n1" and net.goal == "n3"
    assert [(p.node, p.count) for p in net.starts] == [("n1", 3)]
    assert [(p.node, p.count) for p in net.ends] == [("n3", 3)]


def test_edges_count_probability_class_risk_and_durations_exactly():
    net = small_network()
    got = {e.id: (e.label, e.risk, e.count, e.probability, e.durations) for e in net.edges}
    assert got == {
        "n1->n2": ("E", "none", 2, round(2 / 3, 9), (1.0, 1.0)),
        "n1->n4": ("E", "none", 1, round(1 / 3, 9), (2.0,)),
        "n2->n3": ("E", "none", 1, 0.5, (2.0,)),
        "n2->n4": ("C", "none", 1, 0.5, (1.0,)),
        "n4->n3": ("E", "none", 2, 1.0, (1.5, 1.0)),
    }
    # departures of every node sum to one
    for n in net.nodes:
        out = net.out_edges(n.id)
        if out:
            assert sum(Fraction(e.count) for e in out) / sum(e.count for e in out) == 1
            assert sum(e.probability for e in out) == pytest.approx(1.0)


def test_edge_motions_are_mean_and_spread_of_the_demonstrated_displacements():
    net = small_network()
    e = next(e for e in net.edges if e.id == "n1->n2")  # A: 1 s at 0.01 m/s, B: 1 s at 0.02 m/s
    np.testing.assert_allclose(e.motion.world_mean, [0.015, 0.0, 0.0], atol=1e-12)
    np.testing.assert_allclose(e.motion.world_std, [0.005, 0.0, 0.0], atol=1e-12)
    np.testing.assert_allclose(e.motion.relative_mean, [0.015, 0.0, 0.0], atol=1e-12)
    np.testing.assert_allclose(e.motion.start_mean, [0.0, 0.0, 0.3], atol=1e-12)
    np.testing.assert_allclose(e.motion.end_mean, [0.015, 0.0, 0.3], atol=1e-12)
    assert e.motion.start_spread == 0.0
    assert e.demonstrations == (0, 1)


def test_risk_per_class():
    assert [edge_risk(c) for c in [(), ("C",), ("E",), ("T",), ("I",), ("S", "E"), ("T", "E")]] == [
        "none", "none", "none", "caution", "risky", "risky", "caution"
    ]


def test_goal_is_the_most_common_last_situation():
    net = build_network([demo("a", [FREE, TIP]), demo("b", [FREE, LIE]), demo("c", [FREE, TIP, LIE, TIP])])
    assert net.goal == net.locate(TIP)
    assert [(p.node, p.count) for p in net.ends] == [("n2", 2), ("n3", 1)]


def test_demonstrations_of_different_scenes_are_refused_with_one_line():
    with pytest.raises(NetworkError) as ei:
        build_network([demo("a.mcap", [FREE, TIP]), demo("b.mcap", [FREE, TIP], scene=("table", "def"))])
    msg = str(ei.value)
    assert "\n" not in msg and "b.mcap" in msg and "a.mcap" in msg and "table" in msg and "box" in msg
    with pytest.raises(NetworkError, match="no demonstrations"):
        build_network([])


def test_a_nodes_sensed_vector_is_what_a_run_senses_just_after_entering_it():
    """A run senses SENSE_DELAY_S (its detection's latency) + SENSE_HOLD_S (its hold) after a
    transition: a node's expected vector is its demonstrations' force over that window, not over the
    whole stay (in the groove the force first presses down, then the drag tilts it along -x for the
    rest of the 2 s), nor before the window (a knock in the first 30 ms along +x)."""
    dt, weight = 0.002, np.array([0.0, 0.0, -0.1])
    t = np.arange(0.0, 3.0, dt)
    force = np.tile(weight, (len(t), 1))  # free space: the cable's weight
    v = np.zeros((len(t), 3))
    g = t >= 1.0  # the groove, entered at 1 s
    v[g & (t < 1.03)] = (1.0, 0.0, 0.0)
    v[g & (t >= 1.03) & (t < 1.15)] = (0.0, 0.0, -1.0)
    v[g & (t >= 1.15)] = (-1.0, 0.0, 0.0)
    assert 0.03 < SENSE_DELAY_S and SENSE_DELAY_S + SENSE_HOLD_S < 0.15  # a run senses at about 0.09 s
    force -= 0.5 * v  # a contact with vector v adds about -v F
    d = replace(demo("A", [FREE, GROOVE], [1.0, 2.0]), wrench=WrenchSeries(t, force, np.zeros_like(force)))
    net = build_network([d])
    groove = net.node(node(net, S(GROOVE)))
    assert groove.sensed is not None
    np.testing.assert_allclose(groove.sensed, (0.0, 0.0, -1.0), atol=0.01)  # (the tare: to 1 s inclusive)
    assert net.node(node(net, S(FREE))).sensed == (0.0, 0.0, 0.0)
    # a stay shorter than the detection's latency: its second half
    short = sensed_vectors([replace(d, states=(d.states[0], replace(d.states[1], duration=0.02)))],
                           [["n1", "n2"]])
    np.testing.assert_allclose(short["n2"], (1.0, 0.0, 0.0), atol=0.01)


def test_json_round_trip_is_exact_and_versioned():
    net = small_network()
    back = Network.loads(net.dumps())
    assert back == net
    assert back.dumps() == net.dumps()
    data = json.loads(net.dumps())
    assert data["version"] == 1 and data["kind"] == "transition-network"
    data["version"] = 99
    with pytest.raises(NetworkError, match="format 99"):
        Network.from_json(data)
    with pytest.raises(NetworkError, match="not valid JSON"):
        Network.loads("{")
    bad = json.loads(net.dumps())
    bad["edges"][0]["target"] = "n77"
    with pytest.raises(NetworkError, match="unknown node"):
        Network.from_json(bad)


def test_a_bad_network_file_names_where_the_problem_is():
    """Like every input: ``where: problem``, the item of a list by its index."""
    good = json.loads(small_network().dumps())
    cases = [
        (("nodes", 1, "visits"), None, r"^nodes\[1\]\.visits: missing$"),
        (("edges", 0, "count"), "many", r"^edges\[0\]: ValueError: .*many"),
        (("starts",), {"node": "n1"}, r"^starts: must be a list, got dict$"),
        (("goal",), None, r"^goal: missing$"),
    ]
    for path, value, message in cases:
        bad = json.loads(json.dumps(good))
        *parents, last = path
        holder = bad
        for key in parents:
            holder = holder[key]
        if value is None:
            del holder[last]
        else:
            holder[last] = value
        with pytest.raises(NetworkError, match=message):
            Network.from_json(bad)


def test_network_as_a_networkx_graph():
    g = small_network().graph()
    assert sorted(g.nodes) == ["n1", "n2", "n3", "n4"]
    assert g.edges["n1", "n2"]["count"] == 2 and g.nodes["n2"]["stability"] == "stable"


# --------------------------------------------------------------------------------------------------
# Path choice
# --------------------------------------------------------------------------------------------------

A = "V/G & E/N & V/F[box.F1]"
R = "V/G & E/N & V/E^LI[box.F1,box.F2]"
G = "V/G & E/N & V/F[box.F2]"
B = "V/G & E/N & E/F[box.F1] & V/N"
EP = "V/G & E/N & E/E^P[box.F1,box.F2] & V/N"


def test_a_stable_path_is_preferred_over_a_shorter_risky_one_of_equal_probability():
    net = build_network([demo("risky", [A, R, G]), demo("stable", [A, B, EP, G])])
    labels = {e.id: (e.label, e.risk) for e in net.edges}
    assert labels[f"{net.locate(A)}->{net.locate(R)}"] == ("I", "risky")
    assert labels[f"{net.locate(R)}->{net.locate(G)}"] == ("S", "risky")
    prog = NetworkProgram(net)
    ch = prog.replan(node(net, A))
    assert ch is not None
    assert ch.path == tuple(net.locate(s) for s in (A, B, EP, G))
    assert (ch.reach_probability, ch.risky, ch.length) == (0.5, 0, 3)
    assert ch.macro.classes == ("C",) and ch.macro.risk == "none"


def test_probability_comes_first_then_risk_then_length():
    risky_often = build_network([demo("r1", [A, R, G]), demo("r2", [A, R, G]), demo("s", [A, B, EP, G])])
    ch = NetworkProgram(risky_often).replan(node(risky_often, A))
    assert ch.path[1] == risky_often.locate(R) and ch.reach_probability == round(2 / 3, 9) and ch.risky == 2
    short = build_network([demo("long", [A, B, EP, G]), demo("short", [A, B, G])])
    ch = NetworkProgram(short).replan(node(short, B))
    assert ch.path == (short.locate(B), short.locate(G)) and ch.reach_probability == 0.5


def test_a_step_without_class_joins_the_next_macro_and_a_final_macro_has_no_detection():
    lie2 = "V/G & E/N & E/F[box.F1] & E/E^P[box.F1,box.F2] & V/N"
    net = build_network([demo("d", [TIP, LIE, lie2, EP], [1.0, 1.0, 1.0, 1.0], line_track(0.01))])
    ch = NetworkProgram(net).replan(node(net, LIE))
    assert ch.macro.edges == ("n2->n3", "n3->n4") and ch.macro.classes == ("C",) and not ch.macro.final
    np.testing.assert_allclose(ch.macro.world, [0.02, 0.0, 0.0], atol=1e-12)
    assert ch.macro.duration == 2.0
    assert [s.node for s in ch.successors] == ["n4"]  # reached through the undetectable step
    ends_flat = build_network([demo("d", [TIP, LIE, lie2])])
    ch = NetworkProgram(ends_flat).replan(node(ends_flat, LIE))
    assert ch.macro.final and ch.macro.classes == () and ch.macro.target == ends_flat.goal


def test_successors_through_a_cycle_of_steps_without_class_walk_round_it():
    # LIE -> lie2 and back are '-' steps (no principal contact changes); the walk leaves the cycle
    # by lie2 -> EP (C) or LIE -> TIP (C). From LIE: 1/3 TIP at once, 2/3 into the cycle, whose walk
    # lands x = 1/2 EP + 1/2 (2/3 x + 1/3 TIP), x = 3/4 EP + 1/4 TIP: in all 1/2 EP, 1/2 TIP
    # (counting only the paths that use an edge once gave 3/7 EP, 4/7 TIP)
    lie2 = "V/G & E/N & E/F[box.F1] & E/E^P[box.F1,box.F2] & V/N"
    net = build_network([demo("1", [TIP, LIE, lie2, EP]), demo("2", [TIP, LIE, lie2, LIE, TIP])])
    prog = NetworkProgram(net)
    out = prog._outcomes(node(net, LIE), None)
    assert out == {node(net, EP): Fraction(1, 2), node(net, TIP): Fraction(1, 2)}
    # with one way out (LIE -> TIP), every walk round the cycle leaves by it
    loop = build_network([demo("1", [TIP, LIE, lie2, LIE, lie2]), demo("2", [TIP, LIE, TIP])])
    assert NetworkProgram(loop)._outcomes(node(loop, LIE), None) == {node(loop, TIP): Fraction(1)}


def test_the_gripper_position_tells_apart_two_visits_of_one_situation():
    # free at the start, touch, lift and move 0.2 m, free again, then into the groove
    t = np.array([0.0, 1.0, 2.0, 3.0])
    pos = np.array([[0, 0, 0.3], [0, 0, 0.28], [0.2, 0, 0.3], [0.2, 0, 0.25]], dtype=float)
    track = PoseTrack(t, pos, np.tile([1.0, 0, 0, 0], (4, 1)))
    net = build_network([demo("d", [FREE, TIP, FREE, GROOVE], poses=track)])
    prog = NetworkProgram(net)
    free = node(net, FREE)
    assert prog.replan(free, (0.0, 0.0, 0.3)).edge == f"{free}->{net.locate(TIP)}"
    assert prog.replan(free, (0.2, 0.0, 0.3)).edge == f"{free}->{net.locate(GROOVE)}"
    # position unknown: both departures, equal probability 1/2 of reaching the goal: the shorter one
    anyway = prog.replan(free)
    assert anyway.edge == f"{free}->{net.locate(GROOVE)}" and anyway.reach_probability == 0.5
    assert [c.edge for c in prog.plan_from_start()] == ["n1->n2", "n2->n1", "n1->n3"]
    assert all(c.reach_probability == 1.0 for c in prog.plan_from_start())


# --------------------------------------------------------------------------------------------------
# Identification and re-planning
# --------------------------------------------------------------------------------------------------

I_ = "V/G & E/N & V/E^LI[box.F1,box.F2]"
X = "V/G & E/N & V/F[wall.F1]"
GOAL = "V/G & E/N & V/E^LS[box.F2,floor.F1]"


def snapping_network() -> Network:
    """At the instable edge the DLO snaps onto box.F2 (twice) or, unexpectedly, onto the wall (once)."""
    return build_network(
        [demo("1", [A, I_, G, GOAL]), demo("2", [A, I_, X, G, GOAL]), demo("3", [A, I_, G, GOAL])]
    )


def test_replanning_after_an_unexpected_transition():
    net = snapping_network()
    prog = NetworkProgram(net)
    at = {s: node(net, s) for s in (A, I_, G, X, GOAL)}
    first = prog.replan(at[A], (0.0, 0.0, 0.3))
    assert first.macro.target == at[I_] and first.macro.classes == ("I",) and first.macro.risk == "risky"
    ch = prog.replan(at[I_], (0.0, 0.0, 0.3))
    assert ch.macro.target == at[G] and ch.macro.classes == ("S",)
    assert ch.reach_probability == round(2 / 3, 9)
    expected = [(at[G], round(2 / 3, 9)), (at[X], round(1 / 3, 9))]
    assert [(s.node, s.probability) for s in ch.successors] == expected
    # the sensor says: pushed against the wall (-y), not box.F2 (-x)
    reached = identify(ch.successors, (0.05, -0.9, 0.1))
    assert reached.node == at[X]
    again = prog.replan(reached.node, (0.0, 0.0, 0.3))
    assert again.macro.target == at[G] and again.macro.classes == ("E",)
    assert prog.replan(at[G]).macro.target == at[GOAL]
    assert prog.replan(at[GOAL]) is None  # at the goal: done
    # the expected outcome is identified from its own vector
    assert identify(ch.successors, (-2.0, 0.0, 0.0)).node == at[G]


def test_identify_ties_tolerance_and_no_vectors():
    a = Successor("n1", "s1", (), (0.0, 0.0, -1.0), 0.3)
    b = Successor("n2", "s2", (), (0.0, 0.0, -1.0), 0.7)
    free = Successor("n3", "s3", (), (0.0, 0.0, 0.0), 0.1)
    assert identify([a, b], (0, 0, -3)).node == "n2"  # a tie goes to the more probable
    assert identify([a, b, free], None).node == "n3"  # no force: free space
    assert identify([a, b, free], (0, 0, 1e-12)).node == "n3"
    assert identify([a, b], (1.0, 0.0, 0.0), tolerance=0.5) is None  # outside the network
    assert identify([Successor("n4", "s4", (), None, 1.0)], (0, 0, -1)) is None


def test_identify_with_sigma_weighs_probability_by_fit():
    """With ``sigma`` the successor's probability is the prior and the fit of its vector the
    likelihood: a likely successor 0.38 away beats an unlikely one that fits exactly at sigma 0.25,
    not when it is twice as far; outside the tolerance is still outside."""
    groove = Successor("n12", "groove", (), (-0.21, 0.06, -0.98), 0.75)
    edge = Successor("n8", "edge", (), (-0.54, 0.0, -0.84), 0.05)
    sensed = (-0.54, 0.0, -0.84)
    assert identify([groove, edge], sensed).node == "n8"  # nearest alone
    assert identify([groove, edge], sensed, 0.8, sigma=0.25).node == "n12"
    far = Successor("n12", "groove", (), (0.2, 0.0, -0.98), 0.75)
    assert identify([far, edge], sensed, 0.8, sigma=0.25).node == "n8"
    assert identify([groove, edge], (1.0, 0.0, 0.0), 0.5, sigma=0.25) is None


def test_a_situation_outside_the_network_is_reported():
    prog = NetworkProgram(snapping_network())
    with pytest.raises(NetworkError, match="n99 is not in the network"):
        prog.replan("n99")
    assert prog.network.locate("V/G & E/N & V/F[moon.F1]") is None


def test_no_path_to_the_goal_gives_no_choice():
    net = build_network([demo("a", [A, B, G]), demo("b", [A, R, EP]), demo("c", [A, B, G])])
    prog = NetworkProgram(net)
    assert net.goal == net.locate(G)
    assert prog.replan(node(net, EP)) is None
    assert prog.replan(node(net, R)) is None
    assert prog.replan(node(net, A)).path == tuple(net.locate(s) for s in (A, B, G))


def test_network_program_json_round_trip():
    prog = NetworkProgram(snapping_network(), name="snap", source="net.json")
    data = json.loads(prog.dumps())
    assert data["kind"] == "network-program" and data["version"] == 1
    assert data["summary"]["plan_macros"] == 3 and data["summary"]["plan_risky"] == 2
    node_i = next(n for n in data["nodes"] if n["situation"] == I_)
    ctx = {c["arrived_by"]: c for c in node_i["contexts"]}
    assert set(ctx) == {"n1->n2", "any"}
    assert ctx["any"]["choice"]["successors"][1]["vector"] == [0.0, -1.0, 0.0]
    back = NetworkProgram.from_json(data)
    assert back.dumps() == prog.dumps()
    assert "P(goal)=0.667" in prog.listing()
    with pytest.raises(NetworkError, match="not a network program"):
        NetworkProgram.from_json({"kind": "program"})


def test_a_flight_edge_is_classed_as_the_program_classes_it():
    """An instable contact left through free space and landed on within the flight time is S,E (as in
    programs), a direct snap S; an edge demonstrated both ways carries both classes."""
    from dlovr.model.discrete import parse_discrete_situation as P
    from dlovr.model.network import Demonstration, build_network
    from dlovr.model.program import PoseTrack, TimedSituation

    corner, landed = P("V/G & E/N & V/VI[a.F1,a.F2,a.F3]"), P("V/G & E/N & V/F[a.F1]")  # same object
    track = PoseTrack(np.array([0.0, 2.0]), np.zeros((2, 3)), np.array([[1.0, 0, 0, 0]] * 2))

    def demo(flight: bool) -> Demonstration:
        states = (TimedSituation(0.0, 1.0, corner), TimedSituation(1.0, 1.0, landed, through_free=flight))
        return Demonstration(f"d{flight}", states, track, "scene", "0" * 64)

    for demos, label in (([demo(True)], ("S", "E")), ([demo(False)], ("S",))):
        (edge,) = build_network(demos).edges
        assert edge.classes == label


def test_merged_detections_take_the_median_of_the_derived_parameters():
    from dlovr.model.network import merge_detections
    from dlovr.model.program import Detection

    def det(thr: float, how: str = "derived: 40% of the step") -> Detection:
        return Detection("E", "force_along_contact_vector", {"force_threshold_n": thr, "max_angle_deg": 30.0},
                         {"force_threshold_n": how, "max_angle_deg": "default: E keeps it"})

    (m,) = merge_detections([[det(0.1)], [det(0.3)], [det(0.2)], [det(0.5, "default: no wrench signal")]])
    assert m.params == {"force_threshold_n": 0.2, "max_angle_deg": 30.0}  # the default one left out
    assert m.derivation["force_threshold_n"] == "derived: median over 3 of 4 demonstrations (0.1 to 0.3)"
    assert m.derivation["max_angle_deg"] == "default: E keeps it"
    (d,) = merge_detections([[det(0.5, "default: no wrench signal")]] * 2)
    assert d.params["force_threshold_n"] == 0.5 and d.derivation["force_threshold_n"].startswith("default")
    assert merge_detections([]) == ()


# --------------------------------------------------------------------------------------------------
# Edge tracks (dlovr.model.tracks)
# --------------------------------------------------------------------------------------------------


def test_each_edge_keeps_the_reference_demonstrations_track_else_the_representative_one():
    """An edge the reference demonstration took (the first given that ended in the goal) keeps its
    track: commanded poses from entering the source to entering the target, every 10 ms. Another
    edge keeps the occurrence nearest the median displacement. The JSON round trip is exact."""
    from dlovr.model.network import reference_demonstration
    from dlovr.model.tracks import SAMPLE_S

    def d(name, seq, v):
        return replace(demo(name, seq, [1.0] * len(seq), line_track(v)), commands=line_track(v, 40))

    lie, groove = [FREE, TIP, LIE], [FREE, GROOVE]
    demos = [d("A", groove, 0.05), d("B", lie, 0.01), d("C", lie, 0.02), d("D", groove, 0.03),
             d("E", lie, 0.01), d("F", groove, 0.035), d("G", lie, 0.02)]
    net = build_network(demos)
    assert net.goal == net.locate(LIE)
    paths = [["n1", "n4"], ["n1", "n3"], ["n1", "n2", "n3"], ["n1", "n2", "n3"]]
    assert reference_demonstration(paths, ["n1", "n2", "n3", "n4"]) == 1
    by = {(net.node(e.source).situation, net.node(e.target).situation): e for e in net.edges}
    tip = by[(FREE, TIP)].track
    assert tip is not None and tip.demonstration == 1  # B: the first that ended in the goal
    assert tip.t[0] == 0.0 and tip.t[-1] == 1.0 and len(tip.t) == round(1.0 / SAMPLE_S) + 1
    np.testing.assert_allclose(tip.pos[-1] - tip.pos[0], [0.01, 0.0, 0.0], atol=1e-9)
    assert by[(FREE, GROOVE)].track.demonstration == 5  # 0.035 m/s: nearest the median of A, D, F
    back = Network.loads(net.dumps())
    assert back == net and back.edges[0].track == net.edges[0].track
    assert build_network([replace(x, commands=None) for x in demos]).edges[0].track is None


def test_joined_tracks_repeat_each_motion_from_where_the_last_ended():
    """Two edges' tracks from different places become one continuous track: a push along +x, then a
    quarter turn about z that moves along +y in its own demonstration, both repeated from the joint."""
    import math

    from dlovr.model.tracks import EdgeTrack, join

    t = np.array([0.0, 0.5, 1.0])
    still_q = np.tile([1.0, 0, 0, 0], (3, 1))
    push = EdgeTrack(0, 0.0, t, np.array([[0.0, 0, 0], [0.05, 0, 0], [0.1, 0, 0]]), still_q)
    c, s = math.cos(math.pi / 8), math.sin(math.pi / 8)
    turn_q = np.array([[1.0, 0, 0, 0], [math.cos(math.pi / 16), 0, 0, math.sin(math.pi / 16)], [c, 0, 0, s]])
    turn = EdgeTrack(1, 3.0, t, np.array([[5.0, 5, 1], [5.0, 5.1, 1], [5.0, 5.2, 1]]), turn_q)
    out = join([push, turn])
    np.testing.assert_allclose(out.t, [0.0, 0.5, 1.0, 1.5, 2.0])
    np.testing.assert_allclose(out.pos[-1], [0.1, 0.2, 0.0], atol=1e-12)
    np.testing.assert_allclose(out.quat[-1], [c, 0.0, 0.0, s], atol=1e-12)
    np.testing.assert_allclose(out.pos[2], [0.1, 0.0, 0.0])


#: Two instable states the tip may go to from TIP, and the goal after either.
INST_X, INST_Y = "V/G & E/N & V/E^LI[box.F1,box.F2]", "V/G & E/N & V/E^LI[box.F1,box.F3]"
BRANCH_GOAL = "V/G & E/N & V/F[box.F2]"


def _branching_demos() -> list[Demonstration]:
    """Three demonstrations FREE, TIP, an instable state, the goal: the reference (A, the first)
    through INST_X, the two others through INST_Y; 1 s a situation."""

    def d(name, seq):
        return replace(demo(name, seq, [1.0] * len(seq), line_track(0.01)), commands=line_track(0.01, 40))

    seqs = (("A", INST_X), ("B", INST_Y), ("C", INST_Y))
    return [d(n, [FREE, TIP, inst, BRANCH_GOAL]) for n, inst in seqs]


def test_network_macros_follow_the_reference_demonstration_where_it_went():
    """Along the reference's own edges a macro lies on its clock (from its entry into the node to its
    entry into the target); an instable transition the plan takes elsewhere than the reference (its
    motion does not choose where it leads) follows the reference's motion through its own one."""
    from dlovr.execution.network_run import borrows_motion, reference_goal_entry, reference_span

    inst_x, inst_y = INST_X, INST_Y
    prog = NetworkProgram(build_network(_branching_demos()))
    net = prog.network
    assert net.reference is not None and net.reference.demonstration == 0
    first = prog.replan(net.start, None)
    assert reference_span(prog, first.macro, net.start) == (0.0, 1.0)
    tip = node(net, TIP)
    at_tip = prog.replan(tip, None)
    assert at_tip.macro.target == net.locate(inst_y) and at_tip.macro.classes == ("I",)
    assert reference_span(prog, at_tip.macro, tip) == (1.0, 2.0)  # A's own I, from TIP to inst_x
    assert reference_goal_entry(prog) == 3.0
    # that macro's end by its motion says nothing of where the DLO went (the reference's motion went
    # to inst_x): a run senses it instead of taking inst_y (peg_in_hole's network from 20 program
    # runs took the groove corner's I this way and went on from the hole as if outside it: 1 of 10)
    assert borrows_motion(prog, at_tip.macro, tip)
    assert not borrows_motion(prog, first.macro, net.start)
    ref_i = replace(at_tip.macro, edges=(f"{tip}->{net.locate(inst_x)}",), target=net.locate(inst_x))
    assert not borrows_motion(prog, ref_i, tip)  # the reference's own I: its motion made it


def _shape(net: Network):
    """The graph's shape: its situations and its transitions (source, target, class)."""
    sit = {n.id: n.situation for n in net.nodes}
    return sorted(sit.values()), sorted((sit[e.source], sit[e.target], e.label) for e in net.edges)


def test_a_network_without_chatter_has_the_shape_of_the_scripted_demonstrations():
    """A person's hand at the tip angle flips TIP/LIE back and forth: as recorded the network shows it
    (a back edge, a cycle, a plan less likely than 1); with each demonstration's chatter removed
    (``dlovr network --without-chatter``) it is the scripted demonstrations' graph, said so in the file."""
    from dlovr.model.program import ChatterRules

    scripted = demo("script", [FREE, TIP, LIE, GROOVE], [1.0, 2.0, 2.0, 1.0])
    person = demo("person", [FREE, TIP, LIE, TIP, LIE, TIP, LIE, GROOVE],
                  [1.0, 2.0, 0.3, 0.05, 0.2, 0.04, 1.5, 1.0])
    script_net = build_network([scripted, scripted])
    as_recorded = build_network([scripted, person])
    nodes, edges = _shape(as_recorded)
    assert nodes == _shape(script_net)[0] and set(edges) - set(_shape(script_net)[1]) == {(LIE, TIP, "C")}
    plan = NetworkProgram(as_recorded).plan_from_start()
    assert plan[0].reach_probability < 1.0
    cleaned = build_network([scripted, person], chatter=ChatterRules())
    assert _shape(cleaned) == _shape(script_net) and not as_recorded.chatter and "removed" in cleaned.chatter
    plans = [[c.macro.classes for c in NetworkProgram(n).plan_from_start()] for n in (cleaned, script_net)]
    assert plans[0] == plans[1] and NetworkProgram(cleaned).plan_from_start()[0].reach_probability == 1.0
    assert Network.loads(cleaned.dumps()).chatter == cleaned.chatter
    assert "chatter" not in json.loads(as_recorded.dumps())


def test_by_default_only_a_hands_chatter_is_removed():
    """``hands_only`` (the default of ``dlovr network``): the chatter of a demonstration whose
    commanded track a hand made (it trembles) is removed; a script's flips (a straight leg at constant
    speed) stay, they are the scene's; a demonstration without a commanded track counts as a
    hand's. The file says how many."""
    from dlovr.model.network import by_hand
    from dlovr.model.program import ChatterRules

    t = np.arange(0.0, 8.0, 0.002)
    line = np.stack([0.01 * t, np.zeros_like(t), np.full_like(t, 0.3)], axis=1)
    quat = np.tile([1.0, 0.0, 0.0, 0.0], (len(t), 1))
    machine = PoseTrack(t, line, quat)
    hand = PoseTrack(t, line + 0.0003 * np.sin(2 * np.pi * 9.0 * t)[:, None], quat)
    flips = ([FREE, TIP, LIE, TIP, LIE, GROOVE], [1.0, 2.0, 0.3, 0.05, 1.5, 1.0])
    script, person, unknown = (replace(demo(n, *flips), commands=c)
                               for n, c in (("script", machine), ("person", hand), ("unknown", None)))
    assert [by_hand(d) for d in (script, person, unknown)] == [False, True, True]
    assert not by_hand(replace(person, program_run=True))  # the executor's track, not a hand's
    net = build_network([script, person, unknown], ChatterRules(), hands_only=True)
    back = [e for e in net.edges if (e.source, e.target) == (node(net, LIE), node(net, TIP))]
    assert [e.count for e in back] == [1]  # the script's flip back, not the others'
    assert "made by a hand (2 of 3)" in net.chatter
    assert not build_network([script], ChatterRules(), hands_only=True).chatter
    everyone = build_network([script, person, unknown], ChatterRules())
    assert all((e.source, e.target) != (node(everyone, LIE), node(everyone, TIP)) for e in everyone.edges)


def test_the_plan_is_never_less_likely_than_the_reference_demonstrations_own_path():
    """``reference_path`` is the edges the reference took, in its order; ``path_probability`` gives a
    path the planner's probability (departures applicable where it gets, 0 for one that is not);
    the plan from the start is at least as likely (here more: two of three went the other way)."""
    inst_x, inst_y, goal = INST_X, INST_Y, BRANCH_GOAL
    demos = _branching_demos()
    prog = NetworkProgram(build_network(demos))
    net = prog.network
    ids = {s: node(net, s) for s in (FREE, TIP, inst_x, inst_y, goal)}
    ref = reference_path(prog.network)
    assert ref == tuple(f"{ids[a]}->{ids[b]}" for a, b in ((FREE, TIP), (TIP, inst_x), (inst_x, goal)))
    plan = prog.plan_from_start()
    start = net.starts[0].position
    assert prog.path_probability(ref, start) == round(1 / 3, 9) < plan[0].reach_probability == round(2 / 3, 9)
    assert prog.path_probability([e for ch in plan for e in ch.macro.edges], start) == round(2 / 3, 9)
    far = (start[0] + 1.0, start[1], start[2])
    assert prog.path_probability(ref, far) == round(1 / 3, 9)  # the nearest departures still apply
    assert reference_path(build_network([replace(x, commands=None) for x in demos])) == ()


def test_a_plan_bets_on_a_transition_it_cannot_sense_only_where_the_motion_made_it_most_often():
    """From B the demonstrations went on to W three times (never to the goal), to FREE twice (then to
    the goal) and to EP once (then to the goal). Through FREE is the likelier path; but when B -> FREE
    shows no force step (a run takes it to have happened without sensing), it is not the departure
    the motion made most often there, and the plan goes through EP instead."""
    from dlovr.model.planning import blind
    from dlovr.model.program import Detection

    w = "V/G & E/N & V/E^LI[box.F1,box.F2]"
    ends = ("V/G & E/N & V/F[wall.F1]", "V/G & E/N & V/E^LS[box.F2,floor.F1]", GROOVE)
    net = build_network([demo("ref", [A, B, EP, G]), demo("y1", [A, B, FREE, G]), demo("y2", [A, B, FREE, G]),
                         *(demo(f"w{k}", [A, B, w, z]) for k, z in enumerate(ends))])
    assert net.goal == node(net, G)
    b, free, ep = node(net, B), node(net, FREE), node(net, EP)
    ch = NetworkProgram(net).replan(b)
    assert ch is not None and ch.path == (b, free, net.goal) and ch.reach_probability == round(1 / 3, 9)
    weak = Detection("E", "release", {"force_threshold_n": 0.05, "step_n": 0.01})
    edges = tuple(replace(e, detection=(weak,)) if e.id == f"{b}->{free}" else e for e in net.edges)
    assert [blind(e) for e in edges if e.source == b] == [False, True, False]  # EP, FREE, W
    ch = NetworkProgram(replace(net, edges=edges)).replan(b)
    assert ch is not None and ch.path == (b, ep, net.goal) and ch.reach_probability == round(1 / 6, 9)
    assert {s.node for s in ch.successors} == {ep, free, node(net, w)}  # still an outcome


def test_the_reference_demonstrations_own_departure_applies_wherever_the_gripper_is():
    """At TIP the reference (and one more) went on into the goal from x = 0; another demonstration
    went from x = 0.1 m to LIE, from where none reached the goal. With the gripper at x = 0.1 m the
    reference's departure is 0.1 m from there, beyond the nearest's 0 + reach, but a run can follow
    the reference's track from wherever it got to (as a compiled program does): it stays
    applicable, and the plan goes on along it instead of finding no path (issue 33, trial 19)."""
    here = line_track(0.0, 3)
    there = PoseTrack(np.array([0.0, 1.0, 2.0]), np.array([[0, 0, 0.3], [0.1, 0, 0.3], [0.1, 0, 0.3]]),
                      np.tile([1.0, 0.0, 0.0, 0.0], (3, 1)))

    def d(name, seq, track):
        return replace(demo(name, seq, [1.0] * 3, track), commands=track)

    net = build_network([d("ref", [FREE, TIP, GROOVE], here), d("y", [FREE, TIP, GROOVE], here),
                         d("z", [FREE, TIP, LIE], there)])
    prog = NetworkProgram(net)
    tip, goal, lie = node(net, TIP), node(net, GROOVE), node(net, LIE)
    assert net.goal == goal and f"{tip}->{goal}" in reference_path(net)
    assert {e.target for e in prog.applicable(tip, (0.1, 0.0, 0.3))} == {goal, lie}
    ch = prog.replan(tip, (0.1, 0.0, 0.3))
    assert ch is not None and ch.path == (tip, goal) and ch.reach_probability == round(2 / 3, 9)
    two = (d("ref", [FREE, TIP, GROOVE], here), d("z", [FREE, TIP, LIE], there))
    ref_less = NetworkProgram(build_network([replace(x, commands=None) for x in two]))
    assert ref_less.replan(tip, (0.1, 0.0, 0.3)) is None  # without a reference: only the near departures
