"""Foxglove messages: the ``foxglove.SceneUpdate`` and ``foxglove.FrameTransforms`` of a visual frame.

A frame shows the cable as a line strip in the world frame, the gripper as a cube locked to the
``gripper`` frame (whose pose ``/tf`` carries), and, in the first frame only, the obstacles as
triangle lists in the world frame (they persist). Positions are in metres; Foxglove's quaternions are
xyzw, MuJoCo's wxyz.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from importlib import resources
from typing import Any

import numpy as np

from dlovr.recording.format import floats


def schema(name: str) -> bytes:
    """The JSON schema of a Foxglove message type (``foxglove.SceneUpdate``, ...), shipped with dlovr."""
    return resources.files("dlovr").joinpath(f"data/foxglove/{name}.json").read_bytes()


def timestamp(ns: int) -> dict[str, int]:
    """A Foxglove timestamp from uint64 nanoseconds."""
    return {"sec": ns // 1_000_000_000, "nsec": ns % 1_000_000_000}


def stamp_ns(stamp: Mapping[str, int]) -> int:
    """Nanoseconds of a Foxglove timestamp (the inverse of :func:`timestamp`)."""
    return int(stamp["sec"]) * 1_000_000_000 + int(stamp["nsec"])


def scene_update(
    stamp: Mapping[str, int],
    points: np.ndarray,
    radius: float,
    obstacles: Sequence[tuple[str, np.ndarray]] = (),
) -> dict[str, Any]:
    """A ``foxglove.SceneUpdate``: the cable (``points`` (n+1, 3) m, world, drawn ``2 * radius`` m
    thick), the gripper and the ``obstacles`` ((name, triangles (k, 3, 3) m, world) pairs)."""
    origin = {"position": {"x": 0, "y": 0, "z": 0}, "orientation": {"x": 0, "y": 0, "z": 0, "w": 1}}

    def entity(id_: str, frame: str, **primitives: list[dict[str, Any]]) -> dict[str, Any]:
        e: dict[str, Any] = {
            "timestamp": stamp, "frame_id": frame, "id": id_, "lifetime": {"sec": 0, "nsec": 0},
            "frame_locked": frame != "world", "metadata": [],
        }
        for kind in ("arrows", "cubes", "spheres", "cylinders", "lines", "triangles", "texts", "models"):
            e[kind] = primitives.get(kind, [])
        return e

    line = {
        "type": 0,  # LINE_STRIP
        "pose": origin,
        "thickness": 2.0 * radius,
        "scale_invariant": False,
        "points": [{"x": p[0], "y": p[1], "z": p[2]} for p in np.asarray(points).tolist()],
        "color": {"r": 0.95, "g": 0.55, "b": 0.1, "a": 1.0},
        "colors": [],
        "indices": [],
    }
    grip = {
        "pose": {"position": {"x": 0, "y": 0, "z": 0.02}, "orientation": origin["orientation"]},
        "size": {"x": 0.03, "y": 0.03, "z": 0.04},
        "color": {"r": 0.3, "g": 0.3, "b": 0.35, "a": 1.0},
    }
    entities = [entity("cable", "world", lines=[line]), entity("gripper", "gripper", cubes=[grip])]
    for name, tris in obstacles:
        mesh = {
            "pose": origin,
            "points": [{"x": v[0], "y": v[1], "z": v[2]} for v in np.asarray(tris).reshape(-1, 3).tolist()],
            "color": {"r": 0.6, "g": 0.65, "b": 0.7, "a": 1.0},
            "colors": [],
            "indices": [],
        }
        entities.append(entity(f"object/{name}", "world", triangles=[mesh]))
    return {"deletions": [], "entities": entities}


def frame_transforms(
    stamp: Mapping[str, int], gripper_pos: Sequence[float], gripper_quat: Sequence[float]
) -> dict[str, Any]:
    """A ``foxglove.FrameTransforms``: the ``gripper`` frame's pose in ``world`` (position m, quat wxyz)."""
    w, x, y, z = floats(gripper_quat)
    return {
        "transforms": [
            {
                "timestamp": stamp,
                "parent_frame_id": "world",
                "child_frame_id": "gripper",
                "translation": dict(zip("xyz", floats(gripper_pos), strict=True)),
                "rotation": {"x": x, "y": y, "z": z, "w": w},  # Foxglove is xyzw, MuJoCo wxyz
            }
        ]
    }
