"""One run of a program in one scene, and the open-loop replay it is compared with.

- :func:`resolve_scene`: the scene a program runs in (given, named by the program, or the one its
  demonstration was recorded in), checked against the program (:func:`check_program_scene`);
- :func:`demo_track`: the demonstration's gripper trajectory (:mod:`dlovr.execution.demo_track`), for
  ``--path demo`` and the baseline;
- :func:`find_recording`: the demonstration a program was compiled from;
- :func:`run_program`: simulate, execute, judge (:class:`dlovr.execution.engine.Engine`) ->
  :class:`dlovr.execution.scoring.RunResult`, or a network program's
  :class:`dlovr.execution.network_run.NetworkRunResult`;
- :func:`run_openloop`: replay the demonstration's recorded gripper commands open loop in a scene
  and judge the end situation against the program's goal -> :class:`OpenLoopResult`.

A run that cannot start (the cable's start pose inside an obstacle of a perturbed scene) or whose
simulation diverges is a failed result with its reason, never an exception.
"""

from __future__ import annotations

import math
import time
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Any, overload

import numpy as np

from dlovr.execution.demo_track import DemoTrack, load_track
from dlovr.execution.engine import Engine
from dlovr.execution.executor import (
    FINAL_SETTLE_S,
    START_TOL_DEG,
    START_TOL_M,
    ExecOptions,
    principal_states,
)
from dlovr.execution.network_run import NetworkOptions, NetworkRunResult, failed_start
from dlovr.execution.recovery import Recovery
from dlovr.execution.scoring import RunResult
from dlovr.model.planning import NetworkProgram
from dlovr.model.program import Program, ProgramError, Runnable


def find_recording(program: Program, given: str | Path | None = None) -> Path | None:
    """The demonstration a program was compiled from: ``given``, else its ``source`` looked up beside
    the program file, in its parent directory and in the working directory; ``None`` if not found."""
    if given is not None:
        return Path(given)
    if not program.source:
        return None
    src = Path(program.source)
    cands = [src] if src.is_absolute() else []
    if program.path is not None and not src.is_absolute():
        cands += [program.path.parent / src, program.path.parent.parent / src]
    if not src.is_absolute():
        cands += [Path.cwd() / src, Path.cwd() / "recordings" / src]
    return next((c for c in cands if c.is_file()), None)


def not_found(program: Program) -> str:
    """Said when :func:`find_recording` finds no demonstration for ``program``."""
    return f"its demonstration {program.source!r} was not found"


POSES_INSTEAD = "the macros move along the program's poses (--path program)"
"""What a program does without its demonstration (another way of moving: another result)."""


def check_program_scene(program: Program, scene: Any) -> None:
    """Raise :class:`ProgramError` when ``program`` was not made for ``scene``: it names objects the
    scene lacks, or it starts away from the scene's gripper pose."""
    where = str(program.path) if program.path else program.name
    names = {o.name for o in scene.objects}
    missing = sorted(program.objects - names)
    if missing:
        raise ProgramError(
            f"{where}: program touches object {missing[0]!r}, which scene {scene.name} does not have "
            f"(a program for another scene?)"
        )
    start = program.start
    d = math.dist(start.start_pos, scene.gripper.pos)
    q0, q1 = np.asarray(start.start_quat, float), np.asarray(scene.gripper.quat, float)
    c = abs(float((q0 * q1).sum())) / float(np.sqrt((q0 * q0).sum() * (q1 * q1).sum()))
    ang = math.degrees(2.0 * math.acos(min(1.0, c)))
    if d > START_TOL_M or ang > START_TOL_DEG:
        raise ProgramError(
            f"{where}: program starts at {[round(x, 4) for x in start.start_pos]}, {d * 1000:.0f} mm and "
            f"{ang:.0f} deg from scene {scene.name}'s gripper pose (a program for another scene?)"
        )


def resolve_scene(program: Program, scene_ref: str | None, recording: Path | None = None) -> Any:
    """The scene to run ``program`` in: ``scene_ref`` (name or path), else the program's ``scene``,
    else the scene its demonstration was recorded in, else the built-in scene named like the program.
    Raises :class:`ProgramError` or ``dlovr.scene.SceneError`` (one line)."""
    from dlovr.geometry.scene_checks import load_checked_scene
    from dlovr.scene import builtin_scenes

    ref = scene_ref or program.scene
    if ref is None and recording is not None and recording.is_file():
        from dlovr.recording import Recording, RecordingError

        try:
            ref = Recording(recording).metadata.get("scene_name") or None
        except RecordingError:
            ref = None
        if ref is not None and ref not in {n for n, _ in builtin_scenes()}:
            ref = None
    if ref is None and program.name in {n for n, _ in builtin_scenes()}:
        ref = program.name
    if ref is None:
        raise ProgramError(f"{program.path or program.name}: cannot tell which scene it is for: give --scene")
    scene = load_checked_scene(ref)
    check_program_scene(program, scene)
    return scene


def demo_track(program: Program, recording: str | Path | None = None) -> DemoTrack | None:
    """The program's demonstration trajectory when its recording can be found, else None."""
    path = find_recording(program, recording)
    return None if path is None else load_track(path)


def fresh_simulator(scene: Any, pieces: Any = None, geometry: Any = None) -> tuple[Any, str | None]:
    """A ``dlovr.sim.Simulator`` of ``scene`` at its start pose with the contact tracker (``pieces``:
    its convex decomposition, if known), or None and why it cannot start.

    ``geometry``: the scene's :class:`dlovr.geometry.SceneGeometry` made before
    (``SceneGeometry.from_scene(scene, pieces=pieces)``; it only reads it), so that two runs in one
    scene (a trial's program and its open-loop replay) build it once."""
    from dlovr.sim import SimulationDiverged, Simulator

    try:
        return Simulator(scene, track=True, pieces=pieces, geometry=geometry), None
    except (ValueError, SimulationDiverged) as e:
        return None, f"cannot start: {e}"


@overload
def run_program(
    program: Program,
    scene: Any,
    opts: ExecOptions | None = None,
    *,
    track: DemoTrack | None = None,
    network: NetworkOptions | None = None,
    pieces: Any = None,
    on_step: Any = None,
    on_event: Any = None,
    recovery: Recovery | None = None,
    geometry: Any = None,
) -> RunResult: ...


@overload
def run_program(
    program: NetworkProgram,
    scene: Any,
    opts: ExecOptions | None = None,
    *,
    track: DemoTrack | None = None,
    network: NetworkOptions | None = None,
    pieces: Any = None,
    on_step: Any = None,
    on_event: Any = None,
    recovery: Recovery | None = None,
    geometry: Any = None,
) -> NetworkRunResult: ...


def run_program(
    program: Runnable,
    scene: Any,
    opts: ExecOptions | None = None,
    *,
    track: DemoTrack | None = None,
    network: NetworkOptions | None = None,
    pieces: Any = None,
    on_step: Any = None,
    on_event: Any = None,
    recovery: Recovery | None = None,
    geometry: Any = None,
) -> RunResult | NetworkRunResult:
    """Execute ``program`` (compiled or network) in a fresh simulation of ``scene`` and judge it
    (:class:`dlovr.execution.engine.Engine`; ``recovery``: a compiled program that misses its goal
    plans again through that network); a run that cannot start is a failed result. ``geometry``:
    the scene's geometry made before (:func:`fresh_simulator`)."""
    opts = opts if opts is not None else ExecOptions()
    sim, why = fresh_simulator(scene, pieces, geometry)
    if sim is None:
        return not_started(program, scene, opts, str(why))
    eng = Engine(
        program, sim, opts, track=track, scene=scene, network=network, on_step=on_step, on_event=on_event,
        recovery=recovery,
    )
    return eng.run()


def not_started(program: Runnable, scene: Any, opts: ExecOptions, why: str) -> RunResult | NetworkRunResult:
    """The failed result of a run that could not start (``why``)."""
    if isinstance(program, NetworkProgram):
        return failed_start(program, scene, opts.detect, why)
    goal = program.goal if isinstance(program, Program) else ()
    return RunResult(
        program=program.name, scene=scene.name, detect=opts.detect, success=False, goal_reached=False,
        goal=goal, final_situation="", final_principals=(), failed_macro=0, reason=why, macros=(),
        sim_time=0.0, wall_time=0.0,
    )


@dataclass(frozen=True)
class OpenLoopResult:
    """The demonstration's gripper commands replayed open loop: whether its end situation has the
    program's goal principal contacts, and why not."""

    goal_reached: bool
    final_situation: str
    final_principals: tuple[str, ...]
    reason: str
    sim_time: float
    wall_time: float

    def to_json(self) -> dict[str, Any]:
        d = asdict(self)
        d["final_principals"] = list(self.final_principals)
        return d


def run_openloop(
    program: Program, scene: Any, track: DemoTrack, *, pieces: Any = None, settle: float = FINAL_SETTLE_S,
    geometry: Any = None,
) -> OpenLoopResult:
    """Replay ``track`` (every step's commanded gripper pose) in a fresh simulation of ``scene``, then
    hold the last command ``settle`` s more (as long as a program holds its last pose), and judge the
    last debounced situation against ``program``'s goal. ``geometry``: the scene's geometry made
    before (:func:`fresh_simulator`)."""
    from dlovr.sim import SimulationDiverged

    wall0 = time.perf_counter()
    sim, why = fresh_simulator(scene, pieces, geometry)
    if sim is None:
        return OpenLoopResult(False, "", (), str(why), 0.0, 0.0)
    sim.tracker.restart(sim.record())
    reason = ""
    pos, quat = np.ascontiguousarray(track.pos, dtype=float), np.ascontiguousarray(track.quat, dtype=float)
    try:
        for i in range(len(track.t)):
            sim.set_target(pos[i], quat[i])  # a row repeated bit for bit costs nothing
            sim.step()
        for _ in range(round(settle / float(sim.model.opt.timestep))):
            sim.step()
    except SimulationDiverged as e:
        reason = f"simulation diverged: {e}"
    kept = sim.tracker.kept
    final = kept[-1].situation if kept else None
    fp = principal_states(final) if final is not None else ()
    reached = not reason and final is not None and fp == program.goal
    if not reached and not reason:
        reason = f"final situation {fp or ('N',)} is not the goal {program.goal or ('N',)}"
    text = final.format() if final is not None else ""
    return OpenLoopResult(reached, text, fp, reason, float(sim.time), time.perf_counter() - wall0)
