"""Replay: re-simulate a recording from its first checkpoint and its command stream alone, and with
``verify`` compare it bit for bit with what was recorded (``dlovr replay``)."""

from __future__ import annotations

import time
from collections.abc import Callable, Mapping, Sequence
from contextlib import nullcontext
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from dlovr import __version__
from dlovr.recording.format import RecordingError
from dlovr.recording.reader import Recording


@dataclass(frozen=True)
class ReplayResult:
    """Outcome of :func:`replay`. ``divergence``: the first difference found by ``verify`` (or None)."""

    steps: int
    sim_time: float
    wall_time: float
    states: tuple[dict[str, Any], ...]
    divergence: str | None
    warnings: tuple[str, ...]


def load_embedded_scene(recording: Recording, directory: str | Path) -> Any:
    """Load the recording's own scene (written into ``directory``; never a path named inside it)."""
    from dlovr.geometry.scene_checks import load_checked_scene
    from dlovr.scene import SceneError

    path = recording.scene.materialize(directory)
    try:
        return load_checked_scene(path)
    except SceneError as e:
        raise RecordingError(f"{recording.path}: embedded scene is invalid: {e}") from None


def replay(
    path: str | Path, *, verify: bool = False, progress: Any = None,
    on_step: Callable[[Any, Any], None] | None = None,
) -> ReplayResult:
    """Re-simulate a recording from its first checkpoint and its command stream alone.

    With ``verify``, the state at every checkpoint and the wrench samples (when the recording has
    them) are compared bit for bit and the contact-state sequence with the recorded one; the first
    difference is reported in ``divergence``.
    ``progress(done, total)`` is called with the number of steps done so far and in all.
    ``on_step(sim, record)`` is called with the simulator and the step's record at the first
    checkpoint (once restored) and after every step (how :mod:`dlovr.datasets` samples frames).
    """
    import tempfile

    from dlovr.sim import SimState, Simulator
    from dlovr.sim.behind import tracking_behind

    rec = Recording(path)
    warnings = _version_warnings(rec)
    steps, pos, quat = rec.commands()
    cps = rec.checkpoints()
    recorded_states = rec.states()
    wrench = rec.wrench() if verify else None
    wrench_steps: dict[int, int] = {}
    if wrench is not None:
        wrench_steps = {round(float(t) / rec.dt): i for i, t in enumerate(wrench.t)}
    with tempfile.TemporaryDirectory(prefix="dlovr-replay-") as tmp:
        scene = load_embedded_scene(rec, tmp)
        if rec.pieces is not None and set(rec.pieces) != {o.name for o in scene.objects}:
            raise RecordingError(f"{rec.path}: the embedded decomposition does not match the scene's objects")
        sim = Simulator(scene, pieces=rec.pieces, track=True)  # every step updates sim.tracker
        if abs(sim.model.opt.timestep - rec.dt) > 1e-15:
            raise RecordingError(
                f"{rec.path}: time step {rec.dt} differs from the scene's {sim.model.opt.timestep}"
            )
    tracker = sim.tracker
    tracker.hold, tracker.flight = rec.hold, rec.flight  # taken by restart() below
    first = cps[0]
    if len(first.state) != len(sim.get_state().mj):
        raise RecordingError(f"{rec.path}: checkpoint size does not match the embedded scene's model")
    sim.set_state(SimState(first.state, first.step, first.target_pos, first.target_quat))
    if steps[0] != first.step + 1:
        raise RecordingError(f"{rec.path}: command stream does not start right after the first checkpoint")
    by_step = {c.step: c for c in cps[1:]}
    divergence: str | None = None
    wrench_bytes = [] if wrench is None else _wrench_rows(wrench)
    # the recorded targets are the exact ones used (validated and normalised when recorded): set as
    # they are (normalising again may change the last bit), rows of private copies made read-only
    # (the records share them, as they share set_target's)
    pos_rows, quat_rows = list(_read_only(pos)), list(_read_only(quat))
    t0 = time.perf_counter()
    start = sim.record()
    tracker.restart(start)
    if on_step is not None:
        on_step(sim, start)
    dt = rec.dt
    step = sim.step
    # nothing reads the states before the end unless on_step may: the tracker works beside the
    # simulation on a second core (the same states, bit for bit)
    with nullcontext() if on_step is not None else tracking_behind(sim):
        for i, k in enumerate(steps.tolist()):
            sim.target_pos, sim.target_quat = pos_rows[i], quat_rows[i]
            r = step()
            if on_step is not None:
                on_step(sim, r)
            if wrench is not None and divergence is None and k in wrench_steps:
                divergence = _check_wrench(wrench, wrench_bytes, wrench_steps.pop(k), r, dt)
            if verify and divergence is None and k in by_step:
                divergence = _check_state(by_step[k].state, sim.get_state().mj, k, dt)
            if progress is not None and (i % 500 == 0 or i == len(steps) - 1):
                progress(i + 1, len(steps))
    wall = time.perf_counter() - t0
    replayed = tuple(st.payload() for st in tracker.changes)
    if wrench is not None and divergence is None and wrench_steps:
        divergence = f"{len(wrench_steps)} recorded wrench samples lie past the replayed steps"
    if verify and divergence is None:
        divergence = _compare_states([p for p in recorded_states if not p.get("end")], replayed, dt)
    return ReplayResult(len(steps), len(steps) * dt, wall, replayed, divergence, tuple(warnings))


def _read_only(a: Any) -> np.ndarray:
    """A private float64 copy of ``a``, read-only."""
    out = np.array(a, dtype=float)
    out.flags.writeable = False
    return out


def _check_state(want: np.ndarray, got: np.ndarray, k: int, dt: float) -> str | None:
    """The difference of the replayed state ``got`` from the checkpoint's ``want`` at step ``k``, bit
    for bit (None when equal)."""
    if np.array_equal(want.view(np.uint64), got.view(np.uint64)):
        return None
    bad = int(np.argmax(want.view(np.uint64) != got.view(np.uint64)))
    return (
        f"state differs at checkpoint step {k} (t={k * dt:.3f} s), element {bad}: "
        f"recorded {float(want[bad])!r}, replayed {float(got[bad])!r}"
    )


def _version_warnings(rec: Recording) -> list[str]:
    """A warning per software version that differs from the recording's."""
    import mujoco

    warnings = []
    for key, have in (("mujoco_version", mujoco.__version__), ("dlovr_version", __version__)):
        want = rec.metadata.get(key)
        if want != have:
            warnings.append(
                f"recorded with {key.split('_')[0]} {want}, replaying with {have}: may not be bit-exact"
            )
    return warnings


def _compare_states(
    recorded: Sequence[Mapping[str, Any]], replayed: Sequence[Mapping[str, Any]], dt: float
) -> str | None:
    for i, (a, b) in enumerate(zip(recorded, replayed, strict=False)):
        for key in ("step", "topological", "discrete"):
            if a.get(key) != b.get(key):
                return (
                    f"contact state {i + 1} (t={a.get('step', 0) * dt:.3f} s) differs in {key}: "
                    f"recorded {a.get(key)!r}, replayed {b.get(key)!r}"
                )
    if len(recorded) != len(replayed):
        return f"recorded {len(recorded)} contact-state changes, replay produced {len(replayed)}"
    return None


def _wrench_rows(wrench: Any) -> list[bytes]:
    """Each wrench sample's force and torque as the bytes of six float64 values."""
    rows = np.ascontiguousarray(np.concatenate([wrench.force, wrench.torque], axis=1), dtype=np.float64)
    return [row.tobytes() for row in rows]


def _check_wrench(wrench: Any, rows: Sequence[bytes], i: int, r: Any, dt: float) -> str | None:
    """:func:`_compare_wrench`, with the bits of sample ``i`` (``rows``: :func:`_wrench_rows`)
    compared as bytes first: the message is made only on a difference."""
    if wrench.t[i] == r.time and rows[i] == r.gripper_force.tobytes() + r.gripper_torque.tobytes():
        return None
    return _compare_wrench(wrench, i, r, dt)


def _compare_wrench(wrench: Any, i: int, r: Any, dt: float) -> str | None:
    """The first difference between wrench sample ``i`` and the replayed step's record, or None."""
    got = np.concatenate([np.asarray(r.gripper_force, float), np.asarray(r.gripper_torque, float)])
    want = np.concatenate([wrench.force[i], wrench.torque[i]])
    if wrench.t[i] != r.time:
        return f"wrench sample {i + 1} is at t={float(wrench.t[i])!r} s, replayed step at {r.time!r} s"
    if np.array_equal(want.view(np.uint64), got.view(np.uint64)):
        return None
    bad = int(np.argmax(want.view(np.uint64) != got.view(np.uint64)))
    what = ("force x", "force y", "force z", "torque x", "torque y", "torque z")[bad]
    return (
        f"wrench sample {i + 1} (t={r.time:.3f} s) differs in {what}: "
        f"recorded {float(want[bad])!r}, replayed {float(got[bad])!r}"
    )
