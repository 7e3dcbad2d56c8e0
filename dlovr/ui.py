"""Browser teleoperation UI (``dlovr serve``): a viser server around a real-time simulation.

The only module that imports viser. :class:`DemoServer` owns one :class:`dlovr.sim.Simulator`, its
:class:`dlovr.sim.tracker.ContactTracker` and, while recording, a :class:`dlovr.recording.DemoRecorder`.
A background thread steps the simulation at its own rate (500 Hz of simulated time) paced to the
wall clock and publishes the cable, the gripper and the contact feedback at ~40 Hz, each update in
one ``server.atomic()`` block followed by ``server.flush()``. Every connected tab sees the same
simulation (all scene and GUI elements are server-wide).

The gripper gizmo only sets the *target* pose; the simulated gripper follows it with bounded speed
(:class:`dlovr.sim.Simulator`). A tab that disconnects mid-drag leaves the gripper where it was; a
recording in progress is independent of the tabs and is finished by :meth:`DemoServer.stop`.
"""

from __future__ import annotations

import contextlib
import datetime as _dt
import html
import math
import socket
import threading
import time
from collections import deque
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import trimesh
import viser

from dlovr.geometry import SceneGeometry
from dlovr.model.discrete import Stability
from dlovr.model.transitions import classify_step, format_classes
from dlovr.recording import DemoRecorder, Recording, RecordingError, compile_recording, kept_states
from dlovr.scene import Scene, SceneError, builtin_scenes, load_scene
from dlovr.sim import SimulationDiverged, Simulator
from dlovr.sim.tracker import ContactState, ContactTracker
from dlovr.transforms import quat_mul

PUBLISH_HZ = 40.0
JOG_STEP = 0.005  # m per key press
JOG_ANGLE = math.radians(5.0)

# cable colours: free, then by stability class of the contact a point belongs to
COLOR_FREE = (235, 140, 30)
COLOR_BY_CLASS = {
    Stability.STABLE: (40, 170, 60),
    Stability.SEMI: (230, 200, 20),
    Stability.INSTABLE: (220, 40, 40),
}
BAND_COLORS = ("#4e79a7", "#f28e2b", "#59a14f", "#e15759", "#76b7b2", "#edc948", "#b07aa1", "#9c755f")


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


# --------------------------------------------------------------------------------------------------
# Pure helpers (no viser): cable geometry, colours, text
# --------------------------------------------------------------------------------------------------


def segment_transforms(points: np.ndarray, radius: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Per-segment (positions, wxyz, xyz scales) placing a unit cylinder (z axis, height 1) on each
    segment of the polyline ``points``."""
    p = np.asarray(points, dtype=float)
    d = np.diff(p, axis=0)
    length = np.linalg.norm(d, axis=1)
    u = d / np.maximum(length, 1e-12)[:, None]
    # rotation taking +z to u: q = (1 + u_z, -u_y, u_x, 0), normalised; u = -z -> 180° about x
    q = np.stack([1.0 + u[:, 2], -u[:, 1], u[:, 0], np.zeros(len(u))], axis=1)
    n = np.linalg.norm(q, axis=1)
    flip = n < 1e-9
    q[flip] = (0.0, 1.0, 0.0, 0.0)
    n[flip] = 1.0
    q /= n[:, None]
    scales = np.stack([np.full(len(u), radius), np.full(len(u), radius), length], axis=1)
    return (p[:-1] + p[1:]) / 2.0, q, scales


def point_classes(state: ContactState | None, npoints: int) -> list[Stability | None]:
    """Stability class of the contact each cable point belongs to (None: free point)."""
    out: list[Stability | None] = [None] * npoints
    if state is None:
        return out
    for tc, dc in zip(state.topological.contacts, state.discrete.contacts, strict=True):
        span = tc.dlo.span
        cls = dc.state.stability_class
        if span is None or cls is None:
            continue
        a, b = span
        for i in range(max(0, a), min(npoints - 1, b) + 1):
            prev = out[i]
            # keep the least stable class where two contacts share a point
            if prev is None or _rank(cls) > _rank(prev):
                out[i] = cls
    return out


def _rank(c: Stability) -> int:
    return {Stability.STABLE: 0, Stability.SEMI: 1, Stability.INSTABLE: 2}[c]


def point_colors(classes: list[Stability | None]) -> np.ndarray:
    return np.array([COLOR_BY_CLASS[c] if c is not None else COLOR_FREE for c in classes], dtype=np.uint8)


def contact_arrows(state: ContactState | None, points: np.ndarray, length: float = 0.06) -> np.ndarray:
    """(k, 2, 3) arrows: from each non-free contact's point(s) along its contact vector."""
    if state is None:
        return np.zeros((0, 2, 3))
    out = []
    for tc, dc in zip(state.topological.contacts, state.discrete.contacts, strict=True):
        if dc.vector is None or tc.dlo.span is None or dc.state.stability_class is None:
            continue
        a, b = tc.dlo.span
        base = np.asarray(points[a : b + 1], dtype=float).mean(axis=0)
        v = np.asarray(dc.vector, dtype=float)
        out.append([base, base + length * v / max(float(np.linalg.norm(v)), 1e-12)])
    return np.asarray(out, dtype=float).reshape(-1, 2, 3)


@dataclass
class Snapshot:
    """The cable at one moment (for the timeline): time, points, point colours, situation text."""

    t: float
    points: np.ndarray
    colors: np.ndarray
    gripper_pos: np.ndarray
    gripper_quat: np.ndarray
    text: str


@dataclass
class Band:
    """One kept contact situation on the timeline."""

    start: float
    end: float
    situation: str
    classes: tuple[str, ...]


@dataclass
class Timeline:
    """Kept situations as bands plus cable snapshots (one per kept situation and a few per second)."""

    bands: list[Band] = field(default_factory=list)
    snapshots: deque = field(default_factory=lambda: deque(maxlen=20000))
    source: str = "live"

    @property
    def end(self) -> float:
        t = [b.end for b in self.bands]
        if self.snapshots:
            t.append(self.snapshots[-1].t)
        return max(t, default=0.0)

    @property
    def start(self) -> float:
        t = [b.start for b in self.bands]
        if self.snapshots:
            t.append(self.snapshots[0].t)
        return min(t, default=0.0)

    def at(self, t: float) -> Snapshot | None:
        if not self.snapshots:
            return None
        ts = np.fromiter((s.t for s in self.snapshots), dtype=float, count=len(self.snapshots))
        i = int(np.searchsorted(ts, t, side="right")) - 1
        return self.snapshots[max(0, i)]

    def band_at(self, t: float) -> Band | None:
        for b in self.bands:
            if b.start <= t < b.end:
                return b
        return self.bands[-1] if self.bands and t >= self.bands[-1].start else None

    def html(self) -> str:
        """Coloured bands, one per kept situation, transitions marked with their classes."""
        t0, t1 = self.start, self.end
        span = max(t1 - t0, 1e-9)
        colors: dict[str, str] = {}
        cells = []
        for b in self.bands:
            c = colors.setdefault(b.situation, BAND_COLORS[len(colors) % len(BAND_COLORS)])
            w = max(0.5, 100.0 * (b.end - b.start) / span)
            label = format_classes(b.classes) if b.classes else ""
            tip = html.escape(f"{b.start:.2f}-{b.end:.2f} s  {label}  {b.situation}")
            border = "border-left:2px solid #000;" if b.classes else ""
            cells.append(f'<div title="{tip}" style="width:{w:.2f}%;background:{c};{border}"></div>')
        bar = (
            '<div class="dlovr-timeline" style="display:flex;height:14px;width:100%;'
            f'background:#ddd;overflow:hidden;border-radius:3px">{"".join(cells)}</div>'
        )
        rows = "".join(
            f"<li>{b.start:.2f} s <b>{html.escape(format_classes(b.classes) if b.classes else '')}</b> "
            f"<code>{html.escape(b.situation)}</code></li>"
            for b in self.bands[-8:]
        )
        src = html.escape(self.source)
        return (
            f'<div style="font-size:11px">{bar}<div>{src}: {len(self.bands)} situations, '
            f"{t0:.2f}-{t1:.2f} s</div><ul style='margin:2px 0;padding-left:14px'>{rows}</ul></div>"
        )


def status_markdown(
    state: ContactState | None,
    last_class: str,
    *,
    t: float,
    rtf: float,
    paused: bool,
    note: str = "",
) -> str:
    if state is None:
        return "Situation: (starting)"
    fx, fy, fz = state.gripper_force
    run = "paused" if paused else f"running, {rtf:.2f}x real time"
    lines = [
        f"**Discrete:** `{state.discrete.format()}`",
        f"**Topological:** `{state.topological.format()}`",
        f"**Last transition:** `{last_class or '-'}`",
        f"**Gripper force:** {math.hypot(fx, fy, fz):.2f} N ({fx:+.2f}, {fy:+.2f}, {fz:+.2f})",
        f"**Contact force on the cable:** {sum(state.forces):.2f} N",
        f"t = {t:.2f} s, {run}",
    ]
    if note:
        lines.append(f"**{note}**")
    return "\n\n".join(lines)


# --------------------------------------------------------------------------------------------------
# The simulation session (no viser): sim + tracker + recorder + timeline, thread-safe
# --------------------------------------------------------------------------------------------------


class Session:
    """One scene's simulation with its contact tracker, optional recorder and live timeline.

    All methods take ``lock``; :meth:`advance` is what the real-time thread calls.
    """

    def __init__(self, scene: Scene, lock: threading.RLock):
        self.scene = scene
        self.lock = lock
        self.sim = Simulator(scene, track=True)
        self.tracker: ContactTracker = self.sim.tracker
        self.geometry = self.tracker.geometry
        self.recorder: DemoRecorder | None = None
        self.record = self.sim.record()
        self.state = self.tracker.update(self.record)
        self.timeline = Timeline()
        self._kept_seen = 0
        self._last_snap_t = -1.0
        self.note = ""
        self._class_cache: dict[Any, tuple[str, ...]] = {}
        self._format_cache: dict[Any, str] = {}
        self._snapshot()

    @property
    def dt(self) -> float:
        return float(self.sim.model.opt.timestep)

    def last_class(self) -> str:
        for b in reversed(self.timeline.bands):
            if b.classes:
                return format_classes(b.classes)
        return ""

    def advance(self, n: int, target: tuple[np.ndarray, np.ndarray] | None) -> bool:
        """Step ``n`` times toward ``target``; False (and the state restored) if the sim diverged."""
        with self.lock:
            sim = self.sim
            if target is not None:
                sim.set_target(target[0], target[1])
            for _ in range(n):
                good = sim.get_state()
                try:
                    rec = sim.step()
                except SimulationDiverged as e:
                    sim.set_state(good)
                    sim.set_target(
                        sim.data.mocap_pos[sim.built.mocap_id], sim.data.mocap_quat[sim.built.mocap_id]
                    )
                    self.record = sim.record()
                    self.note = f"simulation diverged ({e.reason}); gripper stopped, state restored"
                    return False
                st = rec.state  # the simulator tracks the contacts (track=True)
                if self.recorder is not None:
                    self.recorder.step(rec)
                self.record, self.state = rec, st
            self._timeline_update()
            return True

    def _timeline_update(self) -> None:
        kept = self.tracker.kept
        bands = self.timeline.bands
        grew = len(kept) > self._kept_seen
        start = max(0, min(len(bands), len(kept)) - 2)  # only the last one or two may change
        del bands[start:]
        for i in range(start, len(kept)):
            k = kept[i]
            classes = self._classes(kept[i - 1].situation, k.situation) if i else ()
            bands.append(Band(k.start, k.end, self._format(k.situation), classes))
        self._kept_seen = len(kept)
        if grew or self.record.time - self._last_snap_t >= 0.1:
            self._snapshot()

    def _classes(self, a: Any, b: Any) -> tuple[str, ...]:
        key = (a, b)
        if key not in self._class_cache:
            self._class_cache[key] = tuple(classify_step(a, b))
        return self._class_cache[key]

    def _format(self, sit: Any) -> str:
        if sit not in self._format_cache:
            self._format_cache[sit] = sit.format()
        return self._format_cache[sit]

    def _snapshot(self) -> None:
        r, st = self.record, self.state
        pts = np.asarray(r.points, dtype=float)
        self.timeline.snapshots.append(
            Snapshot(
                r.time,
                pts,
                point_colors(point_classes(st, len(pts))),
                r.gripper_pos.copy(),
                r.gripper_quat.copy(),
                st.discrete.format(),
            )
        )
        self._last_snap_t = r.time

    def restart_timeline(self) -> None:
        self.timeline = Timeline()
        self._kept_seen = 0
        self._last_snap_t = -1.0
        self._snapshot()

    def start_recording(self, path: Path) -> Path:
        with self.lock:
            if self.recorder is not None:
                return self.recorder.path
            path.parent.mkdir(parents=True, exist_ok=True)
            self.recorder = DemoRecorder(path, self.scene, self.sim, self.tracker)
            self.state = self.tracker.current or self.state
            self.restart_timeline()
            return self.recorder.path

    def stop_recording(self) -> Path | None:
        with self.lock:
            rec, self.recorder = self.recorder, None
            return rec.close() if rec is not None else None

    def gripper_pose(self) -> tuple[np.ndarray, np.ndarray]:
        with self.lock:
            d, mid = self.sim.data, self.sim.built.mocap_id
            return d.mocap_pos[mid].copy(), d.mocap_quat[mid].copy()


def recording_timeline(path: str | Path) -> tuple[Timeline, Scene, Any]:
    """Timeline of a recording file (bands from its debounced contact states, cable from its
    Foxglove frames), its embedded scene (loaded from a temporary directory) and the Recording."""
    import tempfile

    from dlovr.recording import load_embedded_scene, situation_from_payload

    rec = Recording(path)
    tmp = tempfile.mkdtemp(prefix="dlovr-ui-")
    scene = load_embedded_scene(rec, tmp)
    kept = kept_states(rec)
    tl = Timeline(source=Path(path).name)
    for i, k in enumerate(kept):
        classes = classify_step(kept[i - 1].situation, k.situation) if i else ()
        tl.bands.append(Band(k.t, k.t + k.duration, k.situation.format(), tuple(classes)))
    states = rec.states()
    st_t = np.array([float(p["t"]) for p in states])
    for t, pts, gp, gq in rec.frames():
        j = max(0, int(np.searchsorted(st_t, t + 1e-9, side="right")) - 1)
        payload = states[j] if states else None
        classes: list[Stability | None] = [None] * len(pts)
        text = ""
        if payload is not None:
            sit = situation_from_payload(payload)
            text = payload.get("discrete", "")
            for c, m_c in zip(sit.contacts, payload.get("contacts", []), strict=False):
                span, cls = m_c.get("span"), c.state.stability_class
                if span and cls is not None:
                    for i in range(max(0, span[0]), min(len(pts) - 1, span[1]) + 1):
                        classes[i] = cls
        tl.snapshots.append(Snapshot(t, pts, point_colors(classes), gp, gq, text))
    return tl, scene, rec


# --------------------------------------------------------------------------------------------------
# The server
# --------------------------------------------------------------------------------------------------


class DemoServer:
    """The ``dlovr serve`` server: ``DemoServer(scene).start()``, then :meth:`stop`.

    ``port=None`` picks a free port. ``recordings_dir`` is where recordings are written (created on
    the first recording). ``realtime=False`` steps as fast as possible (tests, benchmarks).
    """

    def __init__(
        self,
        scene: str | Path = "table",
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
        self.session = Session(load_scene(scene), self.lock)
        self.server: viser.ViserServer | None = None
        self._thread: threading.Thread | None = None
        self._stop = threading.Event()
        self._wake = threading.Event()
        self._paused = False
        self._target: tuple[np.ndarray, np.ndarray] | None = None
        self._target_dirty = False
        self._dragging: dict[int, float | None] = {}  # client id -> drag end time (None: dragging)
        self._draw_lock = threading.RLock()
        self._view: Timeline | None = None  # a timeline being scrubbed (None: live view)
        self._view_scene: Scene | None = None
        self._shown_geometry: Any = None
        self.program_text = ""
        self.last_recording: Path | None = None
        self.publish_count = 0
        self._rtf = 1.0
        self._last_text = ""
        self._compile_thread: threading.Thread | None = None

    # -- lifecycle ----------------------------------------------------------------------------------

    @property
    def port(self) -> int:
        return self.server.get_port() if self.server is not None else self._port_wanted

    @property
    def url(self) -> str:
        host = "127.0.0.1" if self.host in ("0.0.0.0", "::", "") else self.host
        return f"http://{host}:{self.port}"

    def start(self) -> DemoServer:
        srv = viser.ViserServer(host=self.host, port=self._port_wanted, verbose=self.verbose)
        self.server = srv
        srv.gui.configure_theme(show_share_button=False, control_width="large")
        srv.scene.configure_environment_map(None)
        srv.scene.add_light_ambient("/ambient", intensity=1.2)
        srv.scene.add_light_directional("/sun", intensity=1.5, position=(1.0, -1.0, 2.0))
        srv.scene.set_up_direction("+z")
        self._build_gui()
        self._build_scene()
        srv.on_client_connect(self._on_connect)
        srv.on_client_disconnect(self._on_disconnect)
        self._stop.clear()
        self._thread = threading.Thread(target=self._loop, name="dlovr-sim", daemon=True)
        self._thread.start()
        return self

    def stop(self) -> Path | None:
        """Stop the simulation thread, finish any recording (returned) and stop the server."""
        self._stop.set()
        if self._thread is not None:
            self._thread.join(timeout=10)
            self._thread = None
        path = self.session.stop_recording()
        if path is not None:
            self.last_recording = path
        if self._compile_thread is not None:
            self._compile_thread.join(timeout=30)
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
        """Command the gripper pose (what the gizmo does); the sim follows with bounded speed."""
        p = np.asarray(pos, dtype=float)
        q = np.asarray(quat, dtype=float) if quat is not None else self.target()[1]
        self._target = (p, q)
        self._target_dirty = True
        self._wake.set()
        if move_gizmo and self.server is not None:
            self._gizmo.position = tuple(p)
            self._gizmo.wxyz = tuple(q)

    def target(self) -> tuple[np.ndarray, np.ndarray]:
        if self._target is not None:
            return self._target
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

    def pause(self, paused: bool = True) -> None:
        self._paused = paused
        if self.server is not None:
            self._pause_btn.label = "Resume" if paused else "Pause"

    def reset(self) -> None:
        """Restart the current scene (a recording in progress is finished first)."""
        self.load(self.session.scene.path)

    def load(self, scene: str | Path) -> None:
        """Switch to another scene (built-in name or path); finishes a recording in progress."""
        new = Session(load_scene(scene), self.lock)
        with self.lock:
            self._finish_recording()
            self.session = new
            self._target = None
            self._target_dirty = False
            self._view = None
            self._view_scene = None
        if self.server is not None:
            self._build_scene()
            p, q = new.gripper_pose()
            self._gizmo.position, self._gizmo.wxyz = tuple(p), tuple(q)
            self._live_btn.visible = False

    def start_recording(self, path: str | Path | None = None) -> Path:
        if path is None:
            stamp = _dt.datetime.now().strftime("%Y%m%d-%H%M%S")
            path = self.recordings_dir / f"{self.session.scene.name}-{stamp}.mcap"
            k = 1
            while Path(path).exists():
                path = self.recordings_dir / f"{self.session.scene.name}-{stamp}-{k}.mcap"
                k += 1
        out = self.session.start_recording(Path(path))
        if self.server is not None:
            self._rec_md.content = f"Recording to `{out}`"
            self._rec_btn.disabled = True
            self._stop_btn.disabled = False
        return out

    def stop_recording(self, *, wait: bool = True) -> Path | None:
        """Finish the recording; compile it (in a thread) and show the program in the panel."""
        with self.lock:
            path = self._finish_recording()
        if path is not None and wait and self._compile_thread is not None:
            self._compile_thread.join()
        return path

    def _finish_recording(self) -> Path | None:
        path = self.session.stop_recording()
        if path is None:
            return None
        self.last_recording = path
        if self.server is not None:
            self._rec_md.content = f"Saved `{path}`; compiling..."
            self._rec_btn.disabled = False
            self._stop_btn.disabled = True
        self._compile_thread = threading.Thread(target=self._compile, args=(path,), daemon=True)
        self._compile_thread.start()
        return path

    def _compile(self, path: Path) -> None:
        try:
            prog = compile_recording(path)
            text = prog.listing()
            self.program_text = text
            md = f"Saved `{path}`\n\n**Program:**\n\n```\n{text}\n```"
        except Exception as e:  # shown to the user, not raised in a worker thread
            self.program_text = ""
            md = f"Saved `{path}`; compiling failed: {e}"
        if self.server is not None:
            self._rec_md.content = md
            self._program_md.content = md.split("\n\n", 1)[-1] if self.program_text else ""

    def open_recording(self, path: str | Path) -> Timeline:
        """Show a recording's timeline and cable (the live simulation keeps running unseen)."""
        tl, scene, rec = recording_timeline(path)
        with self.lock:
            self._view = tl
            self._view_scene = scene
        if self.server is not None:
            self._show_obstacles(SceneGeometry.from_scene(scene, pieces=rec.pieces), scene)
            self._live_btn.visible = True
            self._update_timeline_gui(force=True)
            self.scrub(tl.start)
        return tl

    def scrub(self, t: float) -> Snapshot | None:
        """Show the cable of the viewed timeline (a recording, or the live one) at time ``t``."""
        with self.lock:
            if self._view is None:
                self._view = self.session.timeline
                self._view_scene = None
            tl = self._view
            snap = tl.at(t)
        if self.server is None or snap is None:
            return snap
        band = tl.band_at(t)
        srv = self.server
        with self._draw_lock, srv.atomic():
            self._draw_cable(snap.points, snap.colors, np.zeros((0, 2, 3)))
            self._body.position, self._body.wxyz = tuple(snap.gripper_pos), tuple(snap.gripper_quat)
            cls = format_classes(band.classes) if band and band.classes else "-"
            self._status_md.content = (
                f"**Timeline ({tl.source}) at {t:.2f} s**\n\n**Discrete:** `{snap.text}`\n\n"
                f"**Transition into it:** `{cls}`"
            )
        srv.flush()
        self._live_btn.visible = True
        return snap

    def live(self) -> None:
        """Back to the live simulation view."""
        with self.lock:
            was_other = self._view_scene is not None
            self._view = None
            self._view_scene = None
        if self.server is not None:
            if was_other:
                self._show_obstacles(self.session.geometry, self.session.scene)
            self._live_btn.visible = False

    def status(self) -> dict[str, Any]:
        with self.lock:
            s = self.session
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
                "paused": self._paused,
                "rtf": self._rtf,
                "kept": len(s.tracker.kept),
            }

    # -- the real-time loop ------------------------------------------------------------------------

    def _loop(self) -> None:
        period = 1.0 / self.publish_hz
        min_period = 1.0 / 60.0  # viser coalesces to ~60 frames/s anyway
        next_pub = last_pub = time.perf_counter()
        anchor_wall = time.perf_counter()
        anchor_steps = 0
        done = 0
        rtf_t, rtf_sim = time.perf_counter(), self.session.record.time
        session = self.session
        kicked = False  # a new target was applied and has not been published yet
        while not self._stop.is_set():
            now = time.perf_counter()
            if session is not self.session or self._paused:
                session = self.session
                anchor_wall, anchor_steps, done = now, 0, 0
            dt = session.dt
            if not self._paused:
                due = int((now - anchor_wall) / dt) - (done - anchor_steps)
                if due > 50:  # more than 0.1 s behind: give up catching up (slower than real time)
                    anchor_wall, anchor_steps = now, done
                    due = 50
                target = None
                if self._target_dirty:
                    self._target_dirty = False
                    target = self._target
                    due = max(due, 1)  # show a new target at once
                # small chunks: publishing and new targets are never held up by a long batch
                n = min(due, 5)
                if n > 0:
                    if not session.advance(n, target):
                        self.pause(True)
                        with contextlib.suppress(Exception):
                            self.hold()
                    done += n
                    kicked = kicked or target is not None
            now = time.perf_counter()
            if now >= next_pub or (kicked and now - last_pub >= min_period):
                if now - rtf_t >= 1.0:
                    self._rtf = (session.record.time - rtf_sim) / (now - rtf_t)
                    rtf_t, rtf_sim = now, session.record.time
                try:
                    self._publish()
                except Exception as e:  # keep the simulation alive whatever a publish does
                    if self.verbose:
                        print(f"dlovr serve: publish failed: {e!r}")
                last_pub = now
                kicked = False
                if now >= next_pub:  # on schedule
                    next_pub = next_pub + period if next_pub + period > now else now + period
                else:  # early, for a new target: keep the schedule
                    next_pub = max(next_pub, now + min_period)
            next_step = anchor_wall + (done - anchor_steps + 4) * dt
            pub_at = min(next_pub, last_pub + min_period) if kicked else next_pub
            wait = min(pub_at, next_step) - time.perf_counter()
            if wait > 0:
                self._wake.wait(wait)
                self._wake.clear()

    def _publish(self) -> None:
        srv = self.server
        if srv is None:
            return
        with self.lock:
            s = self.session
            rec, st = s.record, s.state
            text = status_markdown(
                st, s.last_class(), t=rec.time, rtf=self._rtf, paused=self._paused, note=s.note
            )
            viewing = self._view is not None
        if not viewing:
            pts = np.asarray(rec.points, dtype=float)
            colors = point_colors(point_classes(st, len(pts)))
            arrows = contact_arrows(st, pts)
            with self._draw_lock, srv.atomic():
                if self._view is not None:
                    return
                self._draw_cable(pts, colors, arrows)
                self._body.position = tuple(map(float, rec.gripper_pos))
                self._body.wxyz = tuple(map(float, rec.gripper_quat))
                if text != self._last_text:
                    self._status_md.content = text
                    self._last_text = text
            srv.flush()
            self.publish_count += 1
        self._update_timeline_gui()

    # -- drawing ------------------------------------------------------------------------------------

    def _draw_cable(self, pts: np.ndarray, colors: np.ndarray, arrows: np.ndarray) -> None:
        r = (
            float(self.session.scene.dlo.radius)
            if self._view_scene is None
            else float(self._view_scene.dlo.radius)
        )
        pos, wxyz, scales = segment_transforms(pts, r)
        seg_colors = np.where(
            (colors[:-1] != np.array(COLOR_FREE)).any(axis=1)[:, None], colors[:-1], colors[1:]
        ).astype(np.uint8)
        n = len(pos)
        if self._cable is None or self._cable_n != n:
            self._make_cable(n, r)
        cable, joints = self._cable, self._joints
        cable.batched_positions = pos.astype(np.float32)
        cable.batched_wxyzs = wxyz.astype(np.float32)
        cable.batched_scales = scales.astype(np.float32)
        cable.batched_colors = seg_colors
        joints.batched_positions = np.asarray(pts, dtype=np.float32)
        joints.batched_colors = colors
        if len(arrows):
            self._arrows = self.server.scene.add_arrows(
                "/contacts/vectors",
                points=arrows,
                colors=(30, 60, 220),
                shaft_radius=0.002,
                head_radius=0.006,
                head_length=0.012,
            )
        elif self._arrows is not None:
            self._arrows.remove()
            self._arrows = None

    def _make_cable(self, n: int, r: float) -> None:
        srv = self.server
        cyl = trimesh.creation.cylinder(radius=1.0, height=1.0, sections=12)
        ball = trimesh.creation.icosphere(subdivisions=1, radius=1.0)
        z = np.zeros((n, 3), dtype=np.float32)
        q = np.tile(np.array([1.0, 0, 0, 0], dtype=np.float32), (n, 1))
        self._cable = srv.scene.add_batched_meshes_simple(
            "/cable/tube",
            cyl.vertices,
            cyl.faces,
            batched_wxyzs=q,
            batched_positions=z,
            batched_scales=np.ones((n, 3), dtype=np.float32),
            batched_colors=COLOR_FREE,
            lod="off",
        )
        self._joints = srv.scene.add_batched_meshes_simple(
            "/cable/points",
            ball.vertices,
            ball.faces,
            batched_wxyzs=np.tile(np.array([1.0, 0, 0, 0], dtype=np.float32), (n + 1, 1)),
            batched_positions=np.zeros((n + 1, 3), dtype=np.float32),
            batched_scales=np.full(n + 1, 1.15 * r, dtype=np.float32),
            batched_colors=COLOR_FREE,
            lod="off",
        )
        self._cable_n = n

    def _show_obstacles(self, geometry: SceneGeometry, scene: Scene) -> None:
        with self._draw_lock:
            self._show_obstacles_locked(geometry, scene)

    def _show_obstacles_locked(self, geometry: SceneGeometry, scene: Scene) -> None:
        srv = self.server
        for h in self._obstacle_handles:
            h.remove()
        self._obstacle_handles = []
        colors = {o.name: o.color for o in scene.objects}
        for obj in geometry.objects:
            c = colors.get(obj.name)
            rgb = tuple(int(255 * x) for x in c) if c else (150, 155, 170)
            self._obstacle_handles.append(
                srv.scene.add_mesh_simple(
                    f"/obstacles/{obj.name}",
                    np.asarray(obj.mesh.vertices, dtype=np.float32),
                    np.asarray(obj.mesh.faces, dtype=np.uint32),
                    color=rgb,
                    flat_shading=True,
                )
            )
            if self._labels_cb.value:
                for name, tris, normal in zip(obj.face_names, obj.face_tris, obj.face_normals, strict=True):
                    tris = np.asarray(tris, dtype=float)
                    area = np.linalg.norm(np.cross(tris[:, 1] - tris[:, 0], tris[:, 2] - tris[:, 0]), axis=1)
                    c3 = (tris.mean(axis=1) * area[:, None]).sum(axis=0) / max(area.sum(), 1e-12)
                    self._obstacle_handles.append(
                        srv.scene.add_label(
                            f"/obstacles/{obj.name}_labels/{name}",
                            name,
                            position=tuple(c3 + 0.01 * np.asarray(normal)),
                        )
                    )
        self._shown_geometry = geometry

    def _build_scene(self) -> None:
        with self._draw_lock:
            self._build_scene_locked()

    def _build_scene_locked(self) -> None:
        s = self.session
        lo = np.min([o.mesh.bounds[0] for o in s.geometry.objects] + [s.record.points.min(axis=0)], axis=0)
        hi = np.max([o.mesh.bounds[1] for o in s.geometry.objects] + [s.record.points.max(axis=0)], axis=0)
        center = (lo + hi) / 2.0
        size = float(max(np.linalg.norm(hi - lo), 0.3))
        cam = self.server.initial_camera
        cam.look_at = tuple(center)
        cam.position = tuple(center + size * np.array([0.55, -0.8, 0.45]))
        self._cable = None
        self._cable_n = -1
        self._arrows = None
        self._show_obstacles(s.geometry, s.scene)
        p, q = s.gripper_pose()
        srv = self.server
        self._body = srv.scene.add_frame("/gripper_body", show_axes=False, position=tuple(p), wxyz=tuple(q))
        srv.scene.add_box(
            "/gripper_body/box", dimensions=(0.03, 0.03, 0.04), color=(70, 70, 85), position=(0.0, 0.0, 0.021)
        )
        self._draw_cable(
            np.asarray(s.record.points),
            point_colors(point_classes(s.state, len(s.record.points))),
            np.zeros((0, 2, 3)),
        )
        self._update_timeline_gui(force=True)

    def _build_gui(self) -> None:
        srv = self.server
        gui = srv.gui
        s = self.session
        p, q = s.gripper_pose()
        self._obstacle_handles: list[Any] = []
        self._gizmo = srv.scene.add_transform_controls(
            "/gripper", scale=0.15, position=tuple(p), wxyz=tuple(q)
        )

        @self._gizmo.on_update
        async def _(event: Any) -> None:
            if event.phase == "start" and event.client_id is not None:
                self._dragging[event.client_id] = None
            elif event.phase == "end":
                # viser sends a synthetic "end" just before the disconnect callbacks of a tab that
                # goes away mid-drag: remember when, so _on_disconnect can tell
                if event.client_id is not None:
                    self._dragging[event.client_id] = time.perf_counter()
                return
            if event.phase == "update":
                g = event.target
                self.set_target(
                    np.array(g.position, dtype=float), np.array(g.wxyz, dtype=float), move_gizmo=False
                )

        self._status_md = gui.add_markdown("Situation: (starting)")
        with gui.add_folder("Recording"):
            self._rec_btn = gui.add_button("Start recording", icon=viser.Icon.PLAYER_RECORD)
            self._stop_btn = gui.add_button("Stop recording", icon=viser.Icon.PLAYER_STOP, disabled=True)
            self._rec_md = gui.add_markdown(f"Recordings go to `{self.recordings_dir}/`")
            self._program_md = gui.add_markdown("")
        self._rec_btn.on_click(lambda _e: self.start_recording())
        self._stop_btn.on_click(lambda _e: self.stop_recording(wait=False))

        with gui.add_folder("Timeline"):
            self._timeline_html = gui.add_html("")
            self._slider = gui.add_slider("Time [s]", min=0.0, max=1.0, step=0.01, initial_value=0.0)
            self._live_btn = gui.add_button("Back to live", visible=False)
            self._open_dd = gui.add_dropdown("Recording file", options=self._recording_files())
            self._open_btn = gui.add_button("Open recording")
            self._open_md = gui.add_markdown("")

        @self._slider.on_update
        def _(event: Any) -> None:
            if event.client is not None:
                self.scrub(float(self._slider.value))

        self._live_btn.on_click(lambda _e: self.live())

        @self._open_btn.on_click
        def _(_e: Any) -> None:
            name = self._open_dd.value
            if not name:
                self._open_md.content = "no recording selected"
                return
            try:
                tl = self.open_recording(self.recordings_dir / name)
                self._open_md.content = f"opened `{name}`: {len(tl.bands)} situations"
            except (RecordingError, SceneError, OSError) as e:
                self._open_md.content = f"cannot open: {e}"

        with gui.add_folder("Simulation"):
            self._pause_btn = gui.add_button("Pause")
            reset_btn = gui.add_button("Reset")
            names = [n for n, _ in builtin_scenes()]
            cur = s.scene.name if s.scene.name in names else None
            self._scene_dd = gui.add_dropdown(
                "Scene", options=names if cur else [s.scene.name, *names], initial_value=s.scene.name
            )
            self._labels_cb = gui.add_checkbox("Face labels", initial_value=False)
            gui.add_markdown(
                "Drag the gizmo to move the gripper. Keys: J/L x, I/K y, U/O z, "
                "N/M yaw, P pause (5 mm / 5° a press)."
            )
        self._pause_btn.on_click(lambda _e: self.pause(not self._paused))
        reset_btn.on_click(lambda _e: self.reset())

        @self._scene_dd.on_update
        def _(event: Any) -> None:
            if event.client is None or self._scene_dd.value == self.session.scene.name:
                return
            try:
                self.load(self._scene_dd.value)
            except (SceneError, ValueError) as e:
                self._open_md.content = f"cannot load scene: {e}"

        @self._labels_cb.on_update
        def _(_e: Any) -> None:
            sc = self._view_scene or self.session.scene
            geo = self._shown_geometry or self.session.geometry
            self._show_obstacles(geo, sc)

        jogs: list[tuple[str, str, Callable[[], None]]] = [
            ("Jog -x", "J", lambda: self.jog(dx=-JOG_STEP)),
            ("Jog +x", "L", lambda: self.jog(dx=JOG_STEP)),
            ("Jog +y", "I", lambda: self.jog(dy=JOG_STEP)),
            ("Jog -y", "K", lambda: self.jog(dy=-JOG_STEP)),
            ("Jog +z", "U", lambda: self.jog(dz=JOG_STEP)),
            ("Jog -z", "O", lambda: self.jog(dz=-JOG_STEP)),
            ("Yaw +", "N", lambda: self.jog(yaw=JOG_ANGLE)),
            ("Yaw -", "M", lambda: self.jog(yaw=-JOG_ANGLE)),
            ("Pause / resume", "P", lambda: self.pause(not self._paused)),
        ]
        for label, key, fn in jogs:
            cmd = gui.add_command(label, hotkey=key)  # type: ignore[arg-type]
            cmd.on_trigger(lambda _e, fn=fn: fn())

    def _recording_files(self) -> list[str]:
        d = self.recordings_dir
        files = sorted((p.name for p in d.glob("*.mcap")), reverse=True) if d.is_dir() else []
        return files or [""]

    def _update_timeline_gui(self, force: bool = False) -> None:
        tl = self._view or self.session.timeline
        key = (id(tl), len(tl.bands), round(tl.end))
        if not force and key == getattr(self, "_tl_key", None):
            return
        self._tl_key = key
        self._timeline_html.content = tl.html()
        self._slider.min = round(tl.start, 2)
        self._slider.max = round(max(tl.end, tl.start + 0.01), 2)
        files = self._recording_files()
        if tuple(files) != tuple(self._open_dd.options):
            self._open_dd.options = files

    # -- clients ------------------------------------------------------------------------------------

    def _on_connect(self, client: Any) -> None:
        pass

    def _on_disconnect(self, client: Any) -> None:
        ended = self._dragging.pop(client.client_id, -1.0)
        if self._stop.is_set():  # the server is stopping (it disconnects everyone): nothing to hold
            return
        if ended is None or (ended >= 0 and time.perf_counter() - ended < 1.0):
            self.hold()  # it went away mid-drag: the gripper stays where it is now


def serve(scene: str, host: str = "127.0.0.1", port: int = 8080, recordings_dir: str = "recordings") -> None:
    """Run the server until Ctrl-C (used by ``dlovr serve``)."""
    srv = DemoServer(scene, host=host, port=port, recordings_dir=recordings_dir).start()
    print(f"dlovr serve: scene {srv.session.scene.name} at {srv.url}  (Ctrl-C to stop)", flush=True)
    try:
        while True:
            time.sleep(0.5)
    except KeyboardInterrupt:
        pass
    finally:
        path = srv.stop()
        if path is not None:
            print(f"dlovr serve: finished recording {path}", flush=True)
        print("dlovr serve: stopped", flush=True)
