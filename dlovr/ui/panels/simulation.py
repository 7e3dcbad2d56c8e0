"""The simulation controls: pause, reset (asking first while recording), the scene at the top of the
panel; and the "Gripper, keys and view" folder: the gripper pose with numeric entry and *Back to start
pose*, the jog step, speed and pivot (:mod:`dlovr.ui.jog`), the key help, camera presets and face
labels."""

from __future__ import annotations

import math
import time
from collections.abc import Callable
from typing import TYPE_CHECKING, Any

import numpy as np

from dlovr.scene import SceneError, builtin_scenes
from dlovr.transforms import quat_to_rotvec
from dlovr.ui.app import App
from dlovr.ui.jog import KEY_HELP, PIVOTS, JogSettings
from dlovr.ui.panels.timeline import TimelinePanel
from dlovr.ui.viewport import CAMERA_PRESETS, Viewport

if TYPE_CHECKING:
    import viser

JOG_STEP = JogSettings().step  # m per key press (the default; the panel's *Jog step* sets it)
JOG_ANGLE = JogSettings().angle

CONFIRM_S = 5.0
"""Seconds a *Reset* asking for confirmation (a recording in progress) waits for the second click."""


class SimulationPanel:
    """The simulation controls and the gripper, keys and view folder; the commands are the app's. A
    scene that cannot be loaded is reported in the ``timeline`` panel."""

    def __init__(self, app: App, viewport: Viewport, timeline: TimelinePanel) -> None:
        self.app = app
        self.viewport = viewport
        self.timeline = timeline
        self.jog = JogSettings()
        self.pivot = PIVOTS[0]
        self._confirm_until = 0.0

    @property
    def face_labels(self) -> bool:
        """Whether the obstacles' faces are labelled with their names (the checkbox)."""
        return bool(self.labels_cb.value)

    def build_controls(self, gui: viser.GuiApi) -> None:
        """Pause, Reset and the scene, at the top of the panel; the hotkey P."""
        app = self.app
        s = app.session
        self.pause_btn = gui.add_button("Pause", hint="Pause / resume the simulation (key P)")
        self.reset_btn = gui.add_button("Reset", hint="Restart the scene")
        self.frame_btn = gui.add_button("Frame scene", hint="Point the camera at the whole workspace")
        names = [n for n, _ in builtin_scenes()]
        cur = s.scene.name if s.scene.name in names else None
        self.scene_dd = gui.add_dropdown(
            "Scene", options=names if cur else [s.scene.name, *names], initial_value=s.scene.name
        )
        self.pause_btn.on_click(lambda _e: app.pause(not app.paused))
        self.reset_btn.on_click(lambda _e: self.reset_clicked())

        @self.scene_dd.on_update
        def _(event: Any) -> None:
            if event.client is None or self.scene_dd.value == app.session.scene.name:
                return
            try:
                app.load(self.scene_dd.value)
            except (SceneError, ValueError) as e:
                self.timeline.say(f"cannot load scene: {e}")

        cmd = gui.add_command("Pause / resume", hotkey="P")
        cmd.on_trigger(lambda _e: app.pause(not app.paused))

    def reset_clicked(self) -> None:
        """Reset; while recording, the first click asks (the label) and a second within
        :data:`CONFIRM_S` resets (the recording is finished first)."""
        now = time.monotonic()
        if self.app.session.recorder is not None and now > self._confirm_until:
            self._confirm_until = now + CONFIRM_S
            self.reset_btn.label = "Confirm reset (ends the recording)"
            self.reset_btn.color = "red"
            return
        self._confirm_until = 0.0
        self.reset_btn.label, self.reset_btn.color = "Reset", None
        self.app.reset()

    def build(self, gui: viser.GuiApi) -> None:
        """The gripper, keys and view folder."""
        app = self.app
        with gui.add_folder("Gripper, keys and view"):
            self.labels_cb = gui.add_checkbox("Face labels", initial_value=False)
            self.camera_bg = gui.add_button_group("Camera", CAMERA_PRESETS)
            self.pose_md = gui.add_markdown("")
            self.pose_in = gui.add_vector3("Go to [mm]", initial_value=(0.0, 0.0, 0.0), step=1.0)
            go_btn = gui.add_button("Go to pose")
            home_btn = gui.add_button("Back to start pose")
            self.pivot_dd = gui.add_dropdown("Turn about", PIVOTS, initial_value=self.pivot)
            self.step_sl = gui.add_slider("Jog step [mm]", min=0.5, max=20.0, step=0.5,
                                          initial_value=1000 * self.jog.step)
            self.speed_sl = gui.add_slider("Jog speed [mm/s]", min=5.0, max=200.0, step=5.0,
                                           initial_value=1000 * self.jog.speed)
            rows = "".join(f"<tr><td><b>{k}</b></td><td>{what}</td></tr>" for k, what in KEY_HELP)
            self.keys_html = gui.add_html(
                '<div class="dlovr-keys" style="font-size:11px">Drag the gizmo, or hold a key (a tap '
                "moves one step). Turns are about the pivot.<table>" + rows + "</table></div>"
            )
        self.frame_btn.on_click(lambda e: self.viewport.frame(e.client))
        self.camera_bg.on_click(lambda e: self.viewport.preset(str(self.camera_bg.value), e.client))
        go_btn.on_click(lambda _e: app.set_target(np.asarray(self.pose_in.value, dtype=float) / 1000.0))
        home_btn.on_click(lambda _e: app.set_target(*app.session.start_pose))

        @self.pivot_dd.on_update
        def _(_e: Any) -> None:
            self.pivot = str(self.pivot_dd.value)

        @self.step_sl.on_update
        def _(_e: Any) -> None:
            step = float(self.step_sl.value) / 1000.0
            self.jog = JogSettings(step, math.radians(5.0) * step / JOG_STEP, self.jog.speed, self.jog.turn)

        @self.speed_sl.on_update
        def _(_e: Any) -> None:
            speed = float(self.speed_sl.value) / 1000.0
            turn = math.radians(30.0) * speed / JogSettings().speed
            self.jog = JogSettings(self.jog.step, self.jog.angle, speed, turn)

        @self.labels_cb.on_update
        def _(_e: Any) -> None:
            sc = app.view.scene or app.session.scene
            geo = self.viewport.shown_geometry or app.session.geometry
            self.viewport.show_obstacles(geo, sc)

    def update(self, pose: Callable[[], tuple[np.ndarray, np.ndarray]]) -> None:
        """Show the gripper pose; give up a confirmation not given in time (called at ``PANEL_HZ``)."""
        if self._confirm_until and time.monotonic() > self._confirm_until:
            self._confirm_until = 0.0
            self.reset_btn.label, self.reset_btn.color = "Reset", None
        p, q = pose()
        rv = np.degrees(quat_to_rotvec(q))
        text = (
            f"**Gripper** x {1000 * p[0]:.1f}, y {1000 * p[1]:.1f}, z {1000 * p[2]:.1f} mm; "
            f"rotation vector ({rv[0]:.0f}, {rv[1]:.0f}, {rv[2]:.0f})°"
        )
        if text != self.pose_md.content:
            self.pose_md.content = text
