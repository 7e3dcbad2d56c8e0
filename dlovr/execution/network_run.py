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
3. after the detection the gripper holds still ``sense_settle`` s, and the **sensed contact vector**
   is taken from the wrench: the sensed force minus the force sensed in free space (the cable's
   weight ``-m g`` along z, known from the scene as a robot knows its payload; the first samples of
   a run are not settled enough to tare on), negated and normalised -- a contact that begins adds
   about ``-v * F`` to the sensed force (:mod:`dlovr.model.detection`), so the environment's share
   is ``-v`` times its size; below ``free_force`` N, or half the detection threshold that fired when
   that is smaller, it is no contact (the zero vector). :func:`dlovr.model.planning.identify` picks
   the successor whose expected vector (the one its demonstrations sensed, else the sum of its
   principal contacts') is closest; farther than ``tolerance`` from every one is **a situation
   outside the network**: the run stops with a report of the sensed vector and the expected ones.
   With the oracle the node is the one whose principal contacts the tracker sees. A macro that ended
   by its motion (its transition shows the force no step) is taken to reach its planned target, as
   in a compiled program, unless its transition is spontaneous (``S``: where it landed is sensed);
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
from dataclasses import asdict, dataclass
from typing import Any

import numpy as np

from dlovr.execution.executor import (
    ENDED_OK,
    DemoTrack,
    ExecOptions,
    Execution,
    _run_final,
    _run_macro,
    _Session,
    principal_states,
)
from dlovr.execution.programs import ContactVec, DetectionSpec, MacroSpec, MotionSpec, ProgramSpec
from dlovr.model.derivation import THRESHOLD_PARAM
from dlovr.model.program import PoseTrack
from dlovr.model.tracks import join
from dlovr.transforms import matrix_to_rotvec, quat_rotate, quat_to_matrix

#: Gravity (m/s^2) for the cable's weight, the force sensed in free space.
GRAVITY = 9.81


@dataclass(frozen=True)
class NetworkOptions:
    """How a network program is executed beyond :class:`ExecOptions`: ``tolerance`` (Euclidean
    distance between unit vectors) for :func:`dlovr.model.planning.identify`; ``sense_settle`` (s)
    held still before sensing; ``free_force`` (N): a contact force below it is no contact;
    ``max_macros``: the run stops after that many macros; ``tracks``: macros follow their edges' own
    demonstrated tracks (:func:`plan_track`) where the network has them, else the mean motions;
    ``blind_motion``: a macro that ended by its motion (its transition shows no force signal) is taken
    to have reached its planned target, as in a compiled program, instead of being identified (a
    spontaneous one, ``S``, is identified all the same);
    ``sigma``: identification weighs each successor's probability by how well its vector fits
    (:func:`dlovr.model.planning.identify`; None: the nearest vector alone)."""

    tolerance: float = 0.8
    sense_settle: float = 0.05
    free_force: float = 0.05
    max_macros: int = 50
    tracks: bool = True
    blind_motion: bool = True
    sigma: float | None = 0.25


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


def plan_track(nprog: Any, plan: Any) -> DemoTrack | None:
    """The macro's motion as one recorded track: its edges' own demonstrated tracks one after the
    other (:func:`dlovr.model.tracks.join`); None when an edge has none (a network of recordings
    without commands), and the macro moves along the summed mean displacement instead."""
    by_id = {e.id: e for e in nprog.network.edges}
    tracks = [by_id[i].track for i in plan.edges]
    if not tracks or any(t is None for t in tracks):
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


def reference_span(nprog: Any, plan: Any, node: str) -> tuple[float, float] | None:
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


def reference_goal_entry(nprog: Any) -> float | None:
    """When the reference demonstration entered the goal (s, its own clock), or None."""
    net = nprog.network
    at = [t1 for _, t1, e in _reference_steps(net) if e.target == net.goal]
    return max(at) if at else None


def reference_track(nprog: Any) -> DemoTrack | None:
    """The reference demonstration's whole commanded track on its own clock (s), or None."""
    ref = nprog.network.reference
    return None if ref is None else DemoTrack(ref.t0 + ref.t, ref.pos, ref.quat)


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
    index: int, nprog: Any, node: str, plan: Any, sim: Any, track: DemoTrack | None = None,
    span: tuple[float, float] | None = None,
) -> MacroSpec:
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
    rel = tuple(float(x) for x in quat_rotate(inv, np.asarray(world, float)))
    motion = MotionSpec(world, rel, rot, duration, here, q)  # type: ignore[arg-type]

    def contacts(n: Any) -> tuple[ContactVec, ...]:
        v = None if n.vector is None or math.sqrt(sum(x * x for x in n.vector)) < 1e-9 else tuple(n.vector)
        return tuple(ContactVec(s, v) for s in n.principal)  # type: ignore[arg-type]

    derived = {d.cls: d for d in plan.detection}  # the network's parameters; the defaults without
    det = tuple(
        DetectionSpec(c, derived[c].algorithm, dict(derived[c].params)) if c in derived
        else DetectionSpec(c, "", {})
        for c in plan.classes
    )  # fmt: skip
    return MacroSpec(index, tuple(plan.classes), t_end, src.situation, dst.situation, contacts(src),
                     contacts(dst), motion, det, final=plan.final, frame="world")  # fmt: skip


def _free_force(m: MacroSpec, free_force: float) -> float:
    """Below what contact force (N) the sensed vector is free space after macro ``m``: ``free_force``,
    or half the smallest threshold its detectors fired at (a detection at a smaller force than
    ``free_force`` is a contact of that size, not free space)."""
    keys = [(d, THRESHOLD_PARAM.get(d.cls)) for d in m.detection]
    thr = [float(d.params[k]) for d, k in keys if k in d.params]
    return min([free_force, *(0.5 * t for t in thr if t > 0.0)])


def _hold(ses: _Session, seconds: float) -> None:
    """Hold the commanded pose ``seconds``: the gripper, which lags its target at speed, catches up
    (holding where it is instead would drop the motion still under way)."""
    sim = ses.sim
    pos, quat = np.array(sim.target_pos, dtype=float), np.array(sim.target_quat, dtype=float)
    for _ in range(round(seconds / ses.dt)):
        ses.step(pos, quat)


def _true_node(nprog: Any, sim: Any) -> tuple[str, tuple[str, ...]]:
    cur = sim.tracker.current
    have = principal_states(cur.discrete) if cur is not None else ()
    for n in nprog.network.nodes:
        if tuple(sorted(n.principal)) == have:
            return n.id, have
    return "?", have


def run_network_in(
    nprog: Any,
    sim: Any,
    scene: Any,
    opts: ExecOptions | None = None,
    nopts: NetworkOptions | None = None,
    *,
    on_step: Any = None,
    on_event: Any = None,
) -> NetworkRunResult:
    """Run the network program ``nprog`` (a :class:`dlovr.model.planning.NetworkProgram`) in ``sim``
    (a :class:`dlovr.sim.Simulator` with ``track=True`` at its start pose); see the module docstring.
    Never raises for a failed run: the reason is in the result."""
    opts = opts if opts is not None else ExecOptions()
    nopts = nopts if nopts is not None else NetworkOptions()
    net = nprog.network
    wall0 = time.perf_counter()
    holder = ProgramSpec(nprog.name or "network", nprog.source, ())
    out = Execution(holder, opts)
    ses = _Session(sim, opts, out, on_step, on_event)
    weight = np.array([0.0, 0.0, -float(scene.dlo.mass) * GRAVITY])
    tare = weight
    head = f"network program {nprog.name}: start {net.start}, goal {net.goal}, detection {opts.detect}"
    ses.emit("start", 0, head)
    node, path, macros, replans = net.start, [net.start], [], 0
    ref_track, resume = reference_track(nprog), None
    last_end: float | None = None  # where the last macro ended on the reference's clock (s)
    reason, arrived = "", False
    from dlovr.sim import SimulationDiverged

    try:
        while len(macros) < nopts.max_macros:
            mid = sim.built.mocap_id
            pos = tuple(float(x) for x in sim.data.mocap_pos[mid])
            if node == net.goal:
                arrived = True
                break
            choice = nprog.replan(node, pos)
            if choice is None:
                where = f"{node} ({net.node(node).situation})"
                reason = f"no demonstrated path from {where} to the goal {net.goal}"
                ses.emit("failed", 0, reason)
                break
            plan = choice.macro
            k = len(macros) + 1
            span = reference_span(nprog, plan, node) if nopts.tracks else None
            if span is not None:  # along the reference demonstration: its own track, as a program
                track = ref_track
            else:
                track, resume = (plan_track(nprog, plan) if nopts.tracks else None), None
            m = _macro_spec(k, nprog, node, plan, sim, track, span)
            ses.emit("plan", k, f"at {node}: edges {' '.join(plan.edges)} toward {plan.target}, "
                                f"P(goal)={choice.reach_probability:.3f}")  # fmt: skip
            t0 = float(sim.time)
            if plan.final:
                _run_final(m, ses, track)
                node = plan.target
                tn, tp = _true_node(nprog, sim)
                macros.append(NetMacro(k, choice.node, plan.target, (), plan.edges, t0, float(sim.time),
                                       "final", None, node, tn, tp))  # fmt: skip
                path.append(node)
                continue
            run = _run_macro(m, ses, track, False, resume)
            resume = run.resume_at if span is not None else None
            last_end = None if span is None else (resume if resume is not None else span[1])
            if run.ended not in ENDED_OK:
                tn, tp = _true_node(nprog, sim)
                macros.append(NetMacro(k, choice.node, plan.target, plan.classes, plan.edges, t0,
                                       run.ended_at, run.ended, None, None, tn, tp, run.reason))  # fmt: skip
                reason = f"macro {k} ({','.join(plan.classes)}, {node} -> {plan.target}): {run.reason}"
                break
            _hold(ses, nopts.sense_settle)
            tn, tp = _true_node(nprog, sim)
            sensed = sensed_contact_vector(ses.f, tare, _free_force(m, nopts.free_force))
            if opts.detect == "oracle":
                found = next((s for s in choice.successors if s.node == tn), None)
            elif run.ended == "motion" and nopts.blind_motion and "S" not in plan.classes:
                # a transition without force signal gives the wrench nothing to tell: as a compiled
                # program does, take the demonstrated motion to have made the planned transition
                # (not a spontaneous one, whose outcome the motion does not choose: where the DLO
                # landed is sensed)
                found = next((s for s in choice.successors if s.node == plan.target), None)
            else:
                from dlovr.model.planning import identify

                found = identify(choice.successors, sensed, nopts.tolerance, nopts.sigma)
            sv = None if sensed is None else tuple(round(float(x), 4) + 0.0 for x in sensed)  # no -0.0
            if found is None:
                exp = ", ".join(f"{s.node} {list(s.vector) if s.vector is not None else '-'}"
                                for s in choice.successors)  # fmt: skip
                reason = (
                    f"macro {k}: sensed contact vector {list(sv) if sv else 'none (free space)'} matches "
                    f"none of the expected situations ({exp}) within {nopts.tolerance:g}: a situation "
                    "outside the network"
                    f" (tracker: {' + '.join(tp) or 'N'})"
                )
                ses.emit("outside", k, reason)
                macros.append(NetMacro(k, choice.node, plan.target, plan.classes, plan.edges, t0,
                                       run.ended_at, "outside", sv, None, tn, tp, reason))  # fmt: skip
                break
            macros.append(NetMacro(k, choice.node, plan.target, plan.classes, plan.edges, t0,
                                   run.ended_at, run.ended, sv, found.node, tn, tp))  # fmt: skip
            if found.node != plan.target:
                replans += 1
                what = f"reached {found.node} ({found.situation}), not {plan.target}: planning again"
                ses.emit("replan", k, what)
            node = found.node
            path.append(node)
        else:
            reason = f"stopped after {nopts.max_macros} macros without reaching the goal"
            ses.emit("failed", 0, reason)
        if arrived or node == net.goal:
            arrived = True
            # the reference's motion after it entered the goal, as a program's final macro (from
            # where the last macro stopped on its clock when that followed it)
            since = last_end if last_end is not None else reference_goal_entry(nprog)
            if since is not None and ref_track is not None and float(ref_track.t[-1]) > since:
                span = (since, float(ref_track.t[-1]))
                fin = _macro_spec(len(macros) + 1, nprog, node, _Final(target=node), sim, ref_track, span)
                _run_final(fin, ses, ref_track)
            _hold(ses, opts.final_settle)
            ses.emit("end", 0, "network program done")
    except SimulationDiverged as e:
        reason = f"simulation diverged: {e}"
        ses.emit("failed", 0, reason)
    kept = list(sim.tracker.kept)
    final = principal_states(kept[-1].situation) if kept else ()
    goal_p = tuple(sorted(net.node(net.goal).principal))
    reached = final == goal_p and not reason.startswith("simulation diverged")
    if arrived and not reached and not reason:
        reason = f"final situation {final or ('N',)} is not the goal {goal_p or ('N',)}"
    return NetworkRunResult(
        nprog.name, scene.name, opts.detect, arrived and reached, reached, net.goal, goal_p, final, reason,
        tuple(path), replans, tuple(macros), float(sim.time), time.perf_counter() - wall0,
    )  # fmt: skip


def run_network(
    nprog: Any, scene: Any, opts: ExecOptions | None = None, nopts: NetworkOptions | None = None,
    *, pieces: Any = None,
) -> NetworkRunResult:  # fmt: skip
    """:func:`run_network_in` in a fresh simulation of ``scene``."""
    from dlovr.execution.run import _simulator

    opts = opts if opts is not None else ExecOptions()
    sim, why = _simulator(scene, pieces)
    if sim is None:
        net = nprog.network
        goal_p = tuple(sorted(net.node(net.goal).principal))
        return NetworkRunResult(nprog.name, scene.name, opts.detect, False, False, net.goal, goal_p, (),
                                str(why), (), 0, (), 0.0, 0.0)  # fmt: skip
    return run_network_in(nprog, sim, scene, opts, nopts)


def format_network_result(res: NetworkRunResult) -> str:
    """The per-macro table and the result line of a network run."""
    lines = [f"network program {res.program} in scene {res.scene}, detection {res.detect}",
             f"{'#':>3}  {'from':<5} {'class':<5} {'expected':<8} {'identified':<10} {'true':<5} "
             f"{'ended':>9}  outcome  sensed"]  # fmt: skip
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
    d = -(np.asarray(force, float) - np.asarray(tare, float))
    n = float(np.sqrt((d * d).sum()))
    return None if n < free_force else d / n


def load_network_program(path: str | Any) -> Any:
    """The :class:`dlovr.model.planning.NetworkProgram` in the JSON file ``path``, or None when the
    file is not a network program (``"kind": "network-program"``; then it is read as a compiled
    program). Raises :class:`dlovr.execution.programs.ProgramError` (one line) for a bad one."""
    import json
    from pathlib import Path

    from dlovr.execution.programs import ProgramError
    from dlovr.model.network import NetworkError
    from dlovr.model.planning import NetworkProgram

    try:
        raw = json.loads(Path(path).read_text(encoding="utf-8"))
    except (OSError, UnicodeDecodeError, json.JSONDecodeError):
        return None  # the compiled-program reader reports it
    if not isinstance(raw, dict) or raw.get("kind") != "network-program":
        return None
    try:
        return NetworkProgram.from_json(raw)
    except NetworkError as e:
        raise ProgramError(f"{path}: {e}") from None


def network_scene(nprog: Any, scene_ref: str | None) -> Any:
    """The scene to run a network program in: ``scene_ref`` or the network's scene; raises
    :class:`dlovr.execution.programs.ProgramError` when the scene lacks an object the network's
    contacts name, or ``dlovr.scene.SceneError``."""
    from dlovr.execution.programs import ProgramError
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
    from dlovr.execution.run import START_TOL_M

    net = nprog.network
    start = next(p for p in net.starts if p.node == net.start)
    d = math.dist(start.position, scene.gripper.pos)
    if d > START_TOL_M:
        raise ProgramError(
            f"network program {nprog.name}: starts {d * 1000:.0f} mm from scene {scene.name}'s gripper pose "
            f"(a program for another scene?)"
        )
    return scene
