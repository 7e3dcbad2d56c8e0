"""The 3D viewport: the obstacles (with the faces in contact highlighted and optional face labels,
:mod:`dlovr.ui.highlight`), the cable as batched cylinders and balls coloured by stability class, the
contact vectors, the gripper body, the gizmo that commands the gripper target, and the camera framing
(:mod:`dlovr.ui.framing`)."""

from __future__ import annotations

import time
from collections.abc import Callable
from typing import TYPE_CHECKING, Any, cast

import numpy as np
import trimesh

from dlovr.geometry import SceneGeometry
from dlovr.scene import Scene, Vec3
from dlovr.ui.app import App
from dlovr.ui.drawing import COLOR_FREE, point_classes, point_colors, segment_transforms
from dlovr.ui.framing import FOV, frame_box
from dlovr.ui.highlight import FaceHighlighter
from dlovr.ui.jog import gizmo_target

if TYPE_CHECKING:
    import viser


CAMERA_PRESETS = ("top", "front", "side", "gripper", "follow", "contacts")
"""The camera presets: looking down, from -y, from +x at the workspace; at the gripper; at the gripper
and following it as it moves (until another preset or *Frame scene*); at the contacts (the cable's tip
when there is none), each from the framing's distance."""

FOLLOW_MIN_M = 0.0005
"""The least gripper motion (m) that moves a following camera (a still gripper sends nothing)."""

_PRESET_DIRS = {"top": (0.0, -0.02, 1.0), "front": (0.0, -1.0, 0.25), "side": (1.0, 0.0, 0.25)}


class Viewport:
    """The server's 3D scene elements; drawing happens under the server's ``draw_lock``.

    ``face_labels`` says whether the obstacles' faces are to be labelled (the simulation panel's
    checkbox). :attr:`dragging` follows the gizmo drags: client id -> when its drag ended
    (``time.perf_counter()``, s), None while it drags.
    """

    def __init__(self, app: App, face_labels: Callable[[], bool]) -> None:
        self.app = app
        self.face_labels = face_labels
        self.dragging: dict[int, float | None] = {}
        self.obstacle_handles: list[Any] = []
        self.shown_geometry: Any = None
        self.cable: viser.BatchedMeshHandle | None = None
        self.joints: viser.BatchedMeshHandle | None = None
        self.cable_n = -1
        self.arrows: Any = None
        # clients whose camera has reported its state -> (aspect, position) of the last framing
        self.camera_ready: dict[int, tuple[float, np.ndarray]] = {}
        # the point gizmo turns are about (m, world; None: the gripper): the simulation panel's pivot
        self.pivot: Callable[[], np.ndarray | None] = lambda: None
        self._drag_start: tuple[np.ndarray, np.ndarray, np.ndarray | None] | None = None
        # clients whose camera follows the gripper -> the gripper position it was last moved for (m)
        self.following: dict[int, np.ndarray] = {}
        self.faces = FaceHighlighter(self._scene_api)

    def _scene_api(self) -> viser.SceneApi:
        srv = self.app.server
        assert srv is not None, "drawing needs the started server"
        return srv.scene

    def build_gizmo(self) -> None:
        """The transform gizmo: a drag sets the gripper target (:meth:`App.set_target`)."""
        app = self.app
        p, q = app.session.gripper_pose()
        self.gizmo = self._scene_api().add_transform_controls(
            "/gripper", scale=0.15, position=tuple(p), wxyz=tuple(q)
        )

        @self.gizmo.on_update
        async def _(event: Any) -> None:
            if event.phase == "start" and event.client_id is not None:
                self.dragging[event.client_id] = None
                g = event.target  # a turn is about the pivot where it was at the drag's start
                self._drag_start = (np.array(g.position, dtype=float), np.array(g.wxyz, dtype=float),
                                    self.pivot())
            elif event.phase == "end":
                # viser sends a synthetic "end" just before the disconnect callbacks of a tab that
                # goes away mid-drag: remember when, so the server's on_client_disconnect can tell
                if event.client_id is not None:
                    self.dragging[event.client_id] = time.perf_counter()
                start, self._drag_start = self._drag_start, None
                if start is not None and start[2] is not None:
                    app.move_gizmo(*app.target())  # turned about a pivot: the gizmo back on the gripper
                return
            if event.phase == "update":
                g = event.target
                pos, quat = np.array(g.position, dtype=float), np.array(g.wxyz, dtype=float)
                start = self._drag_start
                if start is not None and start[2] is not None:
                    pos, quat = gizmo_target(start[0], start[1], pos, quat, start[2])
                app.set_target(pos, quat, move_gizmo=False)

    def draw_cable(self, pts: np.ndarray, colors: np.ndarray, arrows: np.ndarray) -> None:
        """Move the cable to ``pts`` (world frame, m) with per-point ``colors``; ``arrows`` (k, 2, 3)."""
        viewed = self.app.view.scene
        r = float(self.app.session.scene.dlo.radius) if viewed is None else float(viewed.dlo.radius)
        pos, wxyz, scales = segment_transforms(pts, r)
        seg_colors = np.where(
            (colors[:-1] != np.array(COLOR_FREE)).any(axis=1)[:, None], colors[:-1], colors[1:]
        ).astype(np.uint8)
        n = len(pos)
        if self.cable is None or self.cable_n != n:
            self._make_cable(n, r)
        cable, joints = self.cable, self.joints
        assert cable is not None and joints is not None  # made just above when missing
        cable.batched_positions = pos.astype(np.float32)
        cable.batched_wxyzs = wxyz.astype(np.float32)
        cable.batched_scales = scales.astype(np.float32)
        cable.batched_colors = seg_colors
        joints.batched_positions = np.asarray(pts, dtype=np.float32)
        joints.batched_colors = colors
        if len(arrows):
            if self.arrows is not None:
                self.arrows.points = arrows.astype(np.float32)  # moved in place, not re-created
            else:
                self.arrows = self._scene_api().add_arrows(
                    "/contacts/vectors",
                    points=arrows,
                    colors=(30, 60, 220),
                    shaft_radius=0.002,
                    head_radius=0.006,
                    head_length=0.012,
                )
        elif self.arrows is not None:
            self.arrows.remove()
            self.arrows = None

    def _make_cable(self, n: int, r: float) -> None:
        scene = self._scene_api()
        cyl = trimesh.creation.cylinder(radius=1.0, height=1.0, sections=12)
        ball = trimesh.creation.icosphere(subdivisions=1, radius=1.0)
        z = np.zeros((n, 3), dtype=np.float32)
        q = np.tile(np.array([1.0, 0, 0, 0], dtype=np.float32), (n, 1))
        self.cable = scene.add_batched_meshes_simple(
            "/cable/tube",
            cyl.vertices,
            cyl.faces,
            batched_wxyzs=q,
            batched_positions=z,
            batched_scales=np.ones((n, 3), dtype=np.float32),
            batched_colors=COLOR_FREE,
            lod="off",
        )
        self.joints = scene.add_batched_meshes_simple(
            "/cable/points",
            ball.vertices,
            ball.faces,
            batched_wxyzs=np.tile(np.array([1.0, 0, 0, 0], dtype=np.float32), (n + 1, 1)),
            batched_positions=np.zeros((n + 1, 3), dtype=np.float32),
            batched_scales=np.full(n + 1, 1.15 * r, dtype=np.float32),
            batched_colors=COLOR_FREE,
            lod="off",
        )
        self.cable_n = n

    def show_obstacles(self, geometry: SceneGeometry, scene: Scene) -> None:
        with self.app.draw_lock:
            self._show_obstacles_locked(geometry, scene)

    def _show_obstacles_locked(self, geometry: SceneGeometry, scene: Scene) -> None:
        api = self._scene_api()
        for h in self.obstacle_handles:
            h.remove()
        self.obstacle_handles = []
        colors = {o.name: o.color for o in scene.objects}
        for obj in geometry.objects:
            c = colors.get(obj.name)
            rgb = cast(tuple[int, int, int], tuple(int(255 * x) for x in c)) if c else (150, 155, 170)
            self.obstacle_handles.append(
                api.add_mesh_simple(
                    f"/obstacles/{obj.name}",
                    np.asarray(obj.mesh.vertices, dtype=np.float32),
                    np.asarray(obj.mesh.faces, dtype=np.uint32),
                    color=rgb,
                    flat_shading=True,
                )
            )
        self.faces.reset(geometry, labels=self.face_labels())
        self.shown_geometry = geometry

    def build(self) -> None:
        """(Re)build the scene of the server's session: camera, obstacles, gripper body, cable; called
        under the server's ``draw_lock``."""
        s = self.app.session
        self.cable = None
        self.cable_n = -1
        if self.arrows is not None:  # the last scene's contact vectors must not stay on screen
            self.arrows.remove()
            self.arrows = None
        self.show_obstacles(s.geometry, s.scene)
        p, q = s.gripper_pose()
        api = self._scene_api()
        self.body = api.add_frame("/gripper_body", show_axes=False, position=tuple(p), wxyz=tuple(q))
        api.add_box(
            "/gripper_body/box", dimensions=(0.03, 0.03, 0.04), color=(70, 70, 85), position=(0.0, 0.0, 0.021)
        )
        self.draw_cable(
            np.asarray(s.record.points),
            point_colors(point_classes(s.state, len(s.record.points))),
            np.zeros((0, 2, 3)),
        )
        self.frame()

    # -- the camera ---------------------------------------------------------------------------------

    def scene_box(self) -> tuple[np.ndarray, np.ndarray]:
        """The workspace's bounding box (lo, hi; m, world): the obstacles shown, the cable, the gripper."""
        app = self.app
        geo = self.shown_geometry or app.session.geometry
        with app.lock:
            pts = [np.asarray(app.session.record.points, dtype=float)]
            pts.append(np.asarray(app.session.record.gripper_pos, dtype=float)[None] + [[0.0, 0.0, 0.045]])
        boxes = [np.asarray(o.mesh.bounds, dtype=float) for o in geo.objects]
        lo = np.min([b[0] for b in boxes] + [p.min(axis=0) for p in pts], axis=0)
        hi = np.max([b[1] for b in boxes] + [p.max(axis=0) for p in pts], axis=0)
        return lo, hi

    def frame(self, client: Any = None) -> None:
        """Point the camera of ``client`` (every connected client if None, and the initial camera that
        new tabs and *Reset view* use) at the workspace so that it fills most of the view."""
        srv = self.app.server
        if srv is None:
            return
        lo, hi = self.scene_box()
        if client is None:
            pos, look = frame_box(lo, hi, aspect=1.0)
            cam = srv.initial_camera
            cam.fov = FOV
            cam.look_at = cast(Vec3, tuple(map(float, look)))
            cam.position = cast(Vec3, tuple(map(float, pos)))
        clients = [client] if client is not None else list(srv.get_clients().values())
        for c in clients:
            self.following.pop(c.client_id, None)
            if c.client_id not in self.camera_ready:
                continue  # framed when its camera first reports (camera_update)
            cam = c.camera
            aspect = cam.aspect
            pos, look = frame_box(lo, hi, aspect=aspect)
            with c.atomic():
                cam.fov = FOV
                cam.position = cast(Vec3, tuple(map(float, pos)))  # moves look_at along; set it after
                cam.look_at = cast(Vec3, tuple(map(float, look)))
            self.camera_ready[c.client_id] = (aspect, pos)

    def preset(self, name: str, client: Any = None) -> None:
        """Point the camera of ``client`` (every connected one if None) as preset ``name`` says
        (:data:`CAMERA_PRESETS`): the top, front and side views frame the workspace; *gripper* and
        *contacts* look at those from where the camera is, at the framing's distance."""
        srv = self.app.server
        if srv is None or name not in CAMERA_PRESETS:
            return
        lo, hi = self.scene_box()
        clients = [client] if client is not None else list(srv.get_clients().values())
        for c in clients:
            cam = c.camera
            pos, look = frame_box(lo, hi, aspect=cam.aspect)
            dist = float(np.linalg.norm(pos - look))
            self.following.pop(c.client_id, None)
            if name in _PRESET_DIRS:
                d = np.asarray(_PRESET_DIRS[name], dtype=float)
            else:
                d = np.asarray(cam.position, dtype=float) - np.asarray(cam.look_at, dtype=float)
                look = self._focus(name)
                dist *= 0.6
                if name == "follow":
                    self.following[c.client_id] = look.copy()
            d = d / max(float(np.linalg.norm(d)), 1e-9)
            with c.atomic():
                cam.fov = FOV
                cam.position = cast(Vec3, tuple(map(float, look + dist * d)))
                cam.look_at = cast(Vec3, tuple(map(float, look)))

    def _focus(self, name: str) -> np.ndarray:
        """The point the *gripper* or *contacts* preset looks at (m, world)."""
        app = self.app
        with app.lock:
            rec, st = app.session.record, app.session.state
            pts = np.asarray(rec.points, dtype=float)
            if name in ("gripper", "follow"):
                return np.asarray(rec.gripper_pos, dtype=float).copy()
            touched = [i for i, c in enumerate(point_classes(st, len(pts))) if c is not None]
        return pts[touched].mean(axis=0) if touched else pts[-1].copy()

    def follow(self, gripper: np.ndarray) -> None:
        """Move the cameras that follow the gripper (the *follow* preset) by the gripper's motion since
        their last move, to ``gripper`` (m, world): they keep their view of it, turned as the person
        turned them meanwhile."""
        srv = self.app.server
        if srv is None or not self.following:
            return
        clients = srv.get_clients()
        for cid, last in list(self.following.items()):
            c = clients.get(cid)
            if c is None:
                self.following.pop(cid, None)
                continue
            d = np.asarray(gripper, dtype=float) - last
            if float(np.linalg.norm(d)) < FOLLOW_MIN_M:
                continue
            cam = c.camera
            pos, look = np.asarray(cam.position, dtype=float) + d, np.asarray(cam.look_at, dtype=float) + d
            with c.atomic():
                cam.position = cast(Vec3, tuple(map(float, pos)))  # moves look_at along; set it after
                cam.look_at = cast(Vec3, tuple(map(float, look)))
            self.following[cid] = last + d

    def forget(self, client_id: int) -> None:
        """A tab went away: its camera is neither framed nor following any more."""
        self.camera_ready.pop(client_id, None)
        self.following.pop(client_id, None)

    def camera_update(self, client: Any) -> None:
        """A client's camera reported: frame it the first time, and again when its view changed shape
        (the panel docked, the window resized) while the camera is still where the framing put it."""
        cam = client.camera
        last = self.camera_ready.get(client.client_id)
        if last is None:
            self.camera_ready[client.client_id] = (0.0, np.zeros(3))
            self.frame(client)
        elif abs(cam.aspect - last[0]) > 0.01 * last[0] and np.allclose(cam.position, last[1], atol=1e-3):
            self.frame(client)
