"""The timeline panel: the kept situations as coloured bands, a time slider to scrub the cable
through them (live or a recording file), play / step / speed, zoom and pan, and opening a recording."""

from __future__ import annotations

import threading
import time
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from dlovr.geometry import SceneGeometry
from dlovr.model.transitions import format_classes
from dlovr.recording import RecordingError
from dlovr.scene import SceneError
from dlovr.ui.app import App
from dlovr.ui.panels.forces import ForcePanel
from dlovr.ui.panels.state import StatePanel
from dlovr.ui.timeline import (
    Snapshot,
    Timeline,
    axis_end,
    pan_window,
    recording_timeline,
    resimulated_forces,
    step_time,
    window_showing,
    zoom_window,
)
from dlovr.ui.viewport import Viewport

if TYPE_CHECKING:
    import viser

PLAY, PAUSE, STEP_BACK, STEP = "\u25b6 play", "\u275a\u275a pause", "\u25c0 step", "step \u25b6"
ZOOM_IN, ZOOM_OUT, PAN_BACK, PAN_ON, ZOOM_ALL = "zoom in", "out", "\u25c0 pan", "pan \u25b6", "all"
SPEEDS = ("0.25x", "0.5x", "1x", "2x", "4x")
PLAY_HZ = 20.0
"""How often a playing timeline shows its next moment (per second of wall time)."""


class TimelinePanel:
    """The "Timeline" folder and the commands behind it (:meth:`App.open_recording`,
    :meth:`App.scrub`, :meth:`App.live`). The timeline being viewed is the app's ``view``
    (:class:`dlovr.ui.app.View`). A moment is drawn in the ``viewport`` and told by the ``state``
    and the ``forces`` panels."""

    def __init__(self, app: App, viewport: Viewport, state: StatePanel, forces: ForcePanel) -> None:
        self.app = app
        self.viewport = viewport
        self.state = state
        self.forces = forces
        self._key: Any = None
        self._resim_stop: threading.Event | None = None
        self.resim_thread: threading.Thread | None = None
        self.window: tuple[float, float] | None = None  # the zoomed part of the timeline (s)
        self._play_stop = threading.Event()
        self.play_thread: threading.Thread | None = None

    def build(self, gui: viser.GuiApi) -> None:
        app = self.app
        with gui.add_folder("Timeline"):
            self.timeline_html = gui.add_html("")
            self.slider = gui.add_slider("Time [s]", min=0.0, max=1.0, step=0.01, initial_value=0.0)
            self.play_bg = gui.add_button_group("Play", (STEP_BACK, PLAY, STEP))
            self.speed_dd = gui.add_dropdown("Speed", SPEEDS, initial_value="1x")
            self.zoom_bg = gui.add_button_group("Zoom", (ZOOM_IN, ZOOM_OUT, PAN_BACK, PAN_ON, ZOOM_ALL))
            self.live_btn = gui.add_button("Back to live", visible=False)
            self.open_dd = gui.add_dropdown("Recording file", options=self.recording_files())
            self.open_btn = gui.add_button("Open recording")
            self.open_md = gui.add_markdown("")
            # hovering / clicking a situation in the timeline's HTML lands here (Timeline.html)
            self.pick = gui.add_text("Situation picked", initial_value="", visible=False)
        self.pick_uuid: str | None = getattr(getattr(self.pick, "_impl", None), "uuid", None)

        @self.pick.on_update
        def _(event: Any) -> None:
            if event.client is not None:
                self.picked(str(self.pick.value))

        @self.slider.on_update
        def _(event: Any) -> None:
            if event.client is not None:
                self.stop_playing()  # the hand on the slider takes over
                app.scrub(float(self.slider.value))

        self.live_btn.on_click(lambda _e: app.live())
        self.play_bg.on_click(lambda e: self.playback(str(e.target.value)))
        self.zoom_bg.on_click(lambda e: self.zoom(str(e.target.value)))

        @self.open_btn.on_click
        def _(_e: Any) -> None:
            name = self.open_dd.value
            if not name:
                self.open_md.content = "no recording selected"
                return
            try:
                tl = app.open_recording(app.recordings_dir / name)
                self.open_md.content = f"opened `{name}`: {len(tl.bands)} situations"
            except (RecordingError, SceneError, OSError) as e:
                self.open_md.content = f"cannot open: {e}"

    def say(self, text: str) -> None:
        """Show ``text`` (markdown) under the recording picker (what opening a recording, or loading a
        scene, says)."""
        self.open_md.content = text

    def open_recording(self, path: str | Path) -> Timeline:
        app = self.app
        tl, scene, rec = recording_timeline(path)
        self.cancel_resim()
        self.stop_playing()
        self.window = None
        with app.lock:
            app.view.timeline = tl
            app.view.scene = scene
        # the recording stores the force only where the contact state changed: re-simulate it for
        # the force at every step, in the background (the plot shows the samples meanwhile)
        stop = self._resim_stop = threading.Event()
        self.resim_thread = threading.Thread(
            target=self._resim, args=(tl, rec, scene, stop), name="dlovr-resim", daemon=True
        )
        self.resim_thread.start()
        if app.server is not None:
            self.viewport.show_obstacles(SceneGeometry.from_scene(scene, pieces=rec.pieces), scene)
            if scene.name != app.session.scene.name:
                self.viewport.frame()  # another scene: frame its workspace
            self.live_btn.visible = True
            self.viewport.gizmo.visible = False  # it moves the live gripper, which is not shown
            self.update(force=True)
            app.scrub(tl.start)
        return tl

    def _resim(self, tl: Timeline, rec: Any, scene: Any, stop: threading.Event) -> None:
        try:
            trace = resimulated_forces(rec, scene, stop)
        except Exception as e:  # keep the recorded samples; a worker thread must not raise
            tl.forces_note = f"samples at contact-state changes (re-simulation failed: {e})"
            return
        if trace is None:
            return
        tl.forces, tl.forces_note = trace, "re-simulated"
        app = self.app
        if app.view.timeline is tl and app.server is not None:
            self.forces.show_at(tl, float(self.slider.value))

    def cancel_resim(self) -> None:
        """Stop a re-simulation of a recording's forces in progress (another view, or the server stops)."""
        if self._resim_stop is not None:
            self._resim_stop.set()
        if self.resim_thread is not None:
            self.resim_thread.join(timeout=5)
            self.resim_thread = None

    def stop(self) -> None:
        """The server stops: no re-simulation, no playback goes on."""
        self.cancel_resim()
        self.stop_playing()

    def scrub(self, t: float) -> Snapshot | None:
        app = self.app
        with app.lock:
            if app.view.timeline is None:
                app.view.timeline = app.session.timeline
                app.view.scene = None
            tl = app.view.timeline
            snap = tl.at(t)
        if app.server is None or snap is None:
            return snap
        band = tl.band_at(t)
        srv = app.server
        view = self.viewport
        with app.draw_lock, srv.atomic():
            view.draw_cable(snap.points, snap.colors, np.zeros((0, 2, 3)))
            view.faces.show(snap.faces)
            view.body.position, view.body.wxyz = tuple(snap.gripper_pos), tuple(snap.gripper_quat)
            cls = format_classes(band.classes) if band and band.classes else "-"
            self.state.show(
                f"**Timeline ({tl.source}) at {t:.2f} s**\n\n**Discrete:** `{snap.text}`\n\n"
                f"**Transition into it:** `{cls}`"
            )
            self.forces.show_at(tl, t)
        srv.flush()
        self.live_btn.visible = True
        shown = window_showing(self.window, _span(tl), t)
        if shown != self.window:
            self.window = shown
            self.update(force=True)
        v = min(max(round(float(t), 2), float(self.slider.min)), float(self.slider.max))
        if v != self.slider.value:  # the Time [s] box follows (a server-side set calls back without client)
            self.slider.value = v
        return snap

    def live(self) -> None:
        app = self.app
        self.cancel_resim()
        self.stop_playing()
        self.window = None
        with app.lock:
            viewed = app.view.scene
            app.view.clear()
        if app.server is not None:
            with app.draw_lock:
                self.viewport.faces.pin(None)
            if viewed is not None:
                self.viewport.show_obstacles(app.session.geometry, app.session.scene)
                if viewed.name != app.session.scene.name:
                    self.viewport.frame()
            self.viewport.gizmo.visible = True
            self.live_btn.visible = False

    def picked(self, value: str) -> None:
        """A situation of the timeline hovered (``h<i>:<n>``: highlight its faces), left (``:<n>``,
        or ``""``) or clicked (``c<i>:<ms>``: show the middle of it, as the slider would); what follows
        the colon only makes each report a new value (:data:`dlovr.ui.timeline.PICK_JS`)."""
        app = self.app
        tl = self.viewed()
        kind = value.partition(":")[0]
        try:
            i = int(kind[1:]) if kind[:1] in ("h", "c") else -1
        except ValueError:
            return
        band = tl.bands[i] if 0 <= i < len(tl.bands) else None
        if app.server is None:
            return
        if band is not None and kind == f"c{i}":
            app.scrub((band.start + band.end) / 2.0)
        with app.draw_lock, app.server.atomic():
            self.viewport.faces.pin(band.faces if band is not None else None)
        app.server.flush()

    def viewed(self) -> Timeline:
        """The timeline being viewed: an opened recording's, or the live one."""
        return self.app.view.timeline or self.app.session.timeline

    @property
    def speed(self) -> float:
        """The playback speed: seconds of the timeline per second of wall time."""
        return float(str(self.speed_dd.value).rstrip("x"))

    @property
    def playing(self) -> bool:
        return self.play_thread is not None and self.play_thread.is_alive() and not self._play_stop.is_set()

    def playback(self, what: str) -> None:
        """The *Play* buttons: a step to the next or the previous cable frame, or play / pause."""
        if what in (STEP, STEP_BACK):
            self.stop_playing()
            self.app.scrub(step_time(self.viewed(), float(self.slider.value), 1 if what == STEP else -1))
        elif self.playing:
            self.stop_playing()
        else:
            self.play()

    def play(self) -> None:
        """Play the viewed timeline from the moment shown (from its start when at its end), at
        :attr:`speed`, until its end, a pause, or another view."""
        self.stop_playing()
        tl = self.viewed()
        t = float(self.slider.value)
        if t >= tl.end - 1e-3 or t < tl.start:
            t = tl.start
        stop = self._play_stop = threading.Event()
        self.play_thread = threading.Thread(target=self._play, args=(tl, t, stop), name="dlovr-play",
                                            daemon=True)
        self.play_bg.options = (STEP_BACK, PAUSE, STEP)
        self.play_thread.start()

    def _play(self, tl: Timeline, t: float, stop: threading.Event) -> None:
        last = time.perf_counter()
        while not stop.wait(1.0 / PLAY_HZ):
            now = time.perf_counter()
            t, last = min(t + (now - last) * self.speed, tl.end), now
            if self.viewed() is not tl or self.app.server is None:
                break
            self.app.scrub(t)
            if t >= tl.end:
                break
        if not stop.is_set():  # the end, or another view: the button says play again
            stop.set()
            self.play_bg.options = (STEP_BACK, PLAY, STEP)

    def stop_playing(self) -> None:
        """Pause a playing timeline (it stays at the moment reached)."""
        self._play_stop.set()
        th = self.play_thread
        if th is not None and th is not threading.current_thread():
            th.join(timeout=5)
        self.play_thread = None
        if hasattr(self, "play_bg") and self.play_bg.options[1] != PLAY:
            self.play_bg.options = (STEP_BACK, PLAY, STEP)

    def zoom(self, what: str) -> None:
        """The *Zoom* buttons: in or out about the moment shown, pan half a window, or all of it."""
        tl = self.viewed()
        full = _span(tl)
        at = float(self.slider.value)
        if what in (ZOOM_IN, ZOOM_OUT):
            self.window = zoom_window(self.window, full, at, 0.5 if what == ZOOM_IN else 2.0)
        elif what in (PAN_BACK, PAN_ON):
            self.window = pan_window(self.window, full, -0.5 if what == PAN_BACK else 0.5)
        else:
            self.window = None
        self.update(force=True)

    def recording_files(self) -> list[str]:
        d = self.app.recordings_dir
        files = sorted((p.name for p in d.glob("*.mcap")), reverse=True) if d.is_dir() else []
        return files or [""]

    def update(self, force: bool = False) -> None:
        """Redraw the bands and the slider's range when the viewed timeline changed (or ``force``)."""
        app = self.app
        tl = self.viewed()
        key = (id(tl), len(tl.bands), round(tl.end), self.window)
        if not force and key == self._key:
            return
        self._key = key
        live = tl is app.session.timeline
        self.timeline_html.content = tl.html(self.pick_uuid, axis_end(tl.end) if live else None, self.window)
        # the slider spans the timeline, or the zoomed window (finer scrubbing)
        a, b = (tl.start, tl.end) if self.window is None else self.window
        lo, hi = round(a, 2), round(max(b, a + 0.01), 2)
        self.slider.min, self.slider.max = lo, hi
        # the number box shows the slider's value: keep it inside the range (live: the present)
        v = hi if app.view.timeline is None else min(max(float(self.slider.value), lo), hi)
        if v != self.slider.value:
            self.slider.value = v
        files = self.recording_files()
        if tuple(files) != tuple(self.open_dd.options):
            self.open_dd.options = files


def _span(tl: Timeline) -> tuple[float, float]:
    """The whole of ``tl`` (s), at least 0.01 s long (a timeline just begun)."""
    return (tl.start, max(tl.end, tl.start + 0.01))
