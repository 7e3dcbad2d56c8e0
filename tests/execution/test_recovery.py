"""Recovery by replanning (dlovr.execution.recovery): a compiled program that missed its goal
identifies the sensed situation in a transition network and plans again from there. Unit-level on
a hand-made network; the simulated case is in test_network_run.py (it shares that module's network)."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

from dlovr.execution.executor import ExecOptions, Execution, Replan
from dlovr.execution.recovery import Recovery, check_recovery, sensed_node
from dlovr.execution.scoring import format_result, score
from dlovr.execution.trials import replan_counts
from dlovr.model.discrete import DiscreteSituation, parse_discrete_situation
from dlovr.model.network import Demonstration, build_network
from dlovr.model.planning import NetworkProgram
from dlovr.model.program import PoseTrack, ProgramError, TimedSituation

FREE = "V/G & E/N & V/N"
TOP = "V/G & E/N & V/F[block.F2]"  # the tip on the block's top: pressed down, vector -z
WALL = "V/G & E/N & V/F[wall.F1]"  # against the wall: vector -y
GOAL = "V/G & E/N & V/E^LS[block.F1,floor.F1]"
STUCK = "V/G & E/N & V/F[block.F3]"  # demonstrated, but never led on to the goal: vector -x
VECTORS = {
    "V/F[block.F2]": (0.0, 0.0, -1.0),
    "V/F[wall.F1]": (0.0, -1.0, 0.0),
    "V/F[block.F3]": (-1.0, 0.0, 0.0),
    "V/F[block.F4]": (0.0, 0.0, -1.0),
    "V/E^LS[block.F1,floor.F1]": (-0.6, 0.0, -0.8),
}


def S(text: str) -> DiscreteSituation:
    s = parse_discrete_situation(text)
    return DiscreteSituation(tuple(replace(c, vector=VECTORS.get(c.format())) for c in s.contacts))


def demo(name: str, seq: list[str], xs: list[float] | None = None) -> Demonstration:
    """Situations a second each; the gripper at ``x`` (m) of ``xs`` as each begins (else still)."""
    states = tuple(TimedSituation(float(i), 1.0, S(s)) for i, s in enumerate(seq))
    xs = xs or [0.0] * len(seq)
    pos = np.array([[x, 0.0, 0.3] for x in xs])
    poses = PoseTrack(np.arange(len(seq), dtype=float), pos, np.tile([1.0, 0.0, 0.0, 0.0], (len(seq), 1)))
    return Demonstration(name, states, poses, "box", "abc")


@pytest.fixture(scope="module")
def prog() -> NetworkProgram:
    net = build_network([
        demo("a", [FREE, TOP, GOAL]), demo("b", [FREE, WALL, TOP, GOAL]), demo("c", [FREE, TOP, GOAL]),
        demo("d", [FREE, STUCK]), demo("e", [FREE, TOP, GOAL]),
    ])
    return NetworkProgram(net)


def test_the_sensed_situation_is_the_nearest_node_with_a_path_to_the_goal(prog):
    net, pos = prog.network, (0.0, 0.0, 0.3)
    at = {s: net.locate(S(s)) for s in (FREE, TOP, WALL, GOAL, STUCK)}
    assert net.goal == at[GOAL]
    assert sensed_node(prog, (0.1, -0.9, 0.0), pos, 0.8).node == at[WALL]
    assert sensed_node(prog, (0.0, 0.1, -2.0), pos, 0.8).node == at[TOP]
    assert sensed_node(prog, None, pos, 0.8).node == at[FREE]  # no contact force: free space
    # the goal check has said the goal does not fit: the goal node is never the answer
    assert sensed_node(prog, (-0.6, 0.0, -0.8), pos, None).node != at[GOAL]
    # a node from which no demonstration went on to the goal is no place to plan from
    assert sensed_node(prog, (-1.0, 0.0, 0.0), pos, 0.8) is None
    assert sensed_node(prog, (0.0, 0.0, 1.0), pos, 0.8) is None  # pushed up: outside the network


def test_a_network_of_another_goal_or_scene_cannot_recover_a_program(prog):
    class P:  # the two things check_recovery reads of a program
        scene: str | None = None
        goal: tuple[str, ...] = ("V/E^LS[block.F1,floor.F1]",)

    check_recovery(P(), prog)  # type: ignore[arg-type]
    P.goal = ("V/F[block.F2]",)
    with pytest.raises(ProgramError, match="is not the program's"):
        check_recovery(P(), prog)  # type: ignore[arg-type]
    P.goal, P.scene = ("V/E^LS[block.F1,floor.F1]",), "table"
    with pytest.raises(ProgramError, match="made in scene box, the program in table"):
        check_recovery(P(), prog)  # type: ignore[arg-type]
    with pytest.raises(ValueError, match="max_replans"):
        Recovery(prog, max_replans=-1)


def test_a_run_that_a_replan_brought_to_the_goal_succeeds_and_says_so(touch):
    """Judging: a replan that ended at the goal makes the run a success (recovered) even where the
    program's own macro failed; the report names each replan; the trials count them."""
    program, *_ = touch
    kept = [type("K", (), {"situation": S("V/G & E/N & V/F[table.F1]"), "start": 0.0, "end": 1.0})()]
    ex = Execution(program, ExecOptions(), kept=kept)
    assert score(ex).success and not score(ex).recovered
    attempt = Replan("n1", "V/G & E/N & V/N", None, ("n1", "n2"), True, "", True, 1.2, 1.0, 3.0)
    ex.replans.append(attempt)
    res = score(ex)
    assert res.success and res.recovered and res.replans == (attempt,)
    text = format_result(res)
    assert "replan 1: sensed n1 (V/G & E/N & V/N); network path n1 -> n2: arrived at the goal node" in text
    assert "after 1 replan(s) through the network" in text
    ex.kept = []  # the replan did not reach it
    res = score(ex)
    assert not res.success and not res.recovered
    # a network program's trial counts its own replans (dlovr run NET --trials crashed on it)
    trials = [{"program": score(ex).to_json()}, {"program": {"success": True}}, {"program": {"replans": 2}}]
    assert replan_counts(trials) == {"replanned": 1, "recovered": 0, "attempts": 1}


def test_where_the_gripper_is_tells_apart_situations_that_push_alike():
    """Two tops push the gripper alike (-z): the one the demonstrations were on near the gripper is
    the one sensed."""
    top2 = "V/G & E/N & V/F[block.F4]"
    net = build_network([demo("a", [FREE, TOP, GOAL], [0.0, 0.1, 0.1]),
                         demo("b", [FREE, top2, GOAL], [0.0, -0.1, -0.1])])
    prog = NetworkProgram(net)
    assert sensed_node(prog, (0, 0, -1), (0.1, 0.0, 0.3), 0.8).node == net.locate(S(TOP))
    assert sensed_node(prog, (0, 0, -1), (-0.1, 0.0, 0.3), 0.8).node == net.locate(S(top2))


def test_past_bets_nothing_sensed_the_situation_is_one_the_program_aimed_at_since_its_last_detection():
    """A run whose last macros ended by their motion went where the demonstration went, so where the
    gripper is tells nothing: the sensed situation is sought among the one the last detection
    confirmed and those the later macros aimed at, whatever the gripper's position (issue 28: a
    blind run's tip left in the groove beside the hole was taken, by the gripper's position, for
    the tip in the hole)."""
    from types import SimpleNamespace as NS

    from dlovr.execution.recovery import unconfirmed_nodes

    net = build_network([demo("a", [FREE, TOP, GOAL], [0.0, 0.1, 0.1]),
                         demo("b", [FREE, WALL, GOAL], [0.0, -0.1, -0.1]), demo("c", [FREE, STUCK])])
    prog = NetworkProgram(net)
    macros = [NS(index=k + 1, to_situation=s) for k, s in enumerate([STUCK, FREE, TOP, WALL, GOAL])]
    ended = ["detected", "detected", "motion", "motion", "motion"]
    runs = [NS(macro=m, ended=e) for m, e in zip(macros, ended, strict=True)]
    out = NS(program=NS(macros=macros), runs=runs)
    among = unconfirmed_nodes(prog, out)  # type: ignore[arg-type]
    assert among == {net.locate(S(s)) for s in (FREE, TOP, WALL, GOAL)}
    # the gripper over TOP, pushed along -y: by position only TOP is near, and it does not fit
    assert sensed_node(prog, (0, -1, 0), (0.1, 0.0, 0.3), 0.8) is None
    assert sensed_node(prog, (0, -1, 0), (0.1, 0.0, 0.3), 0.8, among).node == net.locate(S(WALL))
    out.runs = [NS(macro=m, ended="motion") for m in macros]
    assert unconfirmed_nodes(prog, out) is None  # type: ignore[arg-type]  # nothing sensed: any node
