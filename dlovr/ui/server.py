"""The ``dlovr serve`` server: a viser server around a real-time simulation.

:class:`DemoServer` owns one :class:`dlovr.sim.Simulator` (in a :class:`dlovr.ui.session.Session`),
its :class:`dlovr.sim.tracker.ContactTracker` and, while recording, a
:class:`dlovr.recording.DemoRecorder`. A background thread (:class:`dlovr.ui.loop.RealtimeLoop`) steps
the simulation at its own rate (500 Hz of simulated time) paced to the wall clock and publishes the
cable, the gripper and the contact feedback at ~60 Hz, each update in one ``server.atomic()`` block
followed by ``server.flush()``. Every connected tab sees the same simulation (all scene and GUI elements are
server-wide): the 3D scene is drawn by :class:`dlovr.ui.viewport.Viewport`, the GUI is built by the
panels of :mod:`dlovr.ui.panels` (state, recording, timeline, simulation). The server wires them: each
is given the :class:`dlovr.ui.app.App` it implements and, where it needs one, another panel or the
viewport.

The gripper gizmo only sets the *target* pose; the simulated gripper follows it with bounded speed
(:class:`dlovr.sim.Simulator`). A tab that disconnects mid-drag leaves the gripper where it was; a
recording in progress is independent of the tabs and is finished by :meth:`DemoServer.stop`.
"""

from __future__ import annotations

import contextlib
import math
import socket
import sys
import threading
import time
from pathlib import Path
from typing import Any, cast

import numpy as np
import viser

from dlovr import signals
from dlovr.geometry.scene_checks import load_checked_scene
from dlovr.scene import Quat, Scene, Vec3
from dlovr.transforms import quat_mul
from dlovr.ui.app import View
from dlovr.ui.drawing import contact_arrows, point_classes, point_colors, situation_faces
from dlovr.ui.framing import camera_key_speed
from dlovr.ui.guard import Reporter, checked_pose, guard_incoming
from dlovr.ui.loop import RealtimeLoop, TargetCommand
from dlovr.ui.panels import (
    ForcePanel,
    NetworkPanel,
    RecordingPanel,
    RunPanel,
    SimulationPanel,
    StatePanel,
    TimelinePanel,
    status_markdown,
)
from dlovr.ui.panels.keys import KeysPanel
from dlovr.ui.panels.status import StatusPanel, current_status
from dlovr.ui.session import Session
from dlovr.ui.starting import StartingServer, exposure_warning
from dlovr.ui.timeline import Snapshot, Timeline
from dlovr.ui.viewport import Viewport

PUBLISH_HZ = 62.5
"""Cable frames per second sent to the browsers (the loop of :mod:`dlovr.ui.loop`): a little above the
browsers' 60 frames/s, so that timer jitter does not bring the count under it."""

PANEL_HZ = 10.0
"""Updates per second of the panels that change with time (situation text, timeline, force plot)."""


HEADLESS_CHROMIUM_ARGS = [
    "--no-sandbox",
    "--disable-gpu",
    "--disable-dev-shm-usage",
    "--disable-quic",
    "--no-first-run",
    "--disable-background-networking",
    "--disable-component-update",
    "--disable-sync",
    "--use-angle=swiftshader",
    "--enable-unsafe-swiftshader",
]
"""Flags under which headless Chromium renders the UI with software WebGL on a machine with no GPU and
no network (used by the browser tests and benchmarks/bench_ui.py)."""


def free_port(host: str = "127.0.0.1") -> int:
    """A TCP port that is free right now on ``host``."""
    with socket.socket(socket.AF_INET, socket.SOCK_STREAM) as s:
        s.bind((host, 0))
        return int(s.getsockname()[1])


class DemoServer:
    """The ``dlovr serve`` server: ``DemoServer(scene).start()``, then :meth:`stop`.

    ``port=None`` picks a free port. ``recordings_dir`` is where recordings are written (created on
    the first recording). It implements :class:`dlovr.ui.app.App`, what its panels see of it.
    """

    def __init__(
        self,
        scene: str | Path | Scene = "table",
        *,
        host: str = "127.0.0.1",
        port: int | None = 8080,
        recordings_dir: str | Path = "recordings",
        publish_hz: float = PUBLISH_HZ,
        verbose: bool = False,
    ):
        self.host = host
        self._port_wanted = free_port(host) if port is None else int(port)
        self.recordings_dir = Path(recordings_dir)
        self.publish_hz = float(publish_hz)
        self.verbose = verbose
        self.lock = threading.RLock()
        self.session = Session(scene if isinstance(scene, Scene) else load_checked_scene(scene), self.lock)
        self.server: viser.ViserServer | None = None
        self._paused = False
        self._target = TargetCommand()
        self.draw_lock = threading.RLock()
        self.view = View()  # a timeline being scrubbed (its timeline None: the live view)
        self.program_text = ""
        self.last_program: Any = None  # the last recording's compiled program
        self.last_recording: Path | None = None
        self.publish_count = 0
        self._panels_at = 0.0
        self.reporter = Reporter(lambda: self.server)  # problems shown on stderr and on every tab
        self.loop = RealtimeLoop(
            lambda: self.session,
            self._target,
            paused=lambda: self._paused,
            publish=self._publish,
            diverged=self._diverged,
            publish_hz=self.publish_hz,
            verbose=verbose,
            failed=self._failed,
        )
        self.viewport = Viewport(self, face_labels=lambda: self.simulation_panel.face_labels)
        self.status_panel = StatusPanel()
        self.state_panel = StatePanel()
        self.run_panel = RunPanel(self)
        self.force_panel = ForcePanel(self, self.run_panel)
        self.recording_panel = RecordingPanel(self)
        self.timeline_panel = TimelinePanel(self, self.viewport, self.state_panel, self.force_panel)
        self.simulation_panel = SimulationPanel(self, self.viewport, self.timeline_panel)
        self.network_panel = NetworkPanel(self)
        self.keys = KeysPanel(self, self.simulation_panel, self.status_panel)
        self.viewport.pivot = self.keys.pivot_point  # gizmo turns about the pivot, as the keys' turns

    # -- lifecycle ----------------------------------------------------------------------------------

    @property
    def port(self) -> int:
        return self.server.get_port() if self.server is not None else self._port_wanted

    @property
    def url(self) -> str:
        host = "127.0.0.1" if self.host in ("0.0.0.0", "::", "") else self.host
        return f"http://{host}:{self.port}"

    def start(self, early: StartingServer | None = None) -> DemoServer:
        """Build the page and start the simulation thread, in a new viser server or in ``early``'s,
        which has been showing what the command waits for (:mod:`dlovr.ui.starting`)."""
        if early is not None:
            early.done()
            srv = early.server
        else:
            srv = viser.ViserServer(host=self.host, port=self._port_wanted, verbose=self.verbose)
        self.server = srv
        srv.gui.configure_theme(show_share_button=False, control_width="large")
        srv.gui.main_panel.dock_right()  # the panel beside the 3D view, not over it (framing)
        srv.scene.configure_environment_map(None)
        srv.scene.add_light_ambient("/ambient", intensity=1.2)
        srv.scene.add_light_directional("/sun", intensity=1.5, position=(1.0, -1.0, 2.0))
        srv.scene.set_up_direction("+z")
        self._build_gui()
        self._build_scene()
        srv.on_client_connect(self.on_client_connect)
        srv.on_client_disconnect(self.on_client_disconnect)
        guard_incoming(srv, self.reporter)  # every client message is checked before its handlers
        self.loop.start()
        return self

    def stop(self) -> Path | None:
        """Stop the simulation thread, finish any recording (returned) and stop the server."""
        self.loop.stop()
        self.timeline_panel.stop()
        self.run_panel.cancel(None)
        self.loop.join(timeout=10)
        path = self.session.stop_recording()
        if path is not None:
            self.last_recording = path
        compiling = self.recording_panel.compile_thread
        if compiling is not None:
            compiling.join(timeout=30)
        if self.server is not None:
            self.server.stop()
            self.server = None
        return path

    def __enter__(self) -> DemoServer:
        return self.start()

    def __exit__(self, *exc: object) -> None:
        self.stop()

    # -- commands (GUI callbacks and tests) --------------------------------------------------------

    def set_target(self, pos: Any, quat: Any | None = None, *, move_gizmo: bool = True) -> None:
        """Command the gripper pose (what the gizmo does); the sim follows with bounded speed. A pose
        that is not one (NaN, a zero quaternion: :func:`dlovr.ui.guard.checked_pose`) is refused and
        reported, the gizmo put back on the last target."""
        try:
            p, q = checked_pose(pos, quat if quat is not None else self.target()[1])
        except ValueError as e:
            self.reporter("target", f"refused: {e}")
            self.move_gizmo(*self.target())
            return
        self._target.set(p, q)
        if move_gizmo:
            self.move_gizmo(p, q)

    def move_gizmo(self, pos: Any, quat: Any) -> None:
        """Put the gizmo at ``pos`` (m, world), ``quat`` (wxyz) without commanding the gripper."""
        if self.server is not None:
            self.viewport.gizmo.position = tuple(pos)
            self.viewport.gizmo.wxyz = tuple(quat)

    def target(self) -> tuple[np.ndarray, np.ndarray]:
        """The gripper target last commanded (m, world; wxyz), else the simulator's."""
        if self._target.pose is not None:
            return self._target.pose
        with self.lock:
            s = self.session.sim
            return s.target_pos.copy(), s.target_quat.copy()

    def jog(self, dx: float = 0.0, dy: float = 0.0, dz: float = 0.0, yaw: float = 0.0) -> None:
        p, q = self.target()
        if yaw:
            q = quat_mul(np.array([math.cos(yaw / 2), 0.0, 0.0, math.sin(yaw / 2)]), q)
        self.set_target(p + np.array([dx, dy, dz]), q)

    def hold(self) -> None:
        """Stop the gripper where it is now (target := current gripper pose)."""
        p, q = self.session.gripper_pose()
        self.set_target(p, q)

    @property
    def paused(self) -> bool:
        return self._paused

    def pause(self, paused: bool = True) -> None:
        with self.lock:  # the real-time loop reads the flag under it: no step once this returned
            self._paused = paused
        if self.server is not None:
            self.simulation_panel.pause_btn.label = "Resume" if paused else "Pause"

    def reset(self) -> None:
        """Restart the current scene (a recording in progress is finished first)."""
        self.load(self.session.scene.path)

    def load(self, scene: str | Path) -> None:
        """Switch to another scene (built-in name or path); finishes a recording in progress."""
        new = Session(load_checked_scene(scene), self.lock)
        with self.lock:
            self.recording_panel.finish()
            old = self.session.scene.name
            self.session = new
            self._target.clear()
            self.view.clear()
            self.run_panel.signals = None  # a run's detector signal belongs to the simulation it ran in
        if self.server is not None:
            self._build_scene()
            self.move_gizmo(*new.gripper_pose())
            self.viewport.gizmo.visible = True
            self.timeline_panel.live_btn.visible = False
            if new.scene.name != old:  # the last scene's program, notes and run are not this one's
                self.recording_panel.forget()
                self.run_panel.refresh()

    def start_recording(self, path: str | Path | None = None) -> Path:
        """Start recording to ``path`` (default: a new timestamped file in ``recordings_dir``)."""
        return self.recording_panel.start(path)

    def stop_recording(self, *, wait: bool = True) -> Path | None:
        """Finish the recording; compile it (in a thread) and show the program in the panel."""
        return self.recording_panel.stop(wait=wait)

    def open_recording(self, path: str | Path) -> Timeline:
        """Show a recording's timeline and cable (the live simulation keeps running unseen)."""
        return self.timeline_panel.open_recording(path)

    def scrub(self, t: float) -> Snapshot | None:
        """Show the cable of the viewed timeline (a recording, or the live one) at time ``t``."""
        return self.timeline_panel.scrub(t)

    def live(self) -> None:
        """Back to the live simulation view."""
        self.timeline_panel.live()

    def status(self) -> dict[str, Any]:
        """The live state, copied (:func:`session_status`)."""
        with self.lock:
            return session_status(self.session, paused=self._paused, rtf=self.loop.rtf)

    def _publish(self) -> None:
        """One frame of the live view: the cable and the gripper body every time (the real-time loop
        calls this at ``publish_hz``); the situation text, the timeline and the force plot at most
        ``PANEL_HZ`` times a second (they cost the browser a re-render each)."""
        srv = self.server
        if srv is None:
            return
        now = time.perf_counter()
        slow = now - self._panels_at >= 1.0 / PANEL_HZ
        with self.lock:
            s = self.session
            rec, st = s.record, s.state
            text = None
            if slow:
                text = status_markdown(
                    st, s.last_class(), t=rec.time, rtf=self.loop.rtf, paused=self._paused, note=s.note,
                    contact_force=s.contact_force,
                )
            viewing = self.view.timeline is not None
        if not viewing:
            pts = np.asarray(rec.points, dtype=float)
            colors = point_colors(point_classes(st, len(pts)))
            arrows = contact_arrows(st, pts)
            faces = situation_faces(st.discrete if st is not None else None)
            view = self.viewport
            with self.draw_lock, srv.atomic():
                if self.view.timeline is not None:
                    return
                view.draw_cable(pts, colors, arrows)
                view.faces.show(faces)
                view.body.position = cast(Vec3, tuple(map(float, rec.gripper_pos)))
                view.body.wxyz = cast(Quat, tuple(map(float, rec.gripper_quat)))
                if text is not None:
                    self.state_panel.show_live(text)
            self.viewport.follow(np.asarray(rec.gripper_pos, dtype=float))
            srv.flush()
            self.publish_count += 1
        self.keys.tick()
        if slow:
            self._panels_at = now
            self.status_panel.show(current_status(self, self.run_panel, self.recording_panel.started))
            self.simulation_panel.update(lambda: self.session.gripper_pose())
            self.timeline_panel.update()
            self.run_panel.update()
            self.network_panel.update()
            if not viewing:
                self.force_panel.show_live()

    # -- the GUI ----------------------------------------------------------------------------------

    def _build_gui(self) -> None:
        """The panel: status and the essential controls at the top, the details in folders below."""
        assert self.server is not None, "the GUI is built on the started server"
        gui = self.server.gui
        self.viewport.build_gizmo()
        self.status_panel.build(gui)
        self.recording_panel.build_controls(gui)
        self.simulation_panel.build_controls(gui)
        self.state_panel.build(gui)
        self.force_panel.build(gui)
        self.run_panel.build(gui)
        self.timeline_panel.build(gui)
        self.simulation_panel.build(gui)
        self.recording_panel.build(gui)
        self.network_panel.build(gui)
        self.status_panel.build_legend(gui)
        self.keys.build(gui)

    def _failed(self, e: Exception) -> None:
        """The simulation thread met an error: reported, the simulation paused, the gripper held."""
        self.reporter("simulation", f"the simulation stopped on an error and is paused: {e!r}")
        self._diverged()

    def _diverged(self) -> None:
        """A step diverged (the session restored the state before it): pause, the gripper held."""
        self.pause(True)
        with contextlib.suppress(Exception):
            self.hold()

    def _build_scene(self) -> None:
        with self.draw_lock:
            self.viewport.build()
            self.timeline_panel.update(force=True)
        self.status_panel.camera_speed = camera_key_speed(*self.viewport.scene_box())

    # -- clients ------------------------------------------------------------------------------------

    def on_client_connect(self, client: Any) -> None:
        """Frame the workspace for the new tab once its camera has reported (its aspect is known)."""

        @client.camera.on_update
        def _(cam: Any) -> None:
            self.viewport.camera_update(client)

    def on_client_disconnect(self, client: Any) -> None:
        """A tab went away: forget its camera, its hover and its keys; hold the gripper if it left
        mid-drag."""
        self.keys.held.clear()
        self.viewport.forget(client.client_id)
        if self.viewport.faces.pinned is not None and not self.loop.stopping:
            with self.draw_lock:  # it may have gone away while hovering a situation
                self.viewport.faces.pin(None)
        ended = self.viewport.dragging.pop(client.client_id, -1.0)
        if self.loop.stopping:  # the server is stopping (it disconnects everyone): nothing to hold
            return
        if ended is None or (ended >= 0 and time.perf_counter() - ended < 1.0):
            self.hold()  # it went away mid-drag: the gripper stays where it is now


def serve(
    scene: str | Path | Scene,
    host: str = "127.0.0.1",
    port: int = 8080,
    recordings_dir: str = "recordings",
    early: StartingServer | None = None,
) -> None:
    """Run the server on ``scene`` (loaded, or a name or path) until Ctrl-C or SIGTERM (used by
    ``dlovr serve``; SIGTERM exits with 143 once the server stopped, a recording in progress finished
    and the temporary folders removed); warns on stderr when ``host`` is not loopback (unless
    ``early``, the page already up, was given: its starter warned)."""
    from dlovr.recording import finish_on_sigterm

    if early is not None:
        early.say(f"loading scene {scene if not isinstance(scene, Scene) else scene.name}")
    srv = DemoServer(scene, host=host, port=port, recordings_dir=recordings_dir)
    srv = srv.start(early) if early is not None else srv.start()
    warning = exposure_warning(host, srv.port) if early is None else None
    if warning is not None:
        print(warning, file=sys.stderr, flush=True)
    try:
        with finish_on_sigterm():  # before the line that tells the server is up
            print(f"dlovr serve: scene {srv.session.scene.name} at {srv.url}  (Ctrl-C to stop)", flush=True)
            while True:
                signals.check()  # a signal that came while it could not interrupt (the kernels compiling)
                time.sleep(0.5)
    except KeyboardInterrupt:
        pass
    finally:
        path = srv.stop()
        if path is not None:
            print(f"dlovr serve: finished recording {path}", flush=True)
        print("dlovr serve: stopped", flush=True)


def session_status(s: Session, *, paused: bool, rtf: float) -> dict[str, Any]:
    """What :meth:`DemoServer.status` tells of ``s`` (positions in m, world frame; forces in N); the
    caller holds the session lock."""
    st = s.state
    return {
        "scene": s.scene.name,
        "t": s.record.time,
        "step": s.record.step,
        "gripper_pos": s.record.gripper_pos.copy(),
        "target_pos": s.sim.target_pos.copy(),
        "points": np.asarray(s.record.points).copy(),
        "discrete": st.discrete.format(),
        "topological": st.topological.format(),
        "last_class": s.last_class(),
        "force": float(sum(st.forces)),
        "gripper_force": list(st.gripper_force),
        "recording": s.recorder.path if s.recorder else None,
        "paused": paused,
        "rtf": rtf,
        "kept": len(s.tracker.kept),
    }
