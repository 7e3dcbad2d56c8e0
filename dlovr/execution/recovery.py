"""Recovery by replanning: a compiled program that missed its goal plans again through a transition
network from the situation it senses (issue 28, item 3; docs/programs.md, "Recovery").

A compiled program repeats one demonstration; where the scene differs more than it can absorb (the
objects a centimetre away and not registered) every macro may "succeed" and the run still end in the
wrong place. The sensed goal check (:func:`dlovr.execution.executor.goal_check`) tells the robot so
from the wrench alone. Given a network program of the same scene (``dlovr run PROGRAM --network
NET-PROGRAM``), the run then:

1. takes the program's end, or the macro it stopped at (one that reached its allowance undetected),
   holds the pose ``final_settle`` s and checks the goal (after the last macro this was done
   already);
2. where the check does not confirm the goal, **identifies the sensed situation**: the contact
   vector sensed over the hold's last 0.2 s (the sensed force minus the cable's weight, as the
   network runs sense it, :func:`dlovr.execution.network_run.sensed_contact_vector`) against the
   expected vector of every node of the network but the goal (the goal check has just said the goal
   does not fit) that has a demonstrated path to the goal from the gripper's position and, on the
   first attempt, that the program confirmed by its last detection or aimed at after it
   (:func:`unconfirmed_nodes`: the macros after its last detection ended by their motion, bets
   that nothing sensed, so the gripper went where the demonstration went and its position tells
   nothing); without such a detection (and on later attempts), those the demonstrations entered
   near the gripper's position (:func:`near_nodes`) (:func:`sensed_node`: the nearest within the
   network options' ``tolerance``; a tie goes to the node visited more often, then the smaller id);
3. runs the network loop from that node (:func:`dlovr.execution.network_run.network_steps_from`:
   plan, guarded macro, sense, identify, plan again ... until it arrives at the goal node, or a
   situation outside the network, a node without a path or a failed macro stops it);
4. holds and checks the goal again; steps 2-4 are repeated while the check does not confirm the goal,
   at most ``max_replans`` times (:data:`MAX_REPLANS` by default), and not after a sensed situation
   that fits no node (sensing again would find the same).

Each attempt is a :class:`dlovr.execution.executor.Replan` in the run's result (``replans``). The run
is judged as any other (:mod:`dlovr.execution.scoring`): the goal is reached when the tracker's last
situation has the goal's principal contacts; a run whose macro failed but that a replan brought to
the goal counts as a success (``recovered``).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from dlovr.execution.demo_track import DemoTrack
from dlovr.execution.executor import (
    ENDED_OK,
    Execution,
    Replan,
    Session,
    Steps,
    final_hold,
    program_steps,
)
from dlovr.execution.network_run import (
    SEARCH_M,
    NetworkOptions,
    Pose,
    commanded_poses,
    network_steps_from,
    rounded_vector,
    sensed_contact_vector,
)
from dlovr.model.planning import NetworkProgram, Successor, departure_distance, expected_vector, identify
from dlovr.model.program import Program, ProgramError

#: How many times by default a run plans again through the network after its goal check failed.
MAX_REPLANS = 2
#: How long (s) the gripper holds after going back (:func:`retrace`) before it senses.
RETRACE_SETTLE_S = 0.3



@dataclass(frozen=True)
class Recovery:
    """What a compiled program recovers through: the network program (of the same scene and goal),
    the most replans (:data:`MAX_REPLANS`) and the network loop's options (by default searching on
    :data:`dlovr.execution.network_run.SEARCH_M` along a macro that ended by its motion short of its
    transition, :meth:`dlovr.execution.network_run._NetworkRun._search`)."""

    network: NetworkProgram
    max_replans: int = MAX_REPLANS
    options: NetworkOptions = field(default_factory=lambda: NetworkOptions(search=SEARCH_M))
    retrace: bool = True

    def __post_init__(self) -> None:
        if not (isinstance(self.max_replans, int) and self.max_replans >= 0):
            raise ValueError(f"max_replans must be an integer >= 0, got {self.max_replans!r}")


def check_recovery(program: Program, nprog: NetworkProgram) -> None:
    """Raise :class:`ProgramError` when ``nprog`` cannot recover ``program``: another scene, or a
    goal node whose principal contacts are not the program's goal."""
    net = nprog.network
    if program.scene and net.scene_name and program.scene != net.scene_name:
        raise ProgramError(
            f"network program {nprog.name or '-'}: made in scene {net.scene_name}, "
            f"the program in {program.scene}"
        )
    goal = tuple(sorted(net.node(net.goal).principal))
    if goal != tuple(program.goal):
        raise ProgramError(
            f"network program {nprog.name or '-'}: its goal {net.goal} ({' + '.join(goal) or 'N'}) is not "
            f"the program's ({' + '.join(program.goal) or 'N'})"
        )


def sensed_node(
    nprog: NetworkProgram, vector: Any, position: Any, tolerance: float | None,
    among: set[str] | None = None,
) -> Successor | None:
    """The node of ``nprog`` the sensed contact ``vector`` (world; None or zero: no contact) shows,
    with the gripper at ``position`` (m, world): among the nodes other than the goal that have a
    demonstrated path to the goal from there: those in ``among`` (:func:`unconfirmed_nodes`), else
    those the demonstrations were in near ``position`` (:func:`near_nodes`), the nearest expected
    vector (ties: more visits, then the smaller id); None when none is within ``tolerance`` (a
    situation outside the network)."""
    net = nprog.network
    nodes = [n for n in net.nodes if n.id != net.goal and (among is None or n.id in among)
             and nprog.replan(n.id, position) is not None]
    if among is None:  # past bets nothing sensed, the gripper is where the demonstration was, not the run
        nodes = near_nodes(nprog, nodes, position)
    total = sum(n.visits for n in nodes) or 1
    cands = [Successor(n.id, n.situation, n.principal, expected_vector(n), n.visits / total) for n in nodes]
    return identify(cands, vector, tolerance)


def unconfirmed_nodes(nprog: NetworkProgram, out: Execution) -> set[str] | None:
    """Where the run may be, by what it sensed: the network nodes of the situation its last macro
    that ended by a detection led to and of those the macros it ran after it aimed at (they ended
    by their motion, bets that nothing sensed, or failed); None when no macro ended by a
    detection, or the network has none of those situations."""
    done = [r for r in out.runs if r.ended == "detected"]
    if not done:
        return None
    ran = {r.macro.index for r in out.runs}
    macros = [m for m in out.program.macros if m.index >= done[-1].macro.index and m.index in ran]
    found = {nprog.network.locate(m.to_situation) for m in macros}
    found.discard(None)
    return {str(n) for n in found} or None


def confirmed_node(nprog: NetworkProgram, out: Execution, position: Any) -> Successor | None:
    """The network node of the situation the program's last detection confirmed (probability 1), when
    it has a demonstrated path to the goal from ``position`` (m, world); else None. After
    :func:`retrace` the gripper is back where that detection left it: dragging back rubs the cable
    against what it touches (the force then tells less than the detection did)."""
    done = [r for r in out.runs if r.ended == "detected"]
    nid = nprog.network.locate(done[-1].macro.to_situation) if done else None
    if nid is None or nid == nprog.network.goal or nprog.replan(nid, position) is None:
        return None
    n = nprog.network.node(nid)
    return Successor(n.id, n.situation, n.principal, expected_vector(n), 1.0)


def near_nodes(nprog: NetworkProgram, nodes: list[Any], position: Any) -> list[Any]:
    """Those of ``nodes`` the demonstrations entered near ``position`` (m, world), by the rule the
    planner picks departures by (:meth:`dlovr.model.planning.NetworkProgram.applicable`): a node's
    distance is the least :func:`dlovr.model.planning.departure_distance` over its out-edges; kept
    are those within the planner's ``reach`` of the nearest. Many situations push the gripper alike
    (a tip resting on any top face senses ``-z``); where the gripper is tells them apart. All of them
    where ``position`` is None."""
    if position is None or not nodes:
        return nodes

    def dist(n: Any) -> float:
        return min((departure_distance(e, position) for e in nprog.network.out_edges(n.id)), default=math.inf)

    d = {n.id: dist(n) for n in nodes}
    limit = min(d.values()) + nprog.reach
    return [n for n in nodes if d[n.id] <= limit]


def recovering_steps(
    program: Program, ses: Session, out: Execution, track: DemoTrack | None, recovery: Recovery, scene: Any
) -> Steps[None]:
    """The steps of ``program`` (:func:`dlovr.execution.executor.program_steps`), then the recovery
    of the module docstring; the attempts land in ``out.replans``."""
    from dlovr.sim import SimulationDiverged

    commanded: list[Pose] = []
    yield from commanded_poses(program_steps(program, ses, out, track), ses.sim, commanded, changed_only=True)
    if out.diverged is not None or not program.goal:
        return
    try:
        if out.runs and out.runs[-1].ended not in ENDED_OK:  # stopped at a macro: what was reached?
            yield from final_hold(ses, out, track)
        while out.goal_sensed is False and len(out.replans) < recovery.max_replans:
            back = 0.0
            if not out.replans and recovery.retrace:
                back = yield from retrace(ses, out, commanded)
            attempt = yield from _replan(ses, out, track, recovery, scene, back > 0.0)
            out.replans.append(attempt)
            if not attempt.node:
                break
    except SimulationDiverged as e:
        out.diverged = str(e)
        ses.emit("failed", 0, f"simulation diverged while planning again: {e.reason}")
    sim = ses.sim
    out.kept = list(sim.tracker.kept) if sim.tracker is not None else []
    out.sim_time = float(sim.time)


def retrace(ses: Session, out: Execution, commanded: list[Pose]) -> Steps[float]:
    """Go back along the commanded motion, at its own pace, to where the program's last detection
    left the gripper, when macros ran after it: they ended by their motion (bets nothing sensed) or
    failed, so the gripper is where the demonstration's went, not where the cable is; from the last
    detection the network loop repeats their motions and searches on where one ended short of its
    transition. Then hold :data:`RETRACE_SETTLE_S`. Returns how long (s) the motion back took (0: not
    gone back)."""
    done = [r for r in out.runs if r.ended == "detected"]
    if not done or done[-1] is out.runs[-1] or not commanded:
        return 0.0
    since = done[-1].ended_at  # from the pose commanded as it ended (its take-back included) on
    first = max((i for i, c in enumerate(commanded) if c[0] <= since + 1e-9), default=0)
    back = commanded[first:]
    if len(back) < 2:
        return 0.0
    n = len(out.runs) - out.runs.index(done[-1]) - 1
    ses.emit("retrace", 0, f"going back along the {n} macros after the last detection (macro "
             f"{done[-1].macro.index}, {back[-1][0] - back[0][0]:.2f} s of motion)")
    for (t1, _, _), (t0, pos, quat) in zip(back[::-1], back[-2::-1], strict=False):
        yield from ses.hold(pos, quat, max(t1 - t0, ses.dt))  # at least one step
    yield from ses.hold(back[0][1], back[0][2], RETRACE_SETTLE_S)
    return back[-1][0] - back[0][0]


def _replan(
    ses: Session, out: Execution, track: DemoTrack | None, recovery: Recovery, scene: Any,
    retraced: bool = False,
) -> Steps[Replan]:
    """One attempt: identify the sensed situation (after a :func:`retrace`: the force sensed now), run
    the network loop from it, hold, check."""
    sim, nopts, t0 = ses.sim, recovery.options, float(ses.sim.time)
    weight = ses.weight()
    tare = weight if weight is not None else np.zeros(3)
    force = out.goal_force if out.goal_force is not None and not retraced else ses.f
    v = sensed_contact_vector(force, tare, nopts.free_force)
    sv = rounded_vector(v)
    pos = tuple(float(x) for x in sim.data.mocap_pos[sim.built.mocap_id])
    among = unconfirmed_nodes(recovery.network, out) if not out.replans else None
    found = confirmed_node(recovery.network, out, pos) if retraced else None
    found = found or sensed_node(recovery.network, v, pos, nopts.tolerance, among)
    if found is None:
        why = (f"the sensed contact vector {list(sv) if sv else 'none (free space)'} fits no situation of "
               "the network with a path to the goal: not planning again")
        ses.emit("outside", 0, why)
        return Replan("", "", sv, (), False, why, out.goal_sensed, out.goal_angle, t0, float(sim.time))
    how = "back where the last detection confirmed" if retraced and found.probability == 1.0 else "sensed"
    what = f"the goal check did not confirm the goal; {how} {found.node} ({found.situation})"
    ses.emit("replan", 0, f"{what}: planning again through the network")
    res, arrived = yield from network_steps_from(recovery.network, ses, scene, nopts, found.node)
    yield from final_hold(ses, out, track)
    return Replan(found.node, found.situation, sv, res.path, arrived, res.reason, out.goal_sensed,
                  out.goal_angle, t0, float(sim.time))
