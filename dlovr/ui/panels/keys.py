"""The jog keys of the page (:mod:`dlovr.ui.jog`): the page follows the keys held down and reports them
to a hidden text input; a key just pressed moves the gripper target one step, a key held moves it on
at the set speed every published frame, and turns are about the simulation panel's pivot."""

from __future__ import annotations

import threading
import time
from typing import TYPE_CHECKING, Any

import numpy as np

from dlovr.ui.app import App
from dlovr.ui.drawing import point_classes
from dlovr.ui.framing import CAMERA_KEYS_JS
from dlovr.ui.jog import HeldKeys, key_motion, keys_js, turn_about
from dlovr.ui.panels.simulation import SimulationPanel
from dlovr.ui.panels.status import StatusPanel

if TYPE_CHECKING:
    import viser


class KeysPanel:
    """The hidden input the page reports the jog keys to, and the motion they make; ``simulation`` has
    the jog settings and the pivot, ``status`` draws the line that installs the page's key follower."""

    def __init__(self, app: App, simulation: SimulationPanel, status: StatusPanel) -> None:
        self.app = app
        self.simulation = simulation
        self.status = status
        self.held = HeldKeys()
        self._moving = threading.Lock()  # one move at a time: no step lost between two threads
        self._reporting = 0  # reports being handled: their steps and corrections not all made yet

    def build(self, gui: viser.GuiApi) -> None:
        keys = gui.add_text("Jog keys held", initial_value="", visible=False)
        uuid = getattr(getattr(keys, "_impl", None), "uuid", None)

        @keys.on_update
        async def _(event: Any) -> None:  # async: the reports are handled in order (a release last)
            if event.client is not None:
                self.report(str(keys.value))

        if uuid is not None:
            self.status.script = keys_js(uuid) + ";" + CAMERA_KEYS_JS.replace("\n", "")

    def move(self, keys: list[str], linear: float, angular: float) -> None:
        """Move the target as the jog keys ``keys`` say: ``linear`` m along and ``angular`` rad about
        their axes, turns about the pivot."""
        if not keys:
            return
        dp, rv = key_motion(keys, linear, angular)
        pivot = self.pivot_point() if np.any(rv) else None
        with self._moving:  # reports (viser's thread) and ticks (the loop's) read, add and write
            p, q = self.app.target()
            p, q = turn_about(p + dp, q, rv, pivot)
            self.app.set_target(p, q)

    def pivot_point(self) -> np.ndarray | None:
        """The point turns are about (m, world): None for the gripper itself, the cable's tip, or the
        middle of the points in contact with the obstacles (the tip when none is)."""
        pivot = self.simulation.pivot
        if pivot == "gripper":
            return None
        app = self.app
        with app.lock:
            pts = np.asarray(app.session.record.points, dtype=float).copy()
            classes = point_classes(app.session.state, len(pts))
        touched = [i for i, c in enumerate(classes) if c is not None]
        return pts[touched].mean(axis=0) if pivot == "contact" and touched else pts[-1]

    def report(self, held: str) -> None:
        """The page reports the jog keys held down: a key just pressed moves one step at once; a key
        released corrects its smooth motion to the time the page held it (:class:`HeldKeys`)."""
        self._reporting += 1
        try:
            pressed, fix = self.held.report(held, time.perf_counter())
            jog = self.simulation.jog
            self.move(pressed, jog.step, jog.angle)
            for key, seconds in fix.items():  # a release: exactly as long as the page held the key
                self.move([key], jog.speed * seconds, jog.turn * seconds)
        finally:
            self._reporting -= 1

    @property
    def idle(self) -> bool:
        """No key held or still to be released, and every report's steps and corrections made: the
        target stays where it is."""
        return not self._reporting and self.held.idle

    def tick(self) -> None:
        """Keys held longer than a press move on at the set speed (called every published frame)."""
        keys, dt = self.held.tick(time.perf_counter())
        if keys and dt > 0:
            jog = self.simulation.jog
            self.move(keys, jog.speed * dt, jog.turn * dt)
