"""Recovery by replanning (dlovr.execution.recovery): a compiled program that missed its goal
identifies the sensed situation in a transition network and plans again from there. Unit-level on
a hand-made network; the simulated case is in test_network_run.py (it shares that module's network)."""

from __future__ import annotations

from dataclasses import replace
from types import SimpleNamespace
from typing import Any, cast

import numpy as np
import pytest

from dlovr.execution.executor import ExecOptions, Execution, Replan
from dlovr.execution.network_run import SEARCH_CONFIRM_S, SEARCH_M, SEARCH_SPEED, NetworkOptions, _NetworkRun
from dlovr.execution.recovery import RETRACE_SETTLE_S, Recovery, check_recovery, retrace, sensed_node
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


# --------------------------------------------------------------------------------------------------
# Searching on and going back (the network loop's search, the recovery's retrace)
# --------------------------------------------------------------------------------------------------


_Q = np.array([1.0, 0.0, 0.0, 0.0])  # the gripper's orientation, held


class _Ses:
    """A session whose sensed force is ``force_at(commanded position)`` (no cable, no lag)."""

    def __init__(self, force_at):
        self.force_at, self.dt, self.events = force_at, 0.002, []
        self.sim = SimpleNamespace(target_pos=np.array([0.02, 0.0, 0.3]),
                                   target_quat=np.array([1.0, 0.0, 0.0, 0.0]), time=1.0)
        self.opts = SimpleNamespace(detect="force")
        self.f, self.poses = force_at(self.sim.target_pos), []

    def step(self, pos, quat):
        self.sim.target_pos, self.sim.target_quat = np.array(pos, float), np.array(quat, float)
        self.sim.time += self.dt
        self.f = self.force_at(self.sim.target_pos)
        self.poses.append(self.sim.target_pos.copy())

    def hold(self, pos, quat, seconds):
        for _ in range(round(seconds / self.dt)):
            self.step(pos, quat)
            yield

    def emit(self, kind, macro, text):
        self.events.append((kind, text))


def _drive(gen):
    try:
        while True:
            next(gen)
    except StopIteration as stop:
        return stop.value


def _searcher(prog, wall_x: float, speed: float = 0.01, search: float = SEARCH_M):
    """A network loop at TOP (the tip pressed down, vector -z) whose macro toward the goal (vector
    (-0.6, 0, -0.8)) ended by its motion at x = 0.02 m, moving along +x at ``speed``; the goal's
    contact begins at ``wall_x``."""
    top = prog.network.locate(S(TOP))
    goal = (-0.6, 0.0, -0.8)

    def force_at(p):  # a contact with vector v adds -v F (F = 1 N); a 10 ms blip at 22 mm fits nothing
        blip = 0.022 <= p[0] <= 0.0221 and wall_x > 0.0221
        return -np.array(goal if p[0] >= wall_x else (0.0, 1.0, 0.0) if blip else (0.0, 0.0, -1.0))

    ses = _Ses(force_at)
    scene = SimpleNamespace(dlo=SimpleNamespace(mass=0.0))
    run = _NetworkRun(prog, cast(Any, ses), scene, NetworkOptions(take_back=False, search=search), start=top)
    for i in range(51):  # the macro's last 0.1 s of commanded motion
        run.commanded.append((0.9 + i * 0.002, np.array([0.02 - speed * (0.1 - i * 0.002), 0.0, 0.3]), _Q))
    choice = prog.replan(top, (0.02, 0.0, 0.3))
    assert choice is not None and choice.macro.target == prog.network.goal
    return run, ses, choice


def test_a_macro_that_ended_by_its_motion_short_of_its_transition_searches_on_until_it_is_sensed(prog):
    """Along the macro's last motion (+x, 10 mm/s), the orientation held, until the sensed vector has
    shown the target for SEARCH_CONFIRM_S (a shorter blip that fits no situation does not stop it)."""
    run, ses, choice = _searcher(prog, wall_x=0.03)
    m = cast(Any, SimpleNamespace(detection=()))
    assert run._unconfirmed(choice, np.array([0.0, 0.0, -1.0]), m)  # still the situation it left
    assert not run._unconfirmed(choice, np.array([-0.6, 0.0, -0.8]), m)  # the target: confirmed
    moved, changed = _drive(run._search(1, choice, m))
    assert changed and 0.010 <= moved <= 0.010 + 0.01 * SEARCH_CONFIRM_S + 1e-4
    assert np.allclose(np.array(ses.poses)[:, 1:], [0.0, 0.3])  # straight on along +x
    assert ses.sim.target_quat.tolist() == [1.0, 0.0, 0.0, 0.0]
    assert [k for k, _ in ses.events] == ["search", "search"] and "changed" in ses.events[1][1]


def test_a_search_stops_where_the_sensed_vector_fits_no_situation(prog):
    """A contact no demonstration sensed there (the tip at the groove's end) is the change searched for."""
    top = prog.network.locate(S(TOP))
    ses = _Ses(lambda p: -np.array((0.0, 1.0, 0.0) if p[0] >= 0.025 else (0.0, 0.0, -1.0)))
    run = _NetworkRun(prog, cast(Any, ses), SimpleNamespace(dlo=SimpleNamespace(mass=0.0)),
                      NetworkOptions(take_back=False, search=SEARCH_M), start=top)
    for i in range(51):
        run.commanded.append((0.9 + i * 0.002, np.array([0.019 + i * 0.00002, 0.0, 0.3]), _Q))
    choice = prog.replan(top, (0.02, 0.0, 0.3))
    moved, changed = _drive(run._search(1, choice, cast(Any, SimpleNamespace(detection=()))))
    assert changed and 0.005 <= moved <= 0.005 + 0.01 * SEARCH_CONFIRM_S + 1e-4


def test_a_search_is_bounded_slow_and_only_where_it_can_sense_the_target(prog):
    run, ses, choice = _searcher(prog, wall_x=0.05)  # 3 cm on: beyond the search
    m = cast(Any, SimpleNamespace(detection=()))
    moved, changed = _drive(run._search(1, choice, m))
    assert not changed and moved == pytest.approx(SEARCH_M, abs=2e-4)
    run, ses, choice = _searcher(prog, wall_x=0.025, speed=0.35)  # a fast lowering: searched slowly
    t0 = ses.sim.time
    moved, changed = _drive(run._search(1, choice, m))
    assert changed and ses.sim.time - t0 >= moved / SEARCH_SPEED and SEARCH_SPEED <= 0.05
    run, ses, choice = _searcher(prog, wall_x=0.03, speed=0.0)  # the macro ended standing still
    assert _drive(run._search(1, choice, m)) == (0.0, False) and ses.poses == []
    run, _, choice = _searcher(prog, wall_x=0.03, search=0.0)  # network runs do not search
    assert not run._unconfirmed(choice, np.array([0.0, 0.0, -1.0]), m)


def test_a_recovery_first_goes_back_along_its_bets_to_its_last_detection():
    """The macros after the last detection ended by their motion: the gripper goes back along the
    commanded poses, in reverse at their pace, to the pose commanded when that detection ended."""
    q = np.array([1.0, 0.0, 0.0, 0.0])
    poses = [(t, np.array([x, 0.0, 0.3]), q) for t, x in ((0.5, 0.0), (1.0, 0.01), (1.5, 0.02), (2.0, 0.03))]
    runs = [SimpleNamespace(ended="detected", ended_at=1.0, macro=SimpleNamespace(index=5)),
            SimpleNamespace(ended="motion", ended_at=2.0, macro=SimpleNamespace(index=6))]
    ses = _Ses(lambda p: np.zeros(3))
    back = _drive(retrace(ses, SimpleNamespace(runs=runs), poses))  # type: ignore[arg-type]
    assert back == pytest.approx(1.0)
    xs = [round(float(p[0]), 4) for p in ses.poses]
    assert xs[0] == 0.02 and xs[-1] == 0.01 and 0.0 not in xs and 0.03 not in xs
    assert len(xs) == round(1.0 / ses.dt) + round(RETRACE_SETTLE_S / ses.dt)
    # nothing ran after the last detection: nothing to go back along
    assert _drive(retrace(ses, SimpleNamespace(runs=runs[:1]), poses)) == 0.0  # type: ignore[arg-type]
