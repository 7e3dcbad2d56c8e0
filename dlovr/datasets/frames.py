"""Frames of an episode: a recording re-simulated (:func:`dlovr.recording.replay`) and sampled at a
fixed rate, each frame with its state, action and labels (docs/datasets.md).

Frame ``j`` is the simulation at step ``s0 + round(j / (fps * dt))``, ``s0`` being the recording's
first checkpoint (frame 0 is that checkpoint itself): the step nearest the frame's timestamp
``j / fps`` (at most ``dt / 2`` away; ``sim_time`` holds the step's exact time). At 30 fps and the 2 ms
step, frame ``30 k`` lies on the recording's ``k``-th checkpoint.
"""

from __future__ import annotations

import json
import math
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from dlovr.transforms import norm, quat_mul, quat_to_rotvec

#: Points of the cable in a frame: the centerline resampled at equal arc length, both ends included.
CABLE_NODES = 32

#: Per-frame label columns (strings; ``macro_index`` is an integer).
LABELS = ("situation", "principal", "stability", "transition", "macro_class")


@dataclass(frozen=True)
class Episode:
    """One episode: ``n`` frames at ``fps``. Arrays are float64, world frame, metres, quaternions wxyz.

    ``state``: MuJoCo's ``mjSTATE_INTEGRATION`` vector (n, S); ``gripper_pos`` (n, 3),
    ``gripper_quat`` (n, 4); ``wrench``: the force (N) and torque (N m, about the gripper's origin)
    the cable exerts on the gripper (n, 6); ``cable``: (n, CABLE_NODES, 3); ``objects``: the scene's
    object poses (n, K, 7: position, quaternion); ``action``: the commanded gripper pose (n, 7);
    ``action_delta``: its change since the previous frame, position (m) and rotation vector (rad,
    world frame) (n, 6; zero at frame 0); ``labels``: per name of :data:`LABELS` a string per frame,
    ``macro_index``: the 1-based index of the program macro the frame belongs to (0 after the last);
    ``images``: per camera (n, H, W, 3) uint8; ``info``: per-episode facts (JSON-able).
    """

    name: str
    fps: float
    sim_time: np.ndarray
    step: np.ndarray
    state: np.ndarray
    gripper_pos: np.ndarray
    gripper_quat: np.ndarray
    wrench: np.ndarray
    cable: np.ndarray
    objects: np.ndarray
    action: np.ndarray
    action_delta: np.ndarray
    labels: dict[str, list[str]]
    macro_index: np.ndarray
    object_names: tuple[str, ...]
    info: dict[str, Any]
    images: dict[str, np.ndarray] = field(default_factory=dict)

    @property
    def length(self) -> int:
        return len(self.sim_time)

    @property
    def timestamps(self) -> np.ndarray:
        """The frames' timestamps ``j / fps`` (s, from the episode's start)."""
        return np.arange(self.length) / self.fps


def resample_cable(points: np.ndarray, nodes: int = CABLE_NODES) -> np.ndarray:
    """The polyline ``points`` (m+1, 3) resampled at ``nodes`` points of equal arc length, ends kept."""
    seg = np.linalg.norm(np.diff(points, axis=0), axis=1)
    s = np.concatenate([[0.0], np.cumsum(seg)])
    want = np.linspace(0.0, s[-1], nodes)
    return np.stack([np.interp(want, s, points[:, k]) for k in range(3)], axis=1)


def frame_steps(n_steps: int, fps: float, dt: float) -> np.ndarray:
    """Offsets (in steps, from the first checkpoint) of the frames of a run of ``n_steps`` steps."""
    per = 1.0 / (fps * dt)
    n = math.floor(n_steps / per + 1e-9) + 1
    return np.round(np.arange(n) * per).astype(np.int64)


@dataclass
class _Sampler:
    """Collects frames during a replay (its ``on_step``)."""

    offsets: np.ndarray
    cameras: Any = None
    rows: list[tuple[Any, ...]] = field(default_factory=list)
    first: int | None = None
    sim: Any = None

    def __call__(self, sim: Any, rec: Any) -> None:
        if self.first is None:
            self.first, self.sim = int(rec.step), sim
        k = len(self.rows)
        if k >= len(self.offsets) or int(rec.step) - self.first != self.offsets[k]:
            return
        wrench = np.concatenate([rec.gripper_force, rec.gripper_torque])
        self.rows.append((rec.time, rec.step, sim.get_state().mj, rec.gripper_pos, rec.gripper_quat, wrench,
                          resample_cable(rec.points), rec.target_pos, rec.target_quat))
        if self.cameras is not None:
            self.cameras.capture(sim)


def gather_episode(
    path: str | Path, fps: float = 30.0, cameras: Sequence[str] = (), size: tuple[int, int] = (320, 240),
) -> Episode:
    """Re-simulate the recording at ``path`` and sample it at ``fps`` (see the module docstring), with
    the videos of ``cameras`` (:mod:`dlovr.datasets.cameras`) at ``size`` (width, height) pixels."""
    from dlovr.recording.reader import Recording
    from dlovr.recording.replaying import replay

    rec = Recording(path)
    n_steps = len(rec.commands()[0])
    sampler = _Sampler(frame_steps(n_steps, fps, rec.dt))
    if cameras:
        from dlovr.datasets.cameras import CameraSet

        sampler.cameras = CameraSet(tuple(cameras), size)
    try:
        replay(path, on_step=sampler)
    finally:
        if sampler.cameras is not None:
            sampler.cameras.close()
    return _episode(rec, fps, sampler)


def _episode(rec: Any, fps: float, sampler: _Sampler) -> Episode:
    """The episode of the frames ``sampler`` gathered from the replay of ``rec``."""
    cols = list(zip(*sampler.rows, strict=True))
    t, steps = np.array(cols[0], float), np.array(cols[1], np.int64)
    tpos, tquat = np.array(cols[7]), np.array(cols[8])
    sim = sampler.sim
    objs = [o for o in sim.scene.objects]
    poses = np.array([[*o.pos, *o.quat] for o in objs], float).reshape(len(objs), 7)
    labels, macro = frame_labels(rec, sim.tracker.transitions(), t)
    images = sampler.cameras.videos() if sampler.cameras is not None else {}
    return Episode(
        name=rec.path.stem, fps=float(fps), sim_time=t, step=steps, state=np.array(cols[2]),
        gripper_pos=np.array(cols[3]), gripper_quat=np.array(cols[4]), wrench=np.array(cols[5]),
        cable=np.array(cols[6]), objects=np.broadcast_to(poses, (len(t), *poses.shape)).copy(),
        action=np.concatenate([tpos, tquat], axis=1), action_delta=action_delta(tpos, tquat),
        labels=labels, macro_index=macro, object_names=tuple(o.name for o in objs),
        info=episode_info(rec, sim), images=images,
    )


def action_delta(pos: np.ndarray, quat: np.ndarray) -> np.ndarray:
    """Per frame the commanded pose's change since the previous frame: position (m) and rotation
    vector (rad, world frame: ``q_j = r * q_{j-1}``); zero at frame 0."""
    out = np.zeros((len(pos), 6))
    out[1:, :3] = np.diff(pos, axis=0)
    for j in range(1, len(pos)):
        prev = quat[j - 1] * np.array([1.0, -1.0, -1.0, -1.0])
        out[j, 3:] = quat_to_rotvec(quat_mul(quat[j], prev / norm(prev)))
    return out


def frame_labels(rec: Any, kept: Sequence[tuple[Any, tuple[str, ...]]], t: np.ndarray) -> tuple[
    dict[str, list[str]], np.ndarray
]:
    """Per frame time ``t`` (s): the debounced discrete situation (``kept``: the replay's kept
    situations and the classes of the transition into each), its principal contacts, its stability,
    the transition classes of a kept situation starting since the previous frame (``""`` if none),
    and the macro of the recording's program (compiled from its contact states) it belongs to."""
    from dlovr.model.network import principal_contacts, situation_stability
    from dlovr.recording.compile import compile_recording

    starts = np.array([k.start for k, _ in kept])
    out: dict[str, list[str]] = {name: [] for name in LABELS}
    for j, tj in enumerate(t):
        i = max(int(np.searchsorted(starts, tj, side="right")) - 1, 0)
        sit = kept[i][0].situation
        out["situation"].append(sit.format())
        out["principal"].append(" & ".join(c.format() for c in principal_contacts(sit)))
        out["stability"].append(situation_stability(sit))
        lo = t[j - 1] if j else -math.inf
        new = [",".join(c) for k, c in kept if lo < k.start <= tj and c]
        out["transition"].append(";".join(new))
    macros = compile_recording(rec.path).macros
    ends = np.array([m.t for m in macros])
    idx = np.searchsorted(ends, t - 1e-9, side="left")
    index = np.array([macros[i].index if i < len(macros) else 0 for i in idx], np.int64)
    out["macro_class"] = [
        ",".join(macros[i].classes) or macros[i].kind if i < len(macros) else "" for i in idx
    ]
    return out, index


def episode_info(rec: Any, sim: Any) -> dict[str, Any]:
    """Per-episode facts: where it came from, success, the scene (TOML, MJCF), versions, trial data."""
    import mujoco

    from dlovr import __version__
    from dlovr.execution.recorded import TOPIC_EVENTS

    meta = rec.metadata
    result = [m["result"] for m in rec.messages(TOPIC_EVENTS) if m.get("kind") == "result" and "result" in m]
    ended = [p for p in rec.states()[-1:] if p.get("end") and p.get("end_reason")]
    success = bool(result[-1].get("success")) if result else not ended
    return {
        "source": rec.path.name,
        "kind": "program run" if result else "demonstration",
        "success": success,
        "scene_toml": rec.scene.toml.decode("utf-8"),
        "scene_sha256": rec.scene.digest,
        "mjcf": sim.built.spec.to_xml(),
        "seed": int(meta["seed"]) if "seed" in meta else None,
        "trial": int(meta["trial"]) if "trial" in meta else None,
        "vary": json.loads(meta["vary"]) if "vary" in meta else None,
        "versions": {"recorded_dlovr": meta.get("dlovr_version"),
                     "recorded_mujoco": meta.get("mujoco_version"), "dlovr": __version__,
                     "mujoco": mujoco.__version__},
    }
