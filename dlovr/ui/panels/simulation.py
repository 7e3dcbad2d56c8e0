"""The simulation panel: pause, reset, the scene, face labels on the obstacles, and the keyboard
commands that jog the gripper target."""

from __future__ import annotations

import math
from collections.abc import Callable
from typing import TYPE_CHECKING, Any, Literal

from dlovr.scene import SceneError, builtin_scenes
from dlovr.ui.app import App
from dlovr.ui.panels.timeline import TimelinePanel
from dlovr.ui.viewport import Viewport

if TYPE_CHECKING:
    import viser

JOG_STEP = 0.005  # m per key press
JOG_ANGLE = math.radians(5.0)

JogKey = Literal["J", "L", "I", "K", "U", "O", "N", "M", "P"]
"""The hotkeys of the jog commands (a subset of viser's hotkey names)."""


class SimulationPanel:
    """The "Simulation" folder and the jog commands (hotkeys); the commands are the app's. A scene
    that cannot be loaded is reported in the ``timeline`` panel."""

    def __init__(self, app: App, viewport: Viewport, timeline: TimelinePanel) -> None:
        self.app = app
        self.viewport = viewport
        self.timeline = timeline

    @property
    def face_labels(self) -> bool:
        """Whether the obstacles' faces are labelled with their names (the checkbox)."""
        return bool(self.labels_cb.value)

    def build(self, gui: viser.GuiApi) -> None:
        app = self.app
        s = app.session
        with gui.add_folder("Simulation"):
            self.frame_btn = gui.add_button("Frame scene", hint="Point the camera at the whole workspace")
            self.pause_btn = gui.add_button("Pause")
            reset_btn = gui.add_button("Reset")
            names = [n for n, _ in builtin_scenes()]
            cur = s.scene.name if s.scene.name in names else None
            self.scene_dd = gui.add_dropdown(
                "Scene", options=names if cur else [s.scene.name, *names], initial_value=s.scene.name
            )
            self.labels_cb = gui.add_checkbox("Face labels", initial_value=False)
            gui.add_markdown(
                "Drag the gizmo to move the gripper. Keys: J/L x, I/K y, U/O z, "
                "N/M yaw, P pause (5 mm / 5° a press)."
            )
        self.frame_btn.on_click(lambda e: self.viewport.frame(e.client))
        self.pause_btn.on_click(lambda _e: app.pause(not app.paused))
        reset_btn.on_click(lambda _e: app.reset())

        @self.scene_dd.on_update
        def _(event: Any) -> None:
            if event.client is None or self.scene_dd.value == app.session.scene.name:
                return
            try:
                app.load(self.scene_dd.value)
            except (SceneError, ValueError) as e:
                self.timeline.say(f"cannot load scene: {e}")

        @self.labels_cb.on_update
        def _(_e: Any) -> None:
            sc = app.view.scene or app.session.scene
            geo = self.viewport.shown_geometry or app.session.geometry
            self.viewport.show_obstacles(geo, sc)

        jogs: list[tuple[str, JogKey, Callable[[], None]]] = [
            ("Jog -x", "J", lambda: app.jog(dx=-JOG_STEP)),
            ("Jog +x", "L", lambda: app.jog(dx=JOG_STEP)),
            ("Jog +y", "I", lambda: app.jog(dy=JOG_STEP)),
            ("Jog -y", "K", lambda: app.jog(dy=-JOG_STEP)),
            ("Jog +z", "U", lambda: app.jog(dz=JOG_STEP)),
            ("Jog -z", "O", lambda: app.jog(dz=-JOG_STEP)),
            ("Yaw +", "N", lambda: app.jog(yaw=JOG_ANGLE)),
            ("Yaw -", "M", lambda: app.jog(yaw=-JOG_ANGLE)),
            ("Pause / resume", "P", lambda: app.pause(not app.paused)),
        ]
        for label, key, fn in jogs:
            cmd = gui.add_command(label, hotkey=key)
            cmd.on_trigger(lambda _e, fn=fn: fn())
