"""Camera images of an episode, rendered offscreen by MuJoCo through EGL (no display needed; Debian's
``libegl1`` and ``libgl1-mesa-dri`` give a software rasteriser).

The cameras (:data:`CAMERAS`): ``scene``, fixed, looking at the scene's objects and the gripper's
start from the front and above; ``gripper``, moving with the gripper: it looks at the gripper's
origin from 0.25 m behind and above it along its heading. A camera of the scene's MuJoCo model
can be named too (none is built today).
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import numpy as np

from dlovr.inputs import InputError

#: The built-in cameras.
CAMERAS = ("scene", "gripper")


class CameraError(InputError):
    """A camera cannot be made (unknown name, bad size, no EGL): one line."""


def check_size(size: tuple[int, int]) -> None:
    """Raise :class:`CameraError` unless ``size`` (width, height) is within 16 and
    ``LIMITS["image_width"]`` x ``LIMITS["image_height"]``, both even (the videos are H.264 in
    yuv420p, which needs even sizes)."""
    from dlovr.inputs import LIMITS

    w, h = size
    wmax, hmax = int(LIMITS["image_width"]), int(LIMITS["image_height"])
    if not (16 <= w <= wmax and 16 <= h <= hmax) or w % 2 or h % 2:
        raise CameraError(f"image size {w}x{h}: width 16..{wmax}, height 16..{hmax}, both even")


class CameraSet:
    """Renders ``names`` at ``size`` (width, height) pixels each time :meth:`capture` is called."""

    def __init__(self, names: Sequence[str], size: tuple[int, int]):
        check_size(size)
        self.names, self.size = tuple(names), size
        self.frames: dict[str, list[np.ndarray]] = {n: [] for n in self.names}
        self._ctx: Any = None
        self._model: Any = None

    def _open(self, sim: Any) -> None:
        """Make the GL context and MuJoCo's rendering context for the simulator's model."""
        import mujoco

        try:
            from mujoco.egl import GLContext
        except (ImportError, OSError, RuntimeError) as e:
            raise CameraError(f"cameras need EGL (Debian: libegl1 libgl1-mesa-dri): {e}") from None
        m = sim.model
        for n in self.names:
            if n not in CAMERAS and mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_CAMERA, n) < 0:
                raise CameraError(f"unknown camera {n!r}: one of {', '.join(CAMERAS)}")
        w, h = self.size
        m.vis.global_.offwidth, m.vis.global_.offheight = max(w, 640), max(h, 480)
        self._ctx = GLContext(m.vis.global_.offwidth, m.vis.global_.offheight)
        self._ctx.make_current()
        self._con = mujoco.MjrContext(m, mujoco.mjtFontScale.mjFONTSCALE_150)
        mujoco.mjr_setBuffer(mujoco.mjtFramebuffer.mjFB_OFFSCREEN, self._con)
        self._scene = mujoco.MjvScene(m, maxgeom=10000)
        self._opt = mujoco.MjvOption()
        self._model, self._fixed = m, _scene_camera(sim)

    def capture(self, sim: Any) -> None:
        """Render every camera at the simulator's current state."""
        import mujoco

        if self._model is None:
            self._open(sim)
        w, h = self.size
        rect = mujoco.MjrRect(0, 0, w, h)
        for n in self.names:
            cam = self._camera(sim, n)
            mujoco.mjv_updateScene(self._model, sim.data, self._opt, None, cam, mujoco.mjtCatBit.mjCAT_ALL,
                                   self._scene)
            mujoco.mjr_render(rect, self._scene, self._con)
            rgb = np.empty((h, w, 3), np.uint8)
            mujoco.mjr_readPixels(rgb, None, rect, self._con)
            self.frames[n].append(rgb[::-1].copy())

    def _camera(self, sim: Any, name: str) -> Any:
        import mujoco

        if name == "scene":
            return self._fixed
        cam = mujoco.MjvCamera()
        if name == "gripper":
            pos, quat = sim.data.mocap_pos[sim.built.mocap_id], sim.data.mocap_quat[sim.built.mocap_id]
            heading = _heading_deg(quat)
            cam.type = mujoco.mjtCamera.mjCAMERA_FREE
            cam.lookat[:], cam.distance, cam.azimuth, cam.elevation = pos, 0.25, heading, -35.0
        else:
            cam.type = mujoco.mjtCamera.mjCAMERA_FIXED
            cam.fixedcamid = mujoco.mj_name2id(self._model, mujoco.mjtObj.mjOBJ_CAMERA, name)
        return cam

    def videos(self) -> dict[str, np.ndarray]:
        """Per camera the frames rendered so far, (n, H, W, 3) uint8."""
        w, h = self.size
        return {n: np.array(f, np.uint8).reshape(len(f), h, w, 3) for n, f in self.frames.items()}

    def close(self) -> None:
        """Free the rendering contexts."""
        if self._ctx is not None:
            self._con.free()
            self._ctx.free()
            self._ctx = None


def _heading_deg(quat: np.ndarray) -> float:
    """The azimuth (deg) of the gripper's x axis in the horizontal plane."""
    from dlovr.transforms import quat_rotate

    x = quat_rotate(np.asarray(quat, float), np.array([1.0, 0.0, 0.0]))
    return float(np.degrees(np.arctan2(x[1], x[0])))


def _scene_camera(sim: Any) -> Any:
    """A fixed free camera framing the scene's objects and the gripper's start."""
    import mujoco

    start = sim.data.mocap_pos[sim.built.mocap_id].copy()
    pts = [np.asarray(o.pos, float) for o in sim.scene.objects] + [start]
    centre = np.mean(pts, axis=0)
    spread = max(float(np.max(np.linalg.norm(np.array(pts) - centre, axis=1))), 0.2)
    cam = mujoco.MjvCamera()
    cam.type = mujoco.mjtCamera.mjCAMERA_FREE
    cam.lookat[:], cam.distance, cam.azimuth, cam.elevation = centre, 2.5 * spread, 90.0, -25.0
    return cam
