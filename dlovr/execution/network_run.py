"""Executing a network program (``dlovr compile --network``): sense the situation reached after each
detected transition and plan again from there (paper §VI, §VII; docs/networks.md).

The loop, from the network's start node and the scene's gripper position:

1. :meth:`dlovr.model.planning.NetworkProgram.replan` at the current node and gripper position gives
   the macro toward the goal (its network edges, classes, summed mean displacement and rotation) and
   the nodes its transition may lead to (successors with their expected contact vectors);
2. the macro runs as a guarded motion like a compiled program's (:mod:`dlovr.execution.executor`):
   from where the gripper is, along its edges' own demonstrated tracks joined one after the other
   (:func:`plan_track`; each edge keeps the reference demonstration's track where that took it, see
   :mod:`dlovr.model.network`), ended by the detectors of its classes (or, with
   ``detect="oracle"``, by the contact tracker), failed at its allowance; the tip's first touch
   tells where the tip is, as for a compiled program;
3. after the detection the gripper holds still ``sense_settle`` s where the detector fired, and the
   **sensed contact vector**
   is taken from the wrench: the sensed force minus the force sensed in free space (the cable's
   weight ``-m g`` along z, known from the scene as a robot knows its payload; the first samples of
   a run are not settled enough to tare on), negated and normalised -- a contact that begins adds
   about ``-v * F`` to the sensed force (:mod:`dlovr.model.detection`), so the environment's share
   is ``-v`` times its size; below ``free_force`` N, or half the detection threshold that fired when
   that is smaller, it is no contact (the zero vector). :func:`dlovr.model.planning.identify` picks
   the successor whose expected vector (the one its demonstrations sensed, else the sum of its
   principal contacts') is closest; farther than ``tolerance`` from every one is **a situation
   outside the network**: the run stops with a report of the sensed vector and the expected ones.
   Then, along the reference's track, the detection is **taken back by its latency** as a compiled
   program's is: the gripper goes back to where it was as long before the detection as the same
   detectors fire late on the reference demonstration's own recorded wrench
   (:func:`reference_wrench`; ``dlovr.execution.executor.detection_lag``), and the next macro
   resumes the track from there (without it the first touch's ~40 ms is read as a longer cable).
   With the oracle the node is the one whose principal contacts the tracker sees. A macro that ended
   by its motion (its transition shows the force no step) is taken to reach its planned target, as
   in a compiled program, unless its transition is spontaneous (``S``: where it landed is sensed)
   or an instable one the plan takes where the reference took another (its macro follows the
   reference's motion through that one, :func:`borrows_motion`: where it landed is sensed);
4. from the identified node the planner chooses again (``replan`` event when it is not the node
   the previous plan expected); the goal node ends the run, a node with no demonstrated path to the
   goal stops it.

Node-level vectors only: a macro's detectors expect the target node's geometric vector (the
normalised sum of its principal contacts' vectors) for the contacts that begin and the source node's
for those that end, with the detection parameters the network derived for its last edge. The run is
judged by the tracker (never read by the loop in force mode): the goal is reached when the last
debounced situation has the goal node's principal contacts.
"""

from __future__ import annotations

import math
import time
from collections import deque
from collections.abc import Generator
from dataclasses import asdict, dataclass
from typing import Any, TypeVar

import numpy as np

from dlovr.execution.demo_track import DemoTrack, load_track
from dlovr.execution.executor import (
    ENDED_OK,
    GRAVITY,
    START_TOL_M,
    MacroRun,
    Session,
    Steps,
    principal_states,
    run_final,
    run_macro,
)
from dlovr.model.detection import THRESHOLD_PARAM
from dlovr.model.network import SENSE_HOLD_S
from dlovr.model.planning import Choice, MacroPlan, NetworkProgram, Successor, expected_vector, identify
from dlovr.model.program import ContactSpec, Detection, Macro, Motion, PoseTrack, ProgramError, risk
from dlovr.model.tracks import join
from dlovr.transforms import matrix_to_rotvec, quat_rotate, quat_to_matrix, unit


@dataclass(frozen=True)
class NetworkOptions:
    """How a network program is executed beyond :class:`ExecOptions`: ``tolerance`` (Euclidean
    distance between unit vectors) for :func:`dlovr.model.planning.identify`; ``sense_settle`` (s)
    held still before sensing; ``free_force`` (N): a contact force below it is no contact;
    ``max_macros``: the run stops after that many macros; ``tracks``: macros follow their edges' own
    demonstrated tracks (:func:`plan_track`) where the network has them, else the mean motions;
    ``blind_motion``: a macro that ended by its motion (its transition shows no force signal) is taken
    to have reached its planned target, as in a compiled program, instead of being identified (a
    spontaneous one, ``S``, and an instable one along the reference's motion through another
    transition, :func:`borrows_motion`, are identified all the same);
    ``sigma``: identification weighs each successor's probability by how well its vector fits
    (:func:`dlovr.model.planning.identify`; None: the nearest vector alone); ``take_back``: along the
    reference's track, a detection is taken back by how late the same detectors fire on the reference
    demonstration's own recorded wrench (:func:`reference_wrench`), as a compiled program's is
    (``dlovr.execution.executor.detection_lag``), once the contact has been sensed at the pose where it
    was detected (:meth:`_NetworkRun._sense`); ``search`` (m): a macro that ended by its motion while
    the sensed vector still shows the situation it left goes on along its last motion up to this
    far, sensing, until the situation changes (:meth:`_NetworkRun._search`; 0: never, as network
    runs; a compiled program's recovery searches :data:`SEARCH_M`)."""

    tolerance: float = 0.8
    sense_settle: float = SENSE_HOLD_S
    free_force: float = 0.05
    max_macros: int = 50
    tracks: bool = True
    blind_motion: bool = True
    sigma: float | None = 0.25
    take_back: bool = True
    search: float = 0.0


#: How far (m) a recovery's network loop searches on along a macro's last motion
#: (:meth:`_NetworkRun._search`).
SEARCH_M = 0.02
#: Over how much of its end (s of commanded motion) a macro's last direction and speed are taken.
SEARCH_BASE_S = 0.1
#: The fastest (m/s) a search goes on: a macro's end faster than this (a fast lowering) is searched on
#: at this speed, slow enough to feel what it reaches.
SEARCH_SPEED = 0.03
#: How long (s) the sensed vector must show another situation than the one left for a search to stop.
SEARCH_CONFIRM_S = 0.02
#: How far apart (distance of unit vectors) the expected vectors of the situation left and of the
#: planned target must be for a search to tell them apart (nearer: the search cannot sense the target).
SEARCH_CONTRAST = 0.2


@dataclass(frozen=True)
class NetMacro:
    """One macro of a network run: from ``node`` toward ``expected`` (the plan's target) along the
    network ``edges``; ``ended`` as :class:`dlovr.execution.executor.MacroRun`; ``sensed``: the sensed
    contact vector (world, unit or zero; None before sensing); ``identified``: the node it chose
    (None: outside the network); ``true_node``: the node with the tracker's principal contacts then
    (``?`` when none has them)."""

    index: int
    node: str
    expected: str
    classes: tuple[str, ...]
    edges: tuple[str, ...]
    started_at: float
    ended_at: float
    ended: str
    sensed: tuple[float, float, float] | None
    identified: str | None
    true_node: str
    true_principals: tuple[str, ...]
    reason: str = ""
    #: how long (s) before its detection the transition was taken to have come: the gripper went back
    #: to where it was then after sensing (0: not taken back)
    taken_back: float = 0.0
    #: how far (m) it searched on along its last motion before sensing (:meth:`_NetworkRun._search`)
    searched: float = 0.0


@dataclass(frozen=True)
class NetworkRunResult:
    """A judged network run: ``success`` when the loop arrived at the goal node and the tracker's
    last situation has the goal's principal contacts; ``path`` the identified nodes in order."""

    program: str
    scene: str
    detect: str
    success: bool
    goal_reached: bool
    goal: str
    goal_principals: tuple[str, ...]
    final_principals: tuple[str, ...]
    reason: str
    path: tuple[str, ...]
    replans: int
    macros: tuple[NetMacro, ...]
    sim_time: float
    wall_time: float

    def to_json(self) -> dict[str, Any]:
        d = asdict(self)
        d["kind"] = "network-run"
        return d


def plan_track(nprog: NetworkProgram, plan: MacroPlan) -> DemoTrack | None:
    """The macro's motion as one recorded track: its edges' own demonstrated tracks one after the
    other (:func:`dlovr.model.tracks.join`); None when an edge has none (a network of recordings
    without commands), and the macro moves along the summed mean displacement instead."""
    by_id = {e.id: e for e in nprog.network.edges}
    tracks = [t for i in plan.edges if (t := by_id[i].track) is not None]
    if not tracks or len(tracks) != len(plan.edges):
        return None
    pt = join(tracks)
    return DemoTrack(pt.t, pt.pos, pt.quat)


def _reference_steps(net: Any) -> list[tuple[float, float, Any]]:
    """The reference demonstration's transitions in time order: (entry into the source, entry into
    the target, edge), s on its own clock."""
    ref = net.reference
    steps = [
        (e.track.t0, e.track.t0 + float(e.track.t[-1]), e)
        for e in net.edges
        if ref is not None and e.track is not None and e.track.demonstration == ref.demonstration
    ]
    return sorted(steps, key=lambda x: x[0])


def reference_span(nprog: NetworkProgram, plan: MacroPlan, node: str) -> tuple[float, float] | None:
    """Where the macro lies in the reference demonstration (start and end, s, its own clock), or
    None: from the reference's latest entry into ``node`` to its entry into the macro's target, when
    the macro's last (classed) edge is the reference's own (the unclassed steps between are not
    chosen, as in a compiled program); or, when the macro's transition is spontaneous or instable
    (``S``, ``I``: the motion does not choose where it leads) and so was the reference's next one
    from ``node``, to the reference's entry into that transition's target."""
    net = nprog.network
    if net.reference is None or not plan.edges:
        return None
    steps = _reference_steps(net)
    last = next((x for x in steps if x[2].id == plan.edges[-1]), None)
    entries = [t0 for t0, _, e in steps if e.source == node and (last is None or t0 <= last[0] + 1e-9)]
    if not entries:
        return None
    start = max(entries) if last is not None else min(entries)
    if last is not None:
        return start, last[1]
    if not {"S", "I"} & set(plan.classes):
        return None
    nxt = next((x for x in steps if x[0] >= start - 1e-9 and x[2].classes), None)
    return (start, nxt[1]) if nxt is not None and {"S", "I"} & set(nxt[2].classes) else None


def borrows_motion(nprog: NetworkProgram, plan: MacroPlan, node: str) -> bool:
    """Whether the macro from ``node`` moves along the reference's motion through another transition
    than its own: an ``S`` or ``I`` macro whose last edge the reference never took there
    (:func:`reference_span`). Such a macro's end by its motion tells nothing of where the DLO went
    (most likely where the reference's own transition led), so the run senses it instead of taking
    the planned target."""
    if not {"S", "I"} & set(plan.classes) or not plan.edges:
        return False
    own = {e.id for _, _, e in _reference_steps(nprog.network)}
    return plan.edges[-1] not in own and reference_span(nprog, plan, node) is not None


def reference_goal_entry(nprog: NetworkProgram) -> float | None:
    """When the reference demonstration entered the goal (s, its own clock), or None."""
    net = nprog.network
    at = [t1 for _, t1, e in _reference_steps(net) if e.target == net.goal]
    return max(at) if at else None


def reference_track(nprog: NetworkProgram, wrench: Any = None) -> DemoTrack | None:
    """The reference demonstration's whole commanded track on its own clock (s), or None; with the
    ``wrench`` it sensed (:func:`reference_wrench`), if given."""
    ref = nprog.network.reference
    return None if ref is None else DemoTrack(ref.t0 + ref.t, ref.pos, ref.quat, wrench=wrench)


#: How far (m) the commanded track of the recording a network names as its reference demonstration
#: may lie from the reference track the network keeps (resampled at 10 ms, :mod:`dlovr.model.tracks`:
#: 0.7 mm on peg_in_hole) for its wrench to be taken as the reference's (:func:`reference_wrench`).
REFERENCE_MATCH_M = 0.002

_WRENCHES: dict[tuple[str, int, int], Any] = {}


def reference_wrench(nprog: NetworkProgram) -> Any:
    """The wrench the reference demonstration sensed (``dlovr.model.derivation.WrenchSeries``), read
    from the recording the network names for it (its path as the network lists it: absolute, or
    relative to the working directory), or None: not found, no wrench channel, unreadable, or its
    commanded track farther than :data:`REFERENCE_MATCH_M` from the network's reference track (another
    recording under that name). Read once per file and process."""
    from pathlib import Path

    net, ref = nprog.network, nprog.network.reference
    if ref is None or not 0 <= ref.demonstration < len(net.demonstrations):
        return None
    path = Path(net.demonstrations[ref.demonstration])
    try:
        st = path.stat()
    except OSError:
        return None
    key = (str(path.resolve()), st.st_mtime_ns, st.st_size)
    if key not in _WRENCHES:
        _WRENCHES[key] = _matching_wrench(ref, path)
    return _WRENCHES[key]


def _matching_wrench(ref: Any, path: Any) -> Any:
    """The wrench recorded in ``path`` where its commanded track is the reference track ``ref``
    (within :data:`REFERENCE_MATCH_M` at the reference's times, over the same span), else None."""
    from dlovr.recording import RecordingError

    try:
        track = load_track(path)
    except (RecordingError, OSError, ValueError):
        return None
    t, pos, wrench = track.t, track.pos, track.wrench
    rt = ref.t0 + np.asarray(ref.t, float)
    if wrench is None or len(t) < 2 or max(abs(t[0] - rt[0]), abs(t[-1] - rt[-1])) > 0.05:
        return None
    at = np.stack([np.interp(rt, t, pos[:, i]) for i in range(3)], axis=1)
    return wrench if float(np.abs(at - np.asarray(ref.pos, float)).max()) <= REFERENCE_MATCH_M else None


@dataclass(frozen=True)
class _Final:
    """The plan of the motion after the goal is reached along the reference (no edges, no detection)."""

    edges: tuple[str, ...] = ()
    classes: tuple[str, ...] = ()
    target: str = ""
    final: bool = True
    world: tuple[float, float, float] = (0.0, 0.0, 0.0)
    rotation: tuple[float, float, float] = (0.0, 0.0, 0.0)
    duration: float = 0.0
    detection: tuple[Any, ...] = ()


def _macro_spec(
    index: int,
    nprog: NetworkProgram,
    node: str,
    plan: MacroPlan | _Final,
    sim: Any,
    track: DemoTrack | None = None,
    span: tuple[float, float] | None = None,
) -> Macro:
    """The executor's macro for a network macro plan, starting at the gripper's pose now (with
    ``track``: its motion is that track's between the times ``span``, s, or all of it)."""
    net = nprog.network
    src, dst = net.node(node), net.node(plan.target)
    mid = sim.built.mocap_id
    here = tuple(float(x) for x in sim.data.mocap_pos[mid])
    q = tuple(float(x) for x in sim.data.mocap_quat[mid])
    inv = np.array([q[0], -q[1], -q[2], -q[3]])
    world, rot, duration = tuple(plan.world), tuple(plan.rotation), float(plan.duration)
    t_end = 0.0
    if track is not None:
        t0, t_end = span if span is not None else (0.0, float(track.t[-1]))
        poses = PoseTrack(track.t, track.pos, track.quat)
        (p0, q0), (p1, q1) = poses.at(t0), poses.at(t_end)
        world = tuple(float(x) for x in p1 - p0)
        rot = tuple(float(x) for x in matrix_to_rotvec(quat_to_matrix(q0).T @ quat_to_matrix(q1)))
        duration = t_end - t0
    rel = quat_rotate(inv, np.asarray(world, float))
    motion = Motion(_v3(world), _v3(rel), _v3(rot), duration, _v3(here), (q[0], q[1], q[2], q[3]))
    derived = {d.cls: d for d in plan.detection}  # the network's parameters; the defaults without
    det = tuple(
        Detection(c, derived[c].algorithm, dict(derived[c].params)) if c in derived else Detection(c, "", {})
        for c in plan.classes
    )
    return Macro(
        index=index,
        kind="final" if plan.final else "transition",
        classes=tuple(plan.classes),
        t=t_end,
        from_situation=src.situation,
        to_situation=dst.situation,
        changes=(),
        from_contacts=_contacts(src),
        to_contacts=_contacts(dst),
        motion=motion,
        detection=det,
        risk=risk(plan.classes),
        frame="world",
    )


def _v3(v: Any) -> tuple[float, float, float]:
    return (float(v[0]), float(v[1]), float(v[2]))


def _contacts(n: Any) -> tuple[ContactSpec, ...]:
    """A node's principal contacts, each with the node's vector (None when it is zero)."""
    v = None if n.vector is None or math.sqrt(sum(x * x for x in n.vector)) < 1e-9 else _v3(n.vector)
    return tuple(ContactSpec(s, v) for s in n.principal)


def _free_force(m: Macro, free_force: float) -> float:
    """Below what contact force (N) the sensed vector is free space after macro ``m``: ``free_force``,
    or half the smallest threshold its detectors fired at (a detection at a smaller force than
    ``free_force`` is a contact of that size, not free space)."""
    keys = [(d, THRESHOLD_PARAM.get(d.cls)) for d in m.detection]
    thr = [float(d.params[k]) for d, k in keys if k in d.params]
    return min([free_force, *(0.5 * t for t in thr if t > 0.0)])


def _hold_target(ses: Session, seconds: float) -> Steps[None]:
    """Hold the commanded pose ``seconds``: the gripper, which lags its target at speed, catches up
    (holding where it is instead would drop the motion still under way)."""
    sim = ses.sim
    yield from ses.hold(
        np.array(sim.target_pos, dtype=float), np.array(sim.target_quat, dtype=float), seconds
    )


def _true_node(nprog: NetworkProgram, sim: Any) -> tuple[str, tuple[str, ...]]:
    cur = sim.tracker.current
    have = principal_states(cur.discrete) if cur is not None else ()
    for n in nprog.network.nodes:
        if tuple(sorted(n.principal)) == have:
            return n.id, have
    return "?", have


def rounded_vector(v: np.ndarray | None) -> tuple[float, float, float] | None:
    """A sensed vector for the report: 4 decimals, no -0.0."""
    return None if v is None else _v3([round(float(x), 4) + 0.0 for x in v])


class _NetworkRun:
    """A network program's run in progress (the loop of the module docstring) and what it found."""

    def __init__(
        self, nprog: NetworkProgram, ses: Session, scene: Any, nopts: NetworkOptions, *,
        start: str | None = None, settle: bool = True,
    ):
        """``start``: the node the loop starts from (default the network's start; a compiled
        program's recovery starts where it sensed it is, :mod:`dlovr.execution.recovery`);
        ``settle``: hold ``final_settle`` s after the goal (the recovery's caller holds itself)."""
        self.nprog, self.ses, self.scene, self.nopts = nprog, ses, scene, nopts
        self.net = nprog.network
        first = self.net.start if start is None else start
        self.node, self.path, self.replans = first, [first], 0
        self.settle = settle
        self.macros: list[NetMacro] = []
        self.tare = np.array([0.0, 0.0, -float(scene.dlo.mass) * GRAVITY])  # the cable's weight
        wrench = reference_wrench(nprog) if nopts.take_back else None
        self.ref_track = reference_track(nprog, wrench)
        # a detection taken back: sensed where it fired, then back (:meth:`_sense`)
        ses.sense_before_back, ses.back = True, None
        self.resume: float | None = None
        self.last_end: float | None = None  # where the last macro ended on the reference's clock (s)
        self.reason, self.arrived = "", False
        #: the commanded gripper poses of the macro's last :data:`SEARCH_BASE_S` (:data:`Pose`)
        self.commanded: deque[Pose] = deque(
            maxlen=max(2, round(SEARCH_BASE_S / ses.dt) + 1)
        )

    def steps(self) -> Steps[None]:
        """Macros until the goal, a failure or ``max_macros``; then the motion after the goal."""
        from dlovr.sim import SimulationDiverged

        net, ses = self.net, self.ses
        head = f"network program {self.nprog.name}: start {self.node}, goal {net.goal}"
        ses.emit("start", 0, f"{head}, detection {ses.opts.detect}")
        try:
            while len(self.macros) < self.nopts.max_macros:
                if self.node == net.goal:
                    self.arrived = True
                    break
                if not (yield from self._macro()):
                    break
            else:
                self.reason = f"stopped after {self.nopts.max_macros} macros without reaching the goal"
                ses.emit("failed", 0, self.reason)
            if self.arrived or self.node == net.goal:
                self.arrived = True
                yield from self._after_goal()
        except SimulationDiverged as e:
            self.reason = f"simulation diverged: {e}"
            ses.emit("failed", 0, self.reason)

    def _macro(self) -> Steps[bool]:
        """Plan at the node reached and run that macro; whether the loop goes on."""
        ses, sim, node = self.ses, self.ses.sim, self.node
        pos = tuple(float(x) for x in sim.data.mocap_pos[sim.built.mocap_id])
        choice = self.nprog.replan(node, pos)
        if choice is None:
            where = f"{node} ({self.net.node(node).situation})"
            self.reason = f"no demonstrated path from {where} to the goal {self.net.goal}"
            ses.emit("failed", 0, self.reason)
            return False
        plan, k = choice.macro, len(self.macros) + 1
        span = reference_span(self.nprog, plan, node) if self.nopts.tracks else None
        if span is not None:  # along the reference demonstration: its own track, as a program
            track = self.ref_track
        else:
            track, self.resume = (plan_track(self.nprog, plan) if self.nopts.tracks else None), None
        m = _macro_spec(k, self.nprog, node, plan, sim, track, span)
        ses.emit(
            "plan",
            k,
            f"at {node}: edges {' '.join(plan.edges)} toward {plan.target}, "
            f"P(goal)={choice.reach_probability:.3f}",
        )
        t0 = float(sim.time)
        if plan.final:
            yield from run_final(m, ses, track)
            self.node = plan.target
            self._log(k, choice, t0, float(sim.time), "final", None, self.node, classes=())
            self.path.append(self.node)
            return True
        self.commanded.clear()
        run = yield from commanded_poses(run_macro(m, ses, track, t_from=self.resume), sim, self.commanded)
        self.resume = run.resume_at if span is not None else None
        self.last_end = None if span is None else (self.resume if self.resume is not None else span[1])
        if run.ended not in ENDED_OK:
            self._log(k, choice, t0, run.ended_at, run.ended, None, None, reason=run.reason)
            self.reason = f"macro {k} ({','.join(plan.classes)}, {node} -> {plan.target}): {run.reason}"
            return False
        return (yield from self._sense(k, choice, m, run, t0))

    def _sense(self, k: int, choice: Choice, m: Macro, run: MacroRun, t0: float) -> Steps[bool]:
        """Hold still, sense the contact vector and identify the node reached; whether it is one."""
        ses = self.ses
        yield from _hold_target(ses, self.nopts.sense_settle)
        tn, _ = _true_node(self.nprog, ses.sim)
        sensed = sensed_contact_vector(ses.f, self.tare, _free_force(m, self.nopts.free_force))
        back, ses.back = ses.back, None
        if back is not None:  # the detection taken back by its latency, now that it has been sensed
            ses.sim.set_target(back[0], back[1])
        searched = 0.0
        if run.ended == "motion" and self._unconfirmed(choice, sensed, m):
            searched, _ = yield from self._search(k, choice, m)
            tn, _ = _true_node(self.nprog, ses.sim)
            sensed = sensed_contact_vector(ses.f, self.tare, _free_force(m, self.nopts.free_force))
        found = self._identify(choice, run, sensed, tn)
        sv = rounded_vector(sensed)
        if found is None:
            self._outside(k, choice, run, sv, t0)
            return False
        lag = 0.0 if back is None else back[2]
        self._log(k, choice, t0, run.ended_at, run.ended, sv, found.node, back=lag, searched=searched)
        plan = choice.macro
        if found.node != plan.target:
            self.replans += 1
            what = f"reached {found.node} ({found.situation}), not {plan.target}: planning again"
            self.ses.emit("replan", k, what)
        self.node = found.node
        self.path.append(self.node)
        return True

    def _stay(self, choice: Choice) -> Successor:
        """The situation the macro left, as a successor (probability 0): it did not move on."""
        n = self.net.node(choice.node)
        return Successor(n.id, n.situation, n.principal, expected_vector(n), 0.0)

    def _unconfirmed(self, choice: Choice, sensed: np.ndarray | None, m: Macro) -> bool:
        """Whether a macro that ended by its motion should search on (:meth:`_search`): searching is
        on, the sensed vector is nearer the situation it left than any successor's, and the planned
        target's expected vector is at least :data:`SEARCH_CONTRAST` from the left one's."""
        if self.nopts.search <= 0.0 or self.ses.opts.detect == "oracle" or choice.macro.final:
            return False
        stay = self._stay(choice)
        target = next((c for c in choice.successors if c.node == choice.macro.target), None)
        if stay.vector is None or target is None or target.vector is None:
            return False
        if math.dist(stay.vector, target.vector) < SEARCH_CONTRAST:
            return False
        where = identify([stay, *choice.successors], sensed, self.nopts.tolerance)
        return where is not None and where.node == stay.node

    def _search(self, k: int, choice: Choice, m: Macro) -> Steps[tuple[float, bool]]:
        """Go on along the macro's last motion (its commanded direction and speed over its last
        :data:`SEARCH_BASE_S`, at most :data:`SEARCH_SPEED`, the orientation held) up to ``search`` m,
        sensing at every step, until
        for :data:`SEARCH_CONFIRM_S` the sensed vector no longer fits the left situation best (another
        successor's fits better, or none within ``tolerance``: a contact no demonstration sensed
        there, as the tip at the groove's end); then hold ``sense_settle`` s. That change is the
        transition the macro searched for, as a detector's firing is: the loop then takes the planned
        target as it does after a motion (a spontaneous transition's outcome is sensed). A motion
        that ended short of its transition (objects farther than demonstrated, the groove's end
        beyond the drag) so reaches it, where the transition shows no force step to detect. Returns
        how far it went (m; 0 when the macro's end stood still) and whether the situation changed."""
        ses, sim, nopts = self.ses, self.ses.sim, self.nopts
        hist = list(self.commanded)
        if len(hist) < 2 or hist[-1][0] - hist[0][0] <= 0.0:
            return 0.0, False
        d = hist[-1][1] - hist[0][1]
        speed = float(np.linalg.norm(d)) / (hist[-1][0] - hist[0][0])
        if speed < 1e-3:  # (1 mm/s) nothing to go on along
            return 0.0, False
        direction, free = d / np.linalg.norm(d), _free_force(m, nopts.free_force)
        speed = min(speed, SEARCH_SPEED)
        start, quat = np.array(sim.target_pos, dtype=float), np.array(sim.target_quat, dtype=float)
        stay = self._stay(choice)
        cands = [stay, *choice.successors]
        ses.emit("search", k, f"macro {k}: still sensed at {stay.node}, not {choice.macro.target}: going on "
                 f"along its last motion ({speed * 1000:.0f} mm/s) up to {nopts.search * 1000:.0f} mm")
        step, moved, other = speed * ses.dt, 0.0, 0.0
        while moved + step <= nopts.search + 1e-12 and other < SEARCH_CONFIRM_S - 1e-12:
            moved += step
            ses.step(start + moved * direction, quat)
            yield
            v = sensed_contact_vector(ses.f, self.tare, free)
            where = identify(cands, v, nopts.tolerance)
            other = other + ses.dt if where is None or where.node != stay.node else 0.0
        found = other >= SEARCH_CONFIRM_S - 1e-12
        ses.emit("search", k, f"macro {k}: {'the situation changed' if found else 'nothing changed'} "
                 f"after {moved * 1000:.1f} mm")
        yield from _hold_target(ses, nopts.sense_settle)
        return moved, found

    def _identify(
        self, choice: Choice, run: MacroRun, sensed: np.ndarray | None, true_node: str
    ) -> Successor | None:
        """The successor reached: the tracker's (oracle), the planned one (a macro ended by its motion,
        not a spontaneous one; searched on or not), or the one whose vector fits the sensed one."""
        plan, nopts = choice.macro, self.nopts
        if self.ses.opts.detect == "oracle":
            return next((s for s in choice.successors if s.node == true_node), None)
        borrowed = nopts.tracks and borrows_motion(self.nprog, plan, choice.node)
        if run.ended == "motion" and nopts.blind_motion and "S" not in plan.classes and not borrowed:
            # a transition without force signal gives the wrench nothing to tell: as a compiled
            # program does, take the demonstrated motion to have made the planned transition
            # (not a spontaneous one, whose outcome the motion does not choose, nor an instable one
            # run along the reference's motion through another transition: where the DLO
            # landed is sensed)
            return next((s for s in choice.successors if s.node == plan.target), None)
        return identify(choice.successors, sensed, nopts.tolerance, nopts.sigma)

    def _outside(
        self, k: int, choice: Choice, run: MacroRun, sv: tuple[float, float, float] | None, t0: float
    ) -> None:
        _, tp = _true_node(self.nprog, self.ses.sim)
        exp = ", ".join(
            f"{s.node} {list(s.vector) if s.vector is not None else '-'}" for s in choice.successors
        )
        self.reason = (
            f"macro {k}: sensed contact vector {list(sv) if sv else 'none (free space)'} matches "
            f"none of the expected situations ({exp}) within {self.nopts.tolerance:g}: a situation "
            f"outside the network (tracker: {' + '.join(tp) or 'N'})"
        )
        self.ses.emit("outside", k, self.reason)
        self._log(k, choice, t0, run.ended_at, "outside", sv, None, reason=self.reason)

    def _log(
        self,
        k: int,
        choice: Choice,
        t0: float,
        t1: float,
        ended: str,
        sensed: tuple[float, float, float] | None,
        identified: str | None,
        *,
        classes: tuple[str, ...] | None = None,
        reason: str = "",
        back: float = 0.0,
        searched: float = 0.0,
    ) -> None:
        """Append the :class:`NetMacro` of macro ``k`` (with the tracker's node now)."""
        plan: MacroPlan = choice.macro
        tn, tp = _true_node(self.nprog, self.ses.sim)
        self.macros.append(
            NetMacro(
                index=k,
                node=choice.node,
                expected=plan.target,
                classes=plan.classes if classes is None else classes,
                edges=plan.edges,
                started_at=t0,
                ended_at=t1,
                ended=ended,
                sensed=sensed,
                identified=identified,
                true_node=tn,
                true_principals=tp,
                reason=reason,
                taken_back=back,
                searched=searched,
            )
        )

    def _after_goal(self) -> Steps[None]:
        """The reference's motion after it entered the goal, as a program's final macro (from where
        the last macro stopped on its clock when that followed it); then the final hold."""
        since = self.last_end if self.last_end is not None else reference_goal_entry(self.nprog)
        ref = self.ref_track
        if since is not None and ref is not None and float(ref.t[-1]) > since:
            span = (since, float(ref.t[-1]))
            fin = _macro_spec(
                len(self.macros) + 1, self.nprog, self.node, _Final(target=self.node), self.ses.sim, ref, span
            )
            yield from run_final(fin, self.ses, ref)
        if self.settle:
            yield from _hold_target(self.ses, self.ses.opts.final_settle)
        self.ses.emit("end", 0, "network program done")

    def result(self, wall_time: float) -> NetworkRunResult:
        """The judged run: the goal is reached when the tracker's last situation has its principals."""
        net, sim = self.net, self.ses.sim
        kept = list(sim.tracker.kept)
        final = principal_states(kept[-1].situation) if kept else ()
        goal_p = tuple(sorted(net.node(net.goal).principal))
        reached = final == goal_p and not self.reason.startswith("simulation diverged")
        reason = self.reason
        if self.arrived and not reached and not reason:
            reason = f"final situation {final or ('N',)} is not the goal {goal_p or ('N',)}"
        return NetworkRunResult(
            program=self.nprog.name, scene=self.scene.name, detect=self.ses.opts.detect,
            success=self.arrived and reached, goal_reached=reached, goal=net.goal, goal_principals=goal_p,
            final_principals=final, reason=reason, path=tuple(self.path), replans=self.replans,
            macros=tuple(self.macros), sim_time=float(sim.time), wall_time=wall_time,
        )


T = TypeVar("T")

#: Commanded gripper poses in time order: (time s, position m, quaternion wxyz), world frame.
Pose = tuple[float, np.ndarray, np.ndarray]


def commanded_poses(
    gen: Generator[None, None, T], sim: Any, into: deque[Pose] | list[Pose], changed_only: bool = False
) -> Steps[T]:
    """The steps of ``gen``, keeping after each the simulator's time and commanded gripper pose in
    ``into`` (with ``changed_only``: only where the pose changed); its result."""
    try:
        while True:
            next(gen)
            pos, quat = np.array(sim.target_pos, dtype=float), np.array(sim.target_quat, dtype=float)
            same = bool(into) and np.array_equal(pos, into[-1][1]) and np.array_equal(quat, into[-1][2])
            if not (changed_only and same):
                into.append((float(sim.time), pos, quat))
            yield
    except StopIteration as stop:
        return stop.value


def network_steps(
    nprog: NetworkProgram, ses: Session, scene: Any, nopts: NetworkOptions
) -> Steps[NetworkRunResult]:
    """The steps of the network program ``nprog`` in ``ses`` (its simulator at the start pose of
    ``scene``, a ``dlovr.scene.Scene``); see the module docstring. Never raises for a failed run:
    the reason is in the result."""
    wall0 = time.perf_counter()
    run = _NetworkRun(nprog, ses, scene, nopts)
    yield from run.steps()
    return run.result(time.perf_counter() - wall0)


def network_steps_from(
    nprog: NetworkProgram, ses: Session, scene: Any, nopts: NetworkOptions, start: str
) -> Steps[tuple[NetworkRunResult, bool]]:
    """The loop of :func:`network_steps` from the node ``start`` (where the run sensed it is) and
    the gripper's pose now, without the final hold (a compiled program's recovery,
    :mod:`dlovr.execution.recovery`, holds and checks the goal itself); its result and whether the
    loop arrived at the goal node (as far as it sensed)."""
    wall0 = time.perf_counter()
    run = _NetworkRun(nprog, ses, scene, nopts, start=start, settle=False)
    yield from run.steps()
    return run.result(time.perf_counter() - wall0), run.arrived


def failed_start(nprog: NetworkProgram, scene: Any, detect: str, why: str) -> NetworkRunResult:
    """The result of a network run that could not start (``why``)."""
    net = nprog.network
    goal_p = tuple(sorted(net.node(net.goal).principal))
    return NetworkRunResult(
        program=nprog.name, scene=scene.name, detect=detect, success=False, goal_reached=False, goal=net.goal,
        goal_principals=goal_p, final_principals=(), reason=why, path=(), replans=0, macros=(), sim_time=0.0,
        wall_time=0.0,
    )


def format_network_result(res: NetworkRunResult) -> str:
    """The per-macro table and the result line of a network run."""
    lines = [
        f"network program {res.program} in scene {res.scene}, detection {res.detect}",
        f"{'#':>3}  {'from':<5} {'class':<5} {'expected':<8} {'identified':<10} {'true':<5} "
        f"{'ended':>9}  outcome  sensed",
    ]
    for m in res.macros:
        sensed = "-" if m.sensed is None else "[" + ", ".join(f"{x:+.2f}" for x in m.sensed) + "]"
        lines.append(
            f"{m.index:>3}  {m.node:<5} {','.join(m.classes) or '-':<5} {m.expected:<8} "
            f"{m.identified or '-':<10} "
            f"{m.true_node:<5} {m.ended_at:>8.3f}s  {m.ended:<8} {sensed}"
        )
    lines.append(f"path: {' -> '.join(res.path)}; {res.replans} replans")
    if res.success:
        lines.append(f"result: goal reached ({res.goal}: {' + '.join(res.goal_principals) or 'N'})")
    else:
        lines.append(f"result: FAILED: {res.reason}")
    return "\n".join(lines)


def sensed_contact_vector(force: Any, tare: Any, free_force: float) -> np.ndarray | None:
    """The sensed contact vector: ``-(force - tare)`` normalised (world frame); None below
    ``free_force`` N (no contact). See the module docstring for the sign."""
    return unit(-(np.asarray(force, float) - np.asarray(tare, float)), free_force)


def network_scene(nprog: NetworkProgram, scene_ref: str | None) -> Any:
    """The scene to run a network program in: ``scene_ref`` or the network's scene; raises
    :class:`dlovr.model.program.ProgramError` when the scene lacks an object the network's
    contacts name, or ``dlovr.scene.SceneError``."""
    if not (scene_ref or nprog.network.scene_name):
        raise ProgramError(f"network program {nprog.name}: its network names no scene: give --scene")
    from dlovr.geometry.scene_checks import load_checked_scene

    scene = load_checked_scene(scene_ref or nprog.network.scene_name)
    names = {o.name for o in scene.objects}
    used = {
        f.rpartition(".")[0]
        for n in nprog.network.nodes
        for s in n.principal
        if "[" in s
        for f in s[s.index("[") + 1 : s.rindex("]")].split(",")
    }
    missing = sorted(used - names)
    if missing:
        raise ProgramError(
            f"network program {nprog.name}: touches object {missing[0]!r}, which scene {scene.name} does "
            f"not have (a program for another scene?)"
        )
    net = nprog.network
    start = next(p for p in net.starts if p.node == net.start)
    d = math.dist(start.position, scene.gripper.pos)
    if d > START_TOL_M:
        raise ProgramError(
            f"network program {nprog.name}: starts {d * 1000:.0f} mm from scene {scene.name}'s gripper pose "
            f"(a program for another scene?)"
        )
    return scene
