"""Writing recordings: :class:`Recorder` (the MCAP file) and :class:`DemoRecorder` (a running
demonstration, step by step); see :mod:`dlovr.recording.format` for what a file holds."""

from __future__ import annotations

import hashlib
import os
import signal
import time
from collections.abc import Iterator, Mapping, Sequence
from contextlib import contextmanager
from pathlib import Path
from typing import Any, BinaryIO

import numpy as np
from mcap.writer import CompressionType, Writer

from dlovr import __version__, signals
from dlovr.model.transitions import DEFAULT_HOLD_S, classify_step
from dlovr.outputs import StreamOutput
from dlovr.plausibility import monitor_of
from dlovr.recording import foxglove
from dlovr.recording.bundle import SceneBundle, pieces_to_json
from dlovr.recording.format import (
    CHANNELS,
    CHECKPOINT_SCHEMA,
    COMMAND_BATCH,
    COMMAND_SCHEMA,
    FORMAT_VERSION,
    PIECES_JSON,
    PROFILE,
    SCENE_PREFIX,
    SCENE_TOML,
    STATES_SCHEMA,
    TOPIC_CHECKPOINT,
    TOPIC_COMMAND,
    TOPIC_SCENE,
    TOPIC_STATES,
    TOPIC_TF,
    TOPIC_WARNINGS,
    TOPIC_WRENCH,
    WARNING_SCHEMA,
    WRENCH_EVERY,
    WRENCH_SCHEMA,
    dumps,
    floats,
)


def schemas() -> dict[str, bytes]:
    """The JSON schemas of the channels' message types, by name (see :data:`CHANNELS`)."""
    own = {
        "dlovr.Commands": COMMAND_SCHEMA,
        "dlovr.Checkpoint": CHECKPOINT_SCHEMA,
        "dlovr.ContactState": STATES_SCHEMA,
        "dlovr.Wrench": WRENCH_SCHEMA,
        "dlovr.Warning": WARNING_SCHEMA,
    }
    return {name: dumps(own[name]) if name in own else foxglove.schema(name) for _, name in CHANNELS}


@contextmanager
def finish_on_sigterm() -> Iterator[None]:
    """Turn SIGTERM into ``SystemExit`` (:class:`dlovr.signals.SignalExit`, exit 143) while inside, so
    ``with Recorder(...)`` finishes the file."""
    with signals.installed((signal.SIGTERM,)):
        yield


class StopSignals:
    """SIGINT (Ctrl-C) and SIGTERM while inside ``with StopSignals() as stop:`` do not interrupt: they
    set ``stop.signum``, so that a recording loop ends between two steps (check ``stop.signum`` after
    each) and finishes its file with the last step's command, contact states and checkpoint all
    written (such a file replays and verifies). ``stop.exit_code`` is the conventional exit status
    (128 + signal number: 130 for SIGINT, 143 for SIGTERM). A signal that came before (and that a
    dependency swallowed, :mod:`dlovr.signals`) is taken as the first request: the loop stops at
    once. Outside the main thread nothing is installed.
    """

    SIGNALS = signals.SIGNALS

    def __init__(self) -> None:
        self.signum: int | None = None
        self._previous: dict[int, Any] = {}

    @property
    def exit_code(self) -> int:
        return signals.exit_code(self.signum or 0)

    @property
    def name(self) -> str:
        return signals.name(self.signum) if self.signum else ""

    def _handle(self, signum: int, _frame: object) -> None:
        if self.signum is None:
            self.signum = signum

    def __enter__(self) -> StopSignals:
        try:
            for sig in self.SIGNALS:
                self._previous[sig] = signal.signal(sig, self._handle)
        except ValueError:  # not the main thread
            pass
        if self._previous and self.signum is None:
            self.signum = signals.clear()  # one that came before: handled here
        return self

    def __exit__(self, *exc: object) -> None:
        for sig, previous in self._previous.items():
            signal.signal(sig, previous)
        self._previous.clear()


class Recorder:
    """Writes one demonstration to an MCAP file (see :mod:`dlovr.recording.format` for its contents).

    Use as a context manager: the file is finished on normal exit and on exceptions (and on SIGTERM
    inside :func:`finish_on_sigterm`). A new file is created exclusively (two writers never share
    one); an existing one is refused without ``overwrite``, else written beside it and renamed over
    it when finished (:class:`dlovr.outputs.StreamOutput`). Each :meth:`checkpoint` ends the chunks
    in progress, so that a killed writer's file is recovered up to its last checkpoint (``dlovr
    recover``); the file is also flushed and synced to disk every ``flush_interval`` seconds of wall
    time. The data section carries a CRC, so readers detect any changed byte.
    """

    def __init__(
        self,
        path: str | Path,
        scene: SceneBundle,
        *,
        scene_name: str,
        dt: float,
        extra_metadata: Mapping[str, str] | None = None,
        flush_interval: float = 2.0,
        frame_rate: float = 30.0,
        t0_ns: int | None = None,
        pieces: Mapping[str, tuple[Sequence[np.ndarray], bool]] | None = None,
        overwrite: bool = False,
    ):
        self.path = Path(path)
        self.dt = float(dt)
        self.dt_ns = round(self.dt * 1e9)
        self.t0_ns = time.time_ns() if t0_ns is None else int(t0_ns)
        self.flush_interval = float(flush_interval)
        self.frame_every = max(1, round(1.0 / (frame_rate * self.dt)))
        self._out = StreamOutput(self.path, overwrite=overwrite)  # exclusive; beside an existing file
        self._fh: BinaryIO = self._out.fh
        self._closed = False
        try:
            self._start(scene, scene_name, extra_metadata, pieces)
        except BaseException:
            self.discard()
            raise

    def _start(
        self,
        scene: SceneBundle,
        scene_name: str,
        extra_metadata: Mapping[str, str] | None,
        pieces: Mapping[str, tuple[Sequence[np.ndarray], bool]] | None,
    ) -> None:
        """The file's header: metadata, the embedded scene, schemas and channels."""
        import mujoco

        self._w = Writer(
            self._fh, chunk_size=1 << 20, compression=CompressionType.ZSTD, enable_data_crcs=True
        )
        self._w.start(profile=PROFILE, library=f"dlovr {__version__}")
        pieces_json = pieces_to_json(pieces) if pieces is not None else b""
        meta = {
            "pieces_sha256": hashlib.sha256(pieces_json).hexdigest() if pieces is not None else "",
            "format_version": FORMAT_VERSION,
            "dlovr_version": __version__,
            "mujoco_version": mujoco.__version__,
            "scene_name": scene_name,
            "scene_sha256": scene.digest,
            "timestep": repr(self.dt),
            "t0_ns": str(self.t0_ns),
            "hold": repr(DEFAULT_HOLD_S),
            **dict(extra_metadata or {}),
        }
        self._w.add_metadata("dlovr", meta)
        now = self.t0_ns
        self._w.add_attachment(now, now, SCENE_TOML, "application/toml", scene.toml)
        if pieces is not None:
            self._w.add_attachment(now, now, PIECES_JSON, "application/json", pieces_json)
        for name, data in scene.files:
            self._w.add_attachment(now, now, SCENE_PREFIX + name, "application/octet-stream", data)
        sids = {name: self._w.register_schema(name, "jsonschema", data) for name, data in schemas().items()}
        self._ch = {topic: self._w.register_channel(topic, "json", sids[name]) for topic, name in CHANNELS}
        self._pending_states: list[tuple[int, bytes]] = []
        self._wrench: list[tuple[int, float, list[float], list[float]]] = []
        self._wrench_every = WRENCH_EVERY
        self._commands: list[tuple[int, list[float], list[float]]] = []
        self._seq = 0
        self._last_flush = time.monotonic()
        self._w.flush()

    # -- messages -----------------------------------------------------------------------------------

    def _ns(self, step: int) -> int:
        return self.t0_ns + int(step) * self.dt_ns

    def _add(self, topic: str, step: int, payload: bytes) -> None:
        self._seq += 1
        ns = self._ns(step)
        self._w.add_message(self._ch[topic], ns, payload, ns, self._seq)

    def add_channel(self, topic: str, schema_name: str, schema: Mapping[str, Any]) -> None:
        """Register an extra JSON channel ``topic`` (its JSON schema ``schema`` named ``schema_name``),
        e.g. the executor events of a recorded program run; readers ignore channels they do not know."""
        if topic in self._ch:
            raise ValueError(f"channel {topic} already exists")
        sid = self._w.register_schema(schema_name, "jsonschema", dumps(dict(schema)))
        self._ch[topic] = self._w.register_channel(topic, "json", sid)

    def message(self, step: int, topic: str, payload: Mapping[str, Any]) -> None:
        """One JSON message on a channel of :meth:`add_channel`, logged at step ``step``."""
        if topic not in self._ch or any(topic == t for t, _ in CHANNELS):
            raise ValueError(f"no extra channel {topic} (register it with add_channel)")
        self._add(topic, step, dumps(dict(payload)))

    def command(
        self, step: int, pos: Sequence[float] | np.ndarray, quat: Sequence[float] | np.ndarray
    ) -> None:
        """The gripper target commanded for step ``step`` (applied before that step); steps come in
        order, written in messages of :data:`COMMAND_BATCH` steps."""
        c = self._commands
        if c and int(step) != c[0][0] + len(c):
            raise ValueError(f"command for step {step} out of order (expected {c[0][0] + len(c)})")
        c.append((int(step), floats(pos), floats(quat)))
        if len(c) >= COMMAND_BATCH:
            self._write_commands()
        self._maybe_flush()

    def _write_commands(self) -> None:
        c = self._commands
        if c:
            payload = {"step": c[0][0], "pos": [x[1] for x in c], "quat": [x[2] for x in c]}
            self._add(TOPIC_COMMAND, c[0][0], dumps(payload))
            c.clear()

    def checkpoint(
        self, step: int, state: np.ndarray, target_pos: Sequence[float], target_quat: Sequence[float]
    ) -> None:
        """A full simulator state after ``step`` steps; give the command of ``step`` and the contact
        states up to it first.

        A checkpoint ends the chunks in progress: when it returns, the commands, contact states and
        frames up to ``step`` and then the checkpoint (in a chunk of its own) are in the file. So a
        file whose writer was killed is consistent up to its last checkpoint (``dlovr recover``).
        """
        payload = {
            "step": int(step),
            "state": floats(state),
            "target_pos": floats(target_pos),
            "target_quat": floats(target_quat),
        }
        self._write_commands()
        self._write_states()
        self._w.flush()
        self._add(TOPIC_CHECKPOINT, step, dumps(payload))
        self._w.flush()  # also hands the bytes to the OS: a killed process loses none of them
        self._maybe_flush()

    def contact_state(self, step: int, payload: Mapping[str, Any]) -> None:
        """A contact situation that began at ``step`` (buffered; written in chunks of its own)."""
        self._pending_states.append((int(step), dumps(dict(payload))))

    def wrench(self, step: int, t: float, force: Sequence[float], torque: Sequence[float]) -> None:
        """The gripper's wrench sensed at ``step`` (simulated time ``t`` s; force N, torque N m, world
        frame); buffered and written with the contact states, in chunks of their own."""
        self._wrench.append((int(step), float(t), floats(force), floats(torque)))

    def _write_wrench(self) -> None:
        w = self._wrench
        if w:
            payload = {
                "step": w[0][0],
                "every": self._wrench_every,
                "t": [x[1] for x in w],
                "force": [x[2] for x in w],
                "torque": [x[3] for x in w],
            }
            self._add(TOPIC_WRENCH, w[0][0], dumps(payload))
            w.clear()

    def warning(self, step: int, payload: Mapping[str, Any]) -> None:
        """A plausibility warning (:class:`dlovr.plausibility.Implausible`) that began at ``step``."""
        self._add(TOPIC_WARNINGS, step, dumps(dict(payload)))

    def frame(
        self,
        step: int,
        points: np.ndarray,
        gripper_pos: Sequence[float],
        gripper_quat: Sequence[float],
        radius: float,
        obstacles: Sequence[tuple[str, np.ndarray]] = (),
    ) -> None:
        """Foxglove scene (cable, gripper, and on the first call the obstacles) and gripper frame.

        ``obstacles``: (name, triangles (k, 3, 3) world frame) pairs, sent once (they persist).
        """
        st = foxglove.timestamp(self._ns(step))
        scene = foxglove.scene_update(st, points, radius, obstacles)
        tf = foxglove.frame_transforms(st, gripper_pos, gripper_quat)
        self._add(TOPIC_SCENE, step, dumps(scene))
        self._add(TOPIC_TF, step, dumps(tf))

    # -- flushing and closing -----------------------------------------------------------------------

    def _write_states(self) -> None:
        """End the bulk chunk, write the buffered contact states, end their chunk; the same for the
        buffered wrench samples (one message, a chunk of its own)."""
        if self._pending_states:
            self._w.flush()
            for step, payload in self._pending_states:
                self._add(TOPIC_STATES, step, payload)
            self._pending_states.clear()
            self._w.flush()
        if self._wrench:
            self._w.flush()
            self._write_wrench()
            self._w.flush()

    def flush(self) -> None:
        """Write everything so far to disk (complete chunks that ``dlovr recover`` can rescue)."""
        self._write_commands()
        self._write_states()
        self._w.flush()
        os.fsync(self._fh.fileno())
        self._last_flush = time.monotonic()

    def _maybe_flush(self) -> None:
        if time.monotonic() - self._last_flush >= self.flush_interval:
            self.flush()

    @property
    def closed(self) -> bool:
        return self._closed

    def discard(self) -> None:
        """Give the file up unfinished and remove it (a recording that failed as it started: nothing
        was recorded); a file it was to replace stays as it was."""
        if not self._closed:
            self._closed = True
            self._out.discard()

    def close(self) -> None:
        """Finish the file (summary and footer). Safe to call twice."""
        if self._closed:
            return
        self._closed = True
        try:
            self._write_commands()
            self._write_states()
            self._w.finish()
        except BaseException:
            self._out.abandon()  # a file written beside an existing one is removed, that one kept
            raise
        self._out.commit()

    def __enter__(self) -> Recorder:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()


CHECKPOINT_EVERY_S = 1.0


class DemoRecorder:
    """Records a running demonstration: call :meth:`step` after every simulation step.

    ``sim`` is a :class:`dlovr.sim.Simulator`, ``tracker`` its :class:`dlovr.sim.tracker.ContactTracker`;
    the scene is embedded from ``scene.path``, or from ``bundle`` (a :class:`SceneBundle`) when given
    (a scene that exists only in memory, e.g. a perturbed one). The first checkpoint is written at
    construction (so a recording may start at any moment of a session), then one every second of
    simulated time.
    """

    def __init__(self, path: str | Path, scene: Any, sim: Any, tracker: Any, **kw: Any):
        dt = float(sim.model.opt.timestep)
        self.sim, self.tracker = sim, tracker
        meta = {
            "hold": repr(float(tracker.hold)),
            "flight": repr(float(tracker.flight)),
            **dict(kw.pop("extra_metadata", None) or {}),
        }
        bundle = kw.pop("bundle", None) or SceneBundle.from_path(scene.path)
        self.rec = Recorder(
            path, bundle, scene_name=scene.name, dt=dt, extra_metadata=meta, pieces=sim.pieces, **kw
        )
        self.path = self.rec.path
        #: Why the demonstration ended early (e.g. the simulation diverged), written in the end marker.
        self.end_reason: str | None = None
        self.start_step = int(sim.step_index)
        self._cp_every = max(1, round(CHECKPOINT_EVERY_S / dt))
        self._radius = float(scene.dlo.radius)
        self._obstacles = [(o.name, np.asarray(o.mesh.triangles)) for o in tracker.geometry.objects]
        try:
            self._checkpoint()
            #: The simulation's plausibility (docs/recordings.md): its episodes are written as warnings.
            self.plausibility = monitor_of(sim)
            start = tracker.restart(sim.record())  # replay restarts the same way from the checkpoint
            self._prev = start.discrete
            self._n_changes = len(tracker.changes)
            self.rec.contact_state(self.start_step, start.payload())
        except BaseException:
            self.rec.discard()  # no unfinished file left behind (e.g. a state that is not finite)
            raise

    @property
    def duration(self) -> float:
        """Simulated time recorded so far (s)."""
        return (int(self.sim.step_index) - self.start_step) * self.rec.dt

    def _checkpoint(self) -> None:
        st = self.sim.get_state()
        self.rec.checkpoint(st.step, st.mj, st.target_pos, st.target_quat)

    def step(self, record: Any) -> None:
        """Log the step just taken (its command, and on schedule checkpoints, states and frames)."""
        k = int(record.step)
        self.rec.command(k, record.target_pos, record.target_quat)
        if (k - self.start_step) % WRENCH_EVERY == 0:
            self.rec.wrench(k, record.time, record.gripper_force, record.gripper_torque)
        for ep in self.plausibility.update(record):
            self.rec.warning(ep.step, ep.payload())
        for st in self.tracker.changes[self._n_changes :]:
            classes = classify_step(self._prev, st.discrete) if self._prev is not None else ()
            self.rec.contact_state(st.step, st.payload(classes))
            self._prev = st.discrete
        self._n_changes = len(self.tracker.changes)
        since = k - self.start_step
        if since % self._cp_every == 0:
            self._checkpoint()
        if since % self.rec.frame_every == 0:
            first = since == self.rec.frame_every
            self.rec.frame(
                k, record.points, record.gripper_pos, record.gripper_quat, self._radius,
                self._obstacles if first else (),
            )

    def close(self) -> Path:
        """Finish the file (with a final checkpoint at the last step); return its path. Idempotent."""
        if not self.rec.closed:
            if (int(self.sim.step_index) - self.start_step) % self._cp_every:
                self._checkpoint()
            for ep in self.plausibility.finish():
                self.rec.warning(ep.step, ep.payload())
            cur = self.tracker.current
            if cur is not None:  # where the recording ends (the situation it ends in, unchanged)
                end = {
                    **cur.payload(),
                    "step": int(self.sim.step_index),
                    "t": float(self.sim.time),
                    "end": True,
                    **({"end_reason": self.end_reason} if self.end_reason else {}),
                }
                self.rec.contact_state(int(self.sim.step_index), end)
            self.rec.close()
        return self.path

    def __enter__(self) -> DemoRecorder:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()
