"""Recording a program run as MCAP: the run is a demonstration (commands, checkpoints, contact states,
Foxglove scene) plus a channel of executor events, so ``dlovr states``, ``dlovr replay --verify``,
Foxglove and the browser timeline open it like any recording.

- :func:`scene_bundle`: the scene to embed, written from the ``Scene`` value itself (a perturbed
  scene of a trial exists only in memory) with the mesh files it names;
- :func:`record_run`: :func:`dlovr.execution.run.run_program` with a recorder attached (a compiled or
  a network program).

The events channel :data:`TOPIC_EVENTS` carries one message per :class:`dlovr.execution.executor.Event`
(``start``, ``macro`` -- a macro starts --, ``detected``, ``failed``, ``final``, ``end``; for network
programs also ``plan``, ``replan`` and ``outside``) at the step it happened, and a last ``result``
message with the run's outcome.
"""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any, overload

from dlovr.execution.demo_track import DemoTrack
from dlovr.execution.engine import Engine
from dlovr.execution.executor import Event, ExecOptions
from dlovr.execution.network_run import NetworkOptions, NetworkRunResult
from dlovr.execution.recovery import Recovery
from dlovr.execution.run import fresh_simulator, not_started
from dlovr.execution.scoring import RunResult
from dlovr.model.planning import NetworkProgram
from dlovr.model.program import Program, Runnable

TOPIC_EVENTS = "/dlovr/executor_events"
EVENT_SCHEMA_NAME = "dlovr.ExecutorEvent"
EVENT_SCHEMA: dict[str, Any] = {
    "type": "object",
    "title": EVENT_SCHEMA_NAME,
    "description": "An executor event of a program run: t (s, simulated), step, kind, macro index, text.",
    "properties": {
        "t": {"type": "number"},
        "step": {"type": "integer"},
        "kind": {"type": "string"},
        "macro": {"type": "integer"},
        "text": {"type": "string"},
        "result": {"type": "object"},
    },
    "required": ["t", "step", "kind", "macro", "text"],
}


def _toml_value(x: Any) -> str:
    if isinstance(x, bool):
        return "true" if x else "false"
    if isinstance(x, int):
        return str(x)
    if isinstance(x, float):
        return repr(float(x))
    if isinstance(x, str):
        return json.dumps(x)  # a TOML basic string is a JSON string
    if isinstance(x, list | tuple):
        return "[" + ", ".join(_toml_value(v) for v in x) + "]"
    raise TypeError(f"cannot write {x!r} to TOML")


def scene_toml(scene: Any) -> bytes:
    """A scene file for ``scene`` (a ``dlovr.scene.Scene``, perturbed or not): every value written
    exactly (floats in round-trip repr), meshes relative to ``scene.path``'s folder."""
    from dataclasses import asdict

    d = scene.dlo
    lines = [f"name = {_toml_value(scene.name)}", f"description = {_toml_value(scene.description)}"]
    lines += ["", "[dlo]"]
    lines += [f"{k} = {_toml_value(v)}" for k, v in asdict(d).items()]
    lines += ["", "[gripper]", f"pos = {_toml_value(list(scene.gripper.pos))}"]
    lines += [f"quat = {_toml_value(list(scene.gripper.quat))}", "", "[model]"]
    lines += [f"{k} = {_toml_value(float(v))}" for k, v in asdict(scene.params).items()]
    base = Path(scene.path).resolve().parent
    for o in scene.objects:
        lines += ["", "[[objects]]", f"name = {_toml_value(o.name)}"]
        lines += [f"pos = {_toml_value(list(o.pos))}", f"quat = {_toml_value(list(o.quat))}"]
        if o.kind == "box":
            lines.append(f"box = {{ size = {_toml_value(list(o.size))} }}")
        else:
            rel = Path(o.mesh_path).resolve().relative_to(base).as_posix()
            lines += [f"mesh = {_toml_value(rel)}", f"scale = {_toml_value(float(o.scale))}"]
        if o.color is not None:
            lines.append(f"color = {_toml_value(list(o.color))}")
    return ("\n".join(lines) + "\n").encode("utf-8")


def scene_bundle(scene: Any) -> Any:
    """The :class:`dlovr.recording.bundle.SceneBundle` of ``scene`` (see :func:`scene_toml`)."""
    from dlovr.recording.bundle import SceneBundle, safe_relpath

    base = Path(scene.path).resolve().parent
    files = []
    for o in scene.objects:
        if o.kind == "mesh":
            rel = Path(o.mesh_path).resolve().relative_to(base).as_posix()
            files.append((str(safe_relpath(rel)), Path(o.mesh_path).read_bytes()))
    return SceneBundle(scene_toml(scene), tuple(sorted(set(files))))


@overload
def record_run(
    program: Program,
    scene: Any,
    path: str | Path,
    opts: ExecOptions | None = None,
    *,
    track: DemoTrack | None = None,
    network: NetworkOptions | None = None,
    pieces: Any = None,
    extra_metadata: dict[str, str] | None = None,
    overwrite: bool = False,
    recovery: Recovery | None = None,
) -> RunResult: ...


@overload
def record_run(
    program: NetworkProgram,
    scene: Any,
    path: str | Path,
    opts: ExecOptions | None = None,
    *,
    track: DemoTrack | None = None,
    network: NetworkOptions | None = None,
    pieces: Any = None,
    extra_metadata: dict[str, str] | None = None,
    overwrite: bool = False,
    recovery: Recovery | None = None,
) -> NetworkRunResult: ...


def record_run(
    program: Runnable,
    scene: Any,
    path: str | Path,
    opts: ExecOptions | None = None,
    *,
    track: DemoTrack | None = None,
    network: NetworkOptions | None = None,
    pieces: Any = None,
    extra_metadata: dict[str, str] | None = None,
    overwrite: bool = False,
    recovery: Recovery | None = None,
) -> RunResult | NetworkRunResult:
    """Run ``program`` (compiled or network) in ``scene`` like :func:`dlovr.execution.run.run_program`
    while recording it to ``path`` (an existing file is replaced only with ``overwrite``, once the
    new one is finished; ``recovery`` as there). A run that cannot start writes no file."""
    from dlovr.recording import DemoRecorder

    opts = opts if opts is not None else ExecOptions()
    sim, why = fresh_simulator(scene, pieces)
    if sim is None:  # the same failed result
        return not_started(program, scene, opts, str(why))
    meta = {"source": "dlovr run", "program": program.name, "detect": opts.detect, **(extra_metadata or {})}
    rec = DemoRecorder(
        path, scene, sim, sim.tracker, bundle=scene_bundle(scene), extra_metadata=meta, overwrite=overwrite
    )
    with rec:
        rec.rec.add_channel(TOPIC_EVENTS, EVENT_SCHEMA_NAME, EVENT_SCHEMA)

        def on_event(ev: Event) -> None:
            rec.rec.message(ev.step, TOPIC_EVENTS, ev.payload())

        eng = Engine(program, sim, opts, track=track, scene=scene, network=network, on_step=rec.step,
                     on_event=on_event, recovery=recovery)
        res = eng.run()
        diverged = eng.execution.diverged if eng.execution is not None else _diverged(res.reason)
        if diverged:
            rec.end_reason = diverged
        text = "goal reached" if res.success else f"failed: {res.reason}"
        result = {"success": res.success, "goal_reached": res.goal_reached, "reason": res.reason}
        payload = Event(float(sim.time), int(sim.step_index), "result", 0, text).payload()
        rec.rec.message(int(sim.step_index), TOPIC_EVENTS, {**payload, "result": result})
    return res


def _diverged(reason: str) -> str | None:
    return reason if reason.startswith("simulation diverged") else None
