"""Demonstration recordings as MCAP files: writing, reading, validation, recovery.

A recording holds everything needed to replay a demonstration with nothing else:

- the scene (its TOML and meshes) as attachments, with a content hash in the metadata;
- software versions (dlovr, mujoco) and the time step as metadata;
- ``/dlovr/command``: the gripper command (target pose) of every step, 50 steps a message;
- ``/dlovr/checkpoint``: full simulator states (``mjSTATE_INTEGRATION``) at the start and every second;
- ``/dlovr/contact_states``: the contact situations (topological, discrete, forces, transitions) each
  time they change, written in chunks of their own so batch readers skip the bulk data;
- ``/foxglove/scene`` (``foxglove.SceneUpdate``) and ``/tf`` (``foxglove.FrameTransforms``) at ~30 Hz
  so that Foxglove can show the cable, the gripper and the obstacles.

Timestamps are ``t0_ns + step * dt_ns`` (uint64 ns). Messages are JSON; floats are written with
Python's shortest round-trip repr, so states and commands come back bit for bit.
"""

from __future__ import annotations

import hashlib
import io
import json
import math
import os
import signal
import time
import tomllib
from collections.abc import Iterator, Mapping, Sequence
from contextlib import contextmanager
from dataclasses import dataclass
from importlib import resources
from pathlib import Path, PurePosixPath
from typing import Any, BinaryIO

import numpy as np
from mcap.exceptions import McapError
from mcap.reader import make_reader
from mcap.stream_reader import StreamReader
from mcap.writer import CompressionType, Writer

from dlovr import __version__
from dlovr.model.transitions import DEFAULT_HOLD_S, classify_step

FORMAT_VERSION = "2"  # 2: commands in messages of 50 steps, an end marker in the states
PROFILE = "dlovr"
TOPIC_COMMAND = "/dlovr/command"
TOPIC_CHECKPOINT = "/dlovr/checkpoint"
TOPIC_STATES = "/dlovr/contact_states"
TOPIC_SCENE = "/foxglove/scene"
TOPIC_TF = "/tf"
REQUIRED_TOPICS = (TOPIC_COMMAND, TOPIC_CHECKPOINT, TOPIC_STATES)
SCENE_PREFIX = "scene/"
SCENE_TOML = "scene/scene.toml"
PIECES_JSON = "model/pieces.json"
MAX_ATTACHMENT_BYTES = 64 * 1024 * 1024


class RecordingError(ValueError):
    """A recording cannot be used; the message names the file and the problem in one line."""


# --------------------------------------------------------------------------------------------------
# The embedded scene
# --------------------------------------------------------------------------------------------------


def _safe_relpath(name: str) -> PurePosixPath:
    p = PurePosixPath(name)
    if p.is_absolute() or not p.parts or any(part in ("..", "") for part in p.parts) or "\\" in name:
        raise RecordingError(f"unsafe file name {name!r} in the embedded scene")
    return p


@dataclass(frozen=True)
class SceneBundle:
    """A scene file and the mesh files it names, as bytes (paths relative to the scene file)."""

    toml: bytes
    files: tuple[tuple[str, bytes], ...] = ()

    @classmethod
    def from_path(cls, path: str | Path) -> SceneBundle:
        """Read a scene TOML and the meshes its ``[[objects]]`` name (``mesh = "…"``)."""
        path = Path(path)
        raw = path.read_bytes()
        data = tomllib.loads(raw.decode("utf-8"))
        files = []
        for obj in data.get("objects", []):
            mesh = obj.get("mesh") if isinstance(obj, dict) else None
            if isinstance(mesh, str):
                rel = _safe_relpath(mesh)
                files.append((str(rel), (path.parent / rel).read_bytes()))
        return cls(raw, tuple(sorted(set(files))))

    @property
    def digest(self) -> str:
        """sha256 over the TOML and every file (name and content)."""
        h = hashlib.sha256()
        h.update(b"scene.toml\0" + self.toml)
        for name, data in self.files:
            h.update(b"\0" + name.encode() + b"\0" + hashlib.sha256(data).digest())
        return h.hexdigest()

    def materialize(self, directory: str | Path) -> Path:
        """Write the scene into ``directory`` (only the embedded files); return the TOML's path."""
        root = Path(directory)
        for name, data in self.files:
            dst = root / _safe_relpath(name)
            dst.parent.mkdir(parents=True, exist_ok=True)
            dst.write_bytes(data)
        out = root / "scene.toml"
        out.write_bytes(self.toml)
        return out


def pieces_to_json(pieces: Mapping[str, tuple[Sequence[np.ndarray], bool]]) -> bytes:
    """The obstacles' convex decomposition as JSON (floats written exactly)."""
    data = {
        name: {"approximate": bool(approx), "pieces": [np.asarray(p, dtype=float).tolist() for p in ps]}
        for name, (ps, approx) in pieces.items()
    }
    return json.dumps(data, allow_nan=False).encode()


def pieces_from_json(raw: bytes) -> dict[str, tuple[list[np.ndarray], bool]]:
    """Parse and check :func:`pieces_to_json` output (finite (k, 3) vertex arrays, k >= 4)."""
    try:
        data = json.loads(raw)
    except (json.JSONDecodeError, UnicodeDecodeError) as e:
        raise ValueError(f"not JSON: {e}") from None
    if not isinstance(data, dict):
        raise ValueError("expected an object of objects")
    out = {}
    for name, entry in data.items():
        try:
            ps = [np.asarray(p, dtype=float) for p in entry["pieces"]]
            approx = bool(entry["approximate"])
        except (KeyError, TypeError, ValueError) as e:
            raise ValueError(f"object {name}: {e}") from None
        if not ps or any(
            p.ndim != 2 or p.shape[1] != 3 or len(p) < 4 or not np.all(np.isfinite(p)) for p in ps
        ):
            raise ValueError(f"object {name}: pieces must be finite (k, 3) vertex arrays with k >= 4")
        out[str(name)] = (ps, approx)
    return out


# --------------------------------------------------------------------------------------------------
# Writing
# --------------------------------------------------------------------------------------------------


def _schema(name: str) -> bytes:
    return resources.files("dlovr").joinpath(f"data/foxglove/{name}.json").read_bytes()


_COMMAND_SCHEMA = {
    "title": "dlovr.Commands",
    "description": "Gripper target poses commanded for consecutive steps, starting at `step`: "
    "pos[i] m (world) and quat[i] wxyz are applied before step `step + i`.",
    "type": "object",
    "properties": {
        "step": {"type": "integer"},
        "pos": {"type": "array", "items": {"type": "array", "items": {"type": "number"}}},
        "quat": {"type": "array", "items": {"type": "array", "items": {"type": "number"}}},
    },
}
COMMAND_BATCH = 50
"""Steps per command message (0.1 s at 2 ms): one message a step would cost more than the rest."""
_CHECKPOINT_SCHEMA = {
    "title": "dlovr.Checkpoint",
    "description": "Full simulator state (mjSTATE_INTEGRATION) after `step` steps, plus the gripper target.",
    "type": "object",
    "properties": {
        "step": {"type": "integer"},
        "state": {"type": "array", "items": {"type": "number"}},
        "target_pos": {"type": "array", "items": {"type": "number"}},
        "target_quat": {"type": "array", "items": {"type": "number"}},
    },
}
_STATES_SCHEMA = {
    "title": "dlovr.ContactState",
    "description": "A contact situation when it began: topological and discrete notation, classes of the "
    "transition into it, and per contact its discrete state, faces, contact vector and normal force (N).",
    "type": "object",
    "properties": {
        "t": {"type": "number"},
        "step": {"type": "integer"},
        "topological": {"type": "string"},
        "discrete": {"type": "string"},
        "classes": {"type": "array", "items": {"type": "string"}},
        "contacts": {"type": "array", "items": {"type": "object"}},
    },
}


def _dumps(obj: Any) -> bytes:
    return json.dumps(obj, separators=(",", ":"), allow_nan=False).encode()


def _floats(a: Any) -> list[float]:
    """A vector or array as a flat list of Python floats."""
    return np.asarray(a, dtype=float).ravel().tolist()


@contextmanager
def finish_on_sigterm() -> Iterator[None]:
    """Turn SIGTERM into ``SystemExit`` while inside, so ``with Recorder(...)`` finishes the file."""
    try:
        previous = signal.getsignal(signal.SIGTERM)
        signal.signal(signal.SIGTERM, lambda *_: (_ for _ in ()).throw(SystemExit(143)))
    except ValueError:  # not the main thread: nothing to install
        yield
        return
    try:
        yield
    finally:
        signal.signal(signal.SIGTERM, previous)


class Recorder:
    """Writes one demonstration to an MCAP file (see the module docstring for its contents).

    Use as a context manager: the file is finished on normal exit and on exceptions (and on SIGTERM
    inside :func:`finish_on_sigterm`). It is flushed every ``flush_interval`` seconds of wall time so
    that a killed writer loses at most that much (``dlovr recover``).
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
    ):
        import mujoco

        self.path = Path(path)
        self.dt = float(dt)
        self.dt_ns = round(self.dt * 1e9)
        self.t0_ns = time.time_ns() if t0_ns is None else int(t0_ns)
        self.flush_interval = float(flush_interval)
        self.frame_every = max(1, round(1.0 / (frame_rate * self.dt)))
        self._fh: BinaryIO = open(self.path, "wb")
        self._w = Writer(self._fh, chunk_size=1 << 20, compression=CompressionType.ZSTD)
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
        js = "jsonschema"
        ids = {
            TOPIC_COMMAND: self._w.register_schema("dlovr.Commands", js, _dumps(_COMMAND_SCHEMA)),
            TOPIC_CHECKPOINT: self._w.register_schema("dlovr.Checkpoint", js, _dumps(_CHECKPOINT_SCHEMA)),
            TOPIC_STATES: self._w.register_schema("dlovr.ContactState", js, _dumps(_STATES_SCHEMA)),
            TOPIC_SCENE: self._w.register_schema("foxglove.SceneUpdate", js, _schema("foxglove.SceneUpdate")),
            TOPIC_TF: self._w.register_schema(
                "foxglove.FrameTransforms", js, _schema("foxglove.FrameTransforms")
            ),
        }
        self._ch = {topic: self._w.register_channel(topic, "json", sid) for topic, sid in ids.items()}
        self._pending_states: list[tuple[int, bytes]] = []
        self._commands: list[tuple[int, list[float], list[float]]] = []
        self._seq = 0
        self._last_flush = time.monotonic()
        self._closed = False
        self._w.flush()

    # -- messages -----------------------------------------------------------------------------------

    def _ns(self, step: int) -> int:
        return self.t0_ns + int(step) * self.dt_ns

    def _add(self, topic: str, step: int, payload: bytes) -> None:
        self._seq += 1
        ns = self._ns(step)
        self._w.add_message(self._ch[topic], ns, payload, ns, self._seq)

    def command(self, step: int, pos: Sequence[float], quat: Sequence[float]) -> None:
        """The gripper target commanded for step ``step`` (applied before that step); steps come in
        order, written in messages of :data:`COMMAND_BATCH` steps."""
        c = self._commands
        if c and int(step) != c[0][0] + len(c):
            raise ValueError(f"command for step {step} out of order (expected {c[0][0] + len(c)})")
        c.append((int(step), _floats(pos), _floats(quat)))
        if len(c) >= COMMAND_BATCH:
            self._write_commands()
        self._maybe_flush()

    def _write_commands(self) -> None:
        c = self._commands
        if c:
            payload = {"step": c[0][0], "pos": [x[1] for x in c], "quat": [x[2] for x in c]}
            self._add(TOPIC_COMMAND, c[0][0], _dumps(payload))
            c.clear()

    def checkpoint(
        self, step: int, state: np.ndarray, target_pos: Sequence[float], target_quat: Sequence[float]
    ) -> None:
        """A full simulator state after ``step`` steps."""
        payload = {
            "step": int(step),
            "state": _floats(state),
            "target_pos": _floats(target_pos),
            "target_quat": _floats(target_quat),
        }
        self._add(TOPIC_CHECKPOINT, step, _dumps(payload))

    def contact_state(self, step: int, payload: Mapping[str, Any]) -> None:
        """A contact situation that began at ``step`` (buffered; written in chunks of its own)."""
        self._pending_states.append((int(step), _dumps(dict(payload))))

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
        ns = self._ns(step)
        stamp = {"sec": ns // 1_000_000_000, "nsec": ns % 1_000_000_000}
        w, x, y, z = _floats(gripper_quat)
        origin = {"position": {"x": 0, "y": 0, "z": 0}, "orientation": {"x": 0, "y": 0, "z": 0, "w": 1}}

        def entity(id_: str, frame: str, **primitives: list[dict[str, Any]]) -> dict[str, Any]:
            e: dict[str, Any] = {
                "timestamp": stamp, "frame_id": frame, "id": id_, "lifetime": {"sec": 0, "nsec": 0},
                "frame_locked": frame != "world", "metadata": [],
            }  # fmt: skip
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
                "points": [
                    {"x": v[0], "y": v[1], "z": v[2]} for v in np.asarray(tris).reshape(-1, 3).tolist()
                ],
                "color": {"r": 0.6, "g": 0.65, "b": 0.7, "a": 1.0},
                "colors": [],
                "indices": [],
            }
            entities.append(entity(f"object/{name}", "world", triangles=[mesh]))
        self._add(TOPIC_SCENE, step, _dumps({"deletions": [], "entities": entities}))
        tf = {
            "transforms": [
                {
                    "timestamp": stamp,
                    "parent_frame_id": "world",
                    "child_frame_id": "gripper",
                    "translation": dict(zip("xyz", _floats(gripper_pos), strict=True)),
                    "rotation": {"x": x, "y": y, "z": z, "w": w},  # Foxglove is xyzw, MuJoCo wxyz
                }
            ]
        }
        self._add(TOPIC_TF, step, _dumps(tf))

    # -- flushing and closing -----------------------------------------------------------------------

    def _write_states(self) -> None:
        """End the bulk chunk, write the buffered contact states, end their chunk."""
        if not self._pending_states:
            return
        self._w.flush()
        for step, payload in self._pending_states:
            self._add(TOPIC_STATES, step, payload)
        self._pending_states.clear()
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

    def close(self) -> None:
        """Finish the file (summary and footer). Safe to call twice."""
        if self._closed:
            return
        self._closed = True
        try:
            self._write_commands()
            self._write_states()
            self._w.finish()
        finally:
            self._fh.close()

    def __enter__(self) -> Recorder:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()


# --------------------------------------------------------------------------------------------------
# Reading
# --------------------------------------------------------------------------------------------------

MCAP_MAGIC = b"\x89MCAP0\r\n"


@dataclass(frozen=True)
class Checkpoint:
    step: int
    state: np.ndarray
    target_pos: np.ndarray
    target_quat: np.ndarray


class Recording:
    """A validated recording opened for reading. Raises :class:`RecordingError` on any problem."""

    def __init__(self, path: str | Path):
        self.path = Path(path)
        p = self.path
        try:
            size = p.stat().st_size
        except OSError as e:
            raise RecordingError(f"{p}: cannot read: {e.strerror}") from None
        if p.is_dir():
            raise RecordingError(f"{p}: is a directory, not a recording")
        if size == 0:
            raise RecordingError(f"{p}: empty file, not an MCAP recording")
        with open(p, "rb") as fh:
            head = fh.read(len(MCAP_MAGIC))
            fh.seek(max(0, size - len(MCAP_MAGIC)))
            tail = fh.read()
        if head != MCAP_MAGIC:
            raise RecordingError(f"{p}: not an MCAP file (bad magic bytes)")
        if tail != MCAP_MAGIC:
            raise RecordingError(
                f"{p}: truncated recording (no MCAP footer: the writer was killed?); "
                f"try `dlovr recover {p} -o FIXED.mcap`"
            )
        try:
            with open(p, "rb") as fh:
                reader = make_reader(fh, validate_crcs=True)
                header = reader.get_header()
                summary = reader.get_summary()
                meta = {m.name: dict(m.metadata) for m in reader.iter_metadata()}
                attachments = {a.name: a.data for a in reader.iter_attachments()}
        except (McapError, ValueError, EOFError, KeyError, OSError) as e:
            raise RecordingError(f"{p}: corrupt MCAP data: {_one_line(e)}") from None
        if header.profile != PROFILE or "dlovr" not in meta:
            raise RecordingError(f"{p}: an MCAP file but not a dlovr recording (profile {header.profile!r})")
        self.metadata: dict[str, str] = meta["dlovr"]
        version = self.metadata.get("format_version")
        if version != FORMAT_VERSION:
            raise RecordingError(
                f"{p}: recording format {version}, this dlovr {__version__} reads format {FORMAT_VERSION}"
            )
        if summary is None:
            raise RecordingError(f"{p}: recording has no summary section")
        topics = {c.topic for c in summary.channels.values()}
        missing = [t for t in REQUIRED_TOPICS if t not in topics]
        if missing:
            raise RecordingError(f"{p}: recording has no channel {missing[0]}")
        self._counts = {
            summary.channels[cid].topic: n for cid, n in (summary.statistics.channel_message_counts.items()
                                                         if summary.statistics else [])
        }  # fmt: skip
        if SCENE_TOML not in attachments:
            raise RecordingError(f"{p}: recording has no embedded scene ({SCENE_TOML})")
        files = []
        for name, data in attachments.items():
            if name.startswith(SCENE_PREFIX) and name != SCENE_TOML:
                rel = name[len(SCENE_PREFIX) :]
                try:
                    _safe_relpath(rel)
                except RecordingError as e:
                    raise RecordingError(f"{p}: {e}") from None
                if len(data) > MAX_ATTACHMENT_BYTES:
                    raise RecordingError(f"{p}: embedded file {rel} is too large")
                files.append((rel, bytes(data)))
        self.scene = SceneBundle(bytes(attachments[SCENE_TOML]), tuple(sorted(files)))
        self.pieces: dict[str, tuple[list[np.ndarray], bool]] | None = None
        if PIECES_JSON in attachments:
            if hashlib.sha256(attachments[PIECES_JSON]).hexdigest() != self.metadata.get("pieces_sha256"):
                raise RecordingError(f"{p}: the embedded convex decomposition was modified")
            try:
                self.pieces = pieces_from_json(bytes(attachments[PIECES_JSON]))
            except ValueError as e:
                raise RecordingError(f"{p}: bad {PIECES_JSON}: {e}") from None
        if self.scene.digest != self.metadata.get("scene_sha256"):
            raise RecordingError(
                f"{p}: the embedded scene was modified (its sha256 does not match the metadata)"
            )
        try:
            self.dt = float(self.metadata["timestep"])
            self.t0_ns = int(self.metadata["t0_ns"])
        except (KeyError, ValueError):
            raise RecordingError(f"{p}: metadata lacks a valid timestep / t0_ns") from None
        if not (0 < self.dt < 1):
            raise RecordingError(f"{p}: implausible timestep {self.dt}")

    def count(self, topic: str) -> int:
        return self._counts.get(topic, 0)

    def _iter(self, topic: str) -> Iterator[dict[str, Any]]:
        try:
            with open(self.path, "rb") as fh:
                reader = make_reader(fh, validate_crcs=True)
                for _, _, msg in reader.iter_messages(topics=[topic]):
                    yield json.loads(msg.data)
        except (McapError, ValueError, EOFError, KeyError, OSError) as e:
            raise RecordingError(f"{self.path}: corrupt data in {topic}: {_one_line(e)}") from None

    def states(self) -> list[dict[str, Any]]:
        """The contact-state messages (reads only their chunks)."""
        return list(self._iter(TOPIC_STATES))

    def commands(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Commanded gripper targets: step numbers (k,), positions (k, 3), quaternions (k, 4)."""
        steps, pos, quat = [], [], []
        try:
            for m in self._iter(TOPIC_COMMAND):
                p, q = np.asarray(m["pos"], float), np.asarray(m["quat"], float)
                if p.ndim != 2 or p.shape[1:] != (3,) or q.shape != (len(p), 4):
                    raise ValueError("pos/quat must be (k, 3) and (k, 4)")
                steps.append(int(m["step"]) + np.arange(len(p)))
                pos.append(p)
                quat.append(q)
        except (KeyError, TypeError, ValueError) as e:
            raise RecordingError(f"{self.path}: bad gripper command message: {e}") from None
        if not steps:
            raise RecordingError(f"{self.path}: recording has no gripper commands")
        s = np.concatenate(steps)
        if np.any(np.diff(s) != 1):
            raise RecordingError(f"{self.path}: gripper command stream has gaps or is out of order")
        return s, np.concatenate(pos), np.concatenate(quat)

    def frames(self) -> Iterator[tuple[float, np.ndarray, np.ndarray, np.ndarray]]:
        """The ~30 Hz visual frames: (time s, cable points (n+1, 3), gripper pos (3,), quat wxyz (4,)).

        Read from the Foxglove channels (this decompresses the bulk chunks: slower than states()).
        """
        poses: dict[int, tuple[np.ndarray, np.ndarray]] = {}
        for m in self._iter(TOPIC_TF):
            for tf in m.get("transforms", []):
                tr, ro = tf["translation"], tf["rotation"]
                poses[_stamp_ns(tf["timestamp"])] = (
                    np.array([tr["x"], tr["y"], tr["z"]], dtype=float),
                    np.array([ro["w"], ro["x"], ro["y"], ro["z"]], dtype=float),
                )
        for m in self._iter(TOPIC_SCENE):
            for ent in m.get("entities", []):
                if ent.get("id") != "cable" or not ent.get("lines"):
                    continue
                ns = _stamp_ns(ent["timestamp"])
                pts = np.array([[p["x"], p["y"], p["z"]] for p in ent["lines"][0]["points"]], dtype=float)
                gp, gq = poses.get(ns, (pts[0], np.array([1.0, 0.0, 0.0, 0.0])))
                yield (ns - self.t0_ns) / 1e9, pts, gp, gq

    def checkpoints(self) -> list[Checkpoint]:
        out = [
            Checkpoint(int(m["step"]), np.asarray(m["state"], float), np.asarray(m["target_pos"], float),
                       np.asarray(m["target_quat"], float))
            for m in self._iter(TOPIC_CHECKPOINT)
        ]  # fmt: skip
        if not out:
            raise RecordingError(f"{self.path}: recording has no checkpoints")
        return out


def _stamp_ns(stamp: Mapping[str, int]) -> int:
    return int(stamp["sec"]) * 1_000_000_000 + int(stamp["nsec"])


def _one_line(e: BaseException) -> str:
    s = str(e).strip().splitlines()
    return (s[0] if s else type(e).__name__)[:200]


# --------------------------------------------------------------------------------------------------
# Recovery
# --------------------------------------------------------------------------------------------------


@dataclass(frozen=True)
class RecoveryReport:
    messages: int
    attachments: int
    last_time_s: float


def recover(src: str | Path, dst: str | Path) -> RecoveryReport:
    """Copy every complete chunk of a recording whose writer was killed into a new, finished file."""
    src, dst = Path(src), Path(dst)
    if src.resolve() == dst.resolve():
        raise RecordingError(f"{dst}: recover writes a new file; choose another output path")
    try:
        raw = src.read_bytes()
    except OSError as e:
        raise RecordingError(f"{src}: cannot read: {e.strerror}") from None
    if not raw.startswith(MCAP_MAGIC):
        raise RecordingError(f"{src}: not an MCAP file (bad magic bytes)")
    from mcap.records import Attachment, Channel, Message, Metadata, Schema

    schemas: dict[int, Schema] = {}
    channels: dict[int, Channel] = {}
    messages: list[Message] = []
    attachments: list[Attachment] = []
    metadata: list[Metadata] = []
    header_profile = PROFILE
    reader = StreamReader(io.BytesIO(raw), validate_crcs=True)
    try:
        for rec in reader.records:
            name = type(rec).__name__
            if name == "Header":
                header_profile = rec.profile
            elif isinstance(rec, Schema):
                schemas[rec.id] = rec
            elif isinstance(rec, Channel):
                channels[rec.id] = rec
            elif isinstance(rec, Message):
                messages.append(rec)
            elif isinstance(rec, Attachment):
                attachments.append(rec)
            elif isinstance(rec, Metadata):
                metadata.append(rec)
    except Exception:  # the broken tail: keep everything complete before it
        pass
    if not channels:
        raise RecordingError(f"{src}: nothing recoverable (no complete chunk with channel definitions)")
    with open(dst, "wb") as fh:
        w = Writer(fh, compression=CompressionType.ZSTD)
        w.start(profile=header_profile, library=f"dlovr {__version__} recover")
        for m in metadata:
            w.add_metadata(m.name, dict(m.metadata))
        for a in attachments:
            w.add_attachment(a.create_time, a.log_time, a.name, a.media_type, a.data)
        sid_map = {sid: w.register_schema(s.name, s.encoding, s.data) for sid, s in schemas.items()}
        cid_map = {
            cid: w.register_channel(
                c.topic, c.message_encoding, sid_map.get(c.schema_id, 0), dict(c.metadata)
            )
            for cid, c in channels.items()
        }
        for m in messages:
            if m.channel_id in cid_map:
                w.add_message(cid_map[m.channel_id], m.log_time, m.data, m.publish_time, m.sequence)
        w.finish()
    last = max((m.log_time for m in messages), default=0)
    first = min((m.log_time for m in messages), default=0)
    return RecoveryReport(len(messages), len(attachments), (last - first) / 1e9 if messages else math.nan)


# --------------------------------------------------------------------------------------------------
# Recording a running demonstration, and replaying one
# --------------------------------------------------------------------------------------------------

CHECKPOINT_EVERY_S = 1.0


class DemoRecorder:
    """Records a running demonstration: call :meth:`step` after every simulation step.

    ``sim`` is a :class:`dlovr.sim.Simulator`, ``tracker`` its :class:`dlovr.sim.tracker.ContactTracker`;
    the scene is embedded from ``scene.path``. The first checkpoint is written at construction (so a
    recording may start at any moment of a session), then one every second of simulated time.
    """

    def __init__(self, path: str | Path, scene: Any, sim: Any, tracker: Any, **kw: Any):
        dt = float(sim.model.opt.timestep)
        self.sim, self.tracker = sim, tracker
        meta = {"hold": repr(float(tracker.hold)), **dict(kw.pop("extra_metadata", None) or {})}
        bundle = SceneBundle.from_path(scene.path)
        self.rec = Recorder(
            path, bundle, scene_name=scene.name, dt=dt, extra_metadata=meta, pieces=sim.pieces, **kw
        )
        self.path = self.rec.path
        self.start_step = int(sim.step_index)
        self._cp_every = max(1, round(CHECKPOINT_EVERY_S / dt))
        self._radius = float(scene.dlo.radius)
        self._obstacles = [(o.name, np.asarray(o.mesh.triangles)) for o in tracker.geometry.objects]
        self._checkpoint()
        start = tracker.restart(sim.record())  # replay restarts the same way from the checkpoint
        self._prev = start.discrete
        self._n_changes = len(tracker.changes)
        self.rec.contact_state(self.start_step, start.payload())

    def _checkpoint(self) -> None:
        st = self.sim.get_state()
        self.rec.checkpoint(st.step, st.mj, st.target_pos, st.target_quat)

    def step(self, record: Any) -> None:
        """Log the step just taken (its command, and on schedule checkpoints, states and frames)."""
        k = int(record.step)
        self.rec.command(k, record.target_pos, record.target_quat)
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
            )  # fmt: skip

    def close(self) -> Path:
        """Finish the file (with a final checkpoint at the last step); return its path. Idempotent."""
        if not self.rec.closed:
            if (int(self.sim.step_index) - self.start_step) % self._cp_every:
                self._checkpoint()
            cur = self.tracker.current
            if cur is not None:  # where the recording ends (the situation it ends in, unchanged)
                end = {
                    **cur.payload(),
                    "step": int(self.sim.step_index),
                    "t": float(self.sim.time),
                    "end": True,
                }
                self.rec.contact_state(int(self.sim.step_index), end)
            self.rec.close()
        return self.path

    def __enter__(self) -> DemoRecorder:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()


@dataclass(frozen=True)
class ReplayResult:
    """Outcome of :func:`replay`. ``divergence``: the first difference found by ``verify`` (or None)."""

    steps: int
    sim_time: float
    wall_time: float
    states: tuple[dict[str, Any], ...]
    divergence: str | None
    warnings: tuple[str, ...]


def load_embedded_scene(recording: Recording, directory: str | Path) -> Any:
    """Load the recording's own scene (written into ``directory``; never a path named inside it)."""
    from dlovr.scene import SceneError, load_scene

    path = recording.scene.materialize(directory)
    try:
        return load_scene(path)
    except SceneError as e:
        raise RecordingError(f"{recording.path}: embedded scene is invalid: {e}") from None


def replay(path: str | Path, *, verify: bool = False, progress: Any = None) -> ReplayResult:
    """Re-simulate a recording from its first checkpoint and its command stream alone.

    With ``verify``, the state at every checkpoint is compared bit for bit and the contact-state
    sequence with the recorded one; the first difference is reported in ``divergence``.
    ``progress(done, total)`` is called with the number of steps done so far and in all.
    """
    import tempfile

    import mujoco

    from dlovr.sim import SimState, Simulator

    rec = Recording(path)
    warnings = []
    for key, have in (("mujoco_version", mujoco.__version__), ("dlovr_version", __version__)):
        want = rec.metadata.get(key)
        if want != have:
            warnings.append(
                f"recorded with {key.split('_')[0]} {want}, replaying with {have}: may not be bit-exact"
            )
    steps, pos, quat = rec.commands()
    cps = rec.checkpoints()
    recorded_states = rec.states()
    with tempfile.TemporaryDirectory(prefix="dlovr-replay-") as tmp:
        scene = load_embedded_scene(rec, tmp)
        if rec.pieces is not None and set(rec.pieces) != {o.name for o in scene.objects}:
            raise RecordingError(f"{rec.path}: the embedded decomposition does not match the scene's objects")
        sim = Simulator(scene, pieces=rec.pieces, track=True)  # every step updates sim.tracker
        if abs(sim.model.opt.timestep - rec.dt) > 1e-15:
            raise RecordingError(
                f"{rec.path}: time step {rec.dt} differs from the scene's {sim.model.opt.timestep}"
            )
    tracker = sim.tracker
    tracker.hold = float(rec.metadata.get("hold", DEFAULT_HOLD_S))  # taken by restart() below
    first = cps[0]
    if len(first.state) != len(sim.get_state().mj):
        raise RecordingError(f"{rec.path}: checkpoint size does not match the embedded scene's model")
    sim.set_state(SimState(first.state, first.step, first.target_pos, first.target_quat))
    if steps[0] != first.step + 1:
        raise RecordingError(f"{rec.path}: command stream does not start right after the first checkpoint")
    by_step = {c.step: c for c in cps[1:]}
    divergence: str | None = None
    t0 = time.perf_counter()
    tracker.restart(sim.record())
    dt = rec.dt
    for i, k in enumerate(steps):
        # the recorded targets are the exact ones used (already validated and normalised when
        # recorded): set them as they are, since normalising again may change the last bit
        sim.target_pos, sim.target_quat = pos[i].copy(), quat[i].copy()
        sim.step()
        if verify and divergence is None and int(k) in by_step:
            want = by_step[int(k)].state
            got = sim.get_state().mj
            if not np.array_equal(want.view(np.uint64), got.view(np.uint64)):
                bad = int(np.argmax(want.view(np.uint64) != got.view(np.uint64)))
                divergence = (
                    f"state differs at checkpoint step {int(k)} (t={k * dt:.3f} s), element {bad}: "
                    f"recorded {want[bad]!r}, replayed {got[bad]!r}"
                )
        if progress is not None and (i % 500 == 0 or i == len(steps) - 1):
            progress(i + 1, len(steps))
    wall = time.perf_counter() - t0
    replayed = tuple(st.payload() for st in tracker.changes)
    if verify and divergence is None:
        divergence = _compare_states([p for p in recorded_states if not p.get("end")], replayed, dt)
    return ReplayResult(len(steps), len(steps) * dt, wall, replayed, divergence, tuple(warnings))


def _compare_states(
    recorded: Sequence[Mapping[str, Any]], replayed: Sequence[Mapping[str, Any]], dt: float
) -> str | None:
    for i, (a, b) in enumerate(zip(recorded, replayed, strict=False)):
        for key in ("step", "topological", "discrete"):
            if a.get(key) != b.get(key):
                return (
                    f"contact state {i + 1} (t={a.get('step', 0) * dt:.3f} s) differs in {key}: "
                    f"recorded {a.get(key)!r}, replayed {b.get(key)!r}"
                )
    if len(recorded) != len(replayed):
        return f"recorded {len(recorded)} contact-state changes, replay produced {len(replayed)}"
    return None


# --------------------------------------------------------------------------------------------------
# From recorded contact states to kept situations and programs (reads only the states channel)
# --------------------------------------------------------------------------------------------------


def situation_from_payload(payload: Mapping[str, Any]) -> Any:
    """The discrete situation of a contact-state message, with its contact vectors."""
    from dataclasses import replace

    from dlovr.model.discrete import DiscreteSituation, parse_discrete_situation

    sit = parse_discrete_situation(payload["discrete"])
    contacts = payload.get("contacts") or []
    if len(contacts) == len(sit.contacts):
        sit = DiscreteSituation(
            tuple(
                replace(c, vector=tuple(m["vector"])) if m.get("vector") is not None else c
                for c, m in zip(sit.contacts, contacts, strict=True)
            )
        )
    return sit


def kept_states(recording: Recording, hold: float | None = None) -> list[Any]:
    """The recording's contact situations debounced as in MODEL.md §4.2, as ``TimedSituation``s."""
    from dlovr.model.program import TimedSituation
    from dlovr.model.transitions import Debouncer, is_transient

    payloads = recording.states()
    if not payloads:
        raise RecordingError(f"{recording.path}: recording has no contact states")
    hold = float(recording.metadata.get("hold", DEFAULT_HOLD_S)) if hold is None else hold
    deb: Debouncer[Any] = Debouncer(hold, is_transient)
    first: dict[Any, Mapping[str, Any]] = {}
    try:
        for p in payloads:
            sit = situation_from_payload(p)
            deb.push(float(p["t"]), sit)
            first.setdefault((float(p["t"]), sit), p)
    except (KeyError, ValueError, TypeError) as e:
        raise RecordingError(f"{recording.path}: bad contact-state message: {e}") from None
    end = payloads[-1]["t"]  # the last message is written when the recording ends
    out = []
    for i, k in enumerate(deb.kept):
        p = first.get((k.start, k.situation), {})
        stop = k.end if i + 1 < len(deb.kept) else end
        force = max((c.get("force", 0.0) for c in p.get("contacts", [])), default=0.0)
        out.append(
            TimedSituation(k.start, round(stop - k.start, 9), k.situation, p.get("topological"), force)
        )
    return out


def compile_recording(path: str | Path, hold: float | None = None) -> Any:
    """Compile a recording into a program (MODEL.md §5); reads only the contact-state channel."""
    from dlovr.model.program import PoseTrack, compile_program

    rec = Recording(path)
    states = kept_states(rec, hold)
    payloads = rec.states()
    t = np.array([float(p["t"]) for p in payloads])
    pos = np.array([p.get("gripper_pos", [0.0, 0.0, 0.0]) for p in payloads], dtype=float)
    quat = np.array([p.get("gripper_quat", [1.0, 0.0, 0.0, 0.0]) for p in payloads], dtype=float)
    return compile_program(states, PoseTrack(t, pos, quat), name=Path(path).stem, source=Path(path).name)


# --------------------------------------------------------------------------------------------------
# Batch compilation
# --------------------------------------------------------------------------------------------------

CACHE_NAME = ".dlovr-compile-cache.json"


@dataclass(frozen=True)
class CompileResult:
    """Outcome for one recording: ``error`` is None on success; ``skipped`` when unchanged."""

    path: str
    json_path: str | None
    macros: int = 0
    risky: int = 0
    skipped: bool = False
    error: str | None = None


def find_recordings(inputs: Sequence[str | Path]) -> list[Path]:
    """Recordings named by files or found (``*.mcap``, recursively) in directories, sorted, unique."""
    out: set[Path] = set()
    for i in inputs:
        p = Path(i)
        if p.is_dir():
            out.update(q for q in p.rglob("*.mcap") if q.is_file())
        else:
            out.add(p)
    return sorted(out)


def _sha256(path: Path) -> str:
    h = hashlib.sha256()
    with open(path, "rb") as fh:
        for block in iter(lambda: fh.read(1 << 20), b""):
            h.update(block)
    return h.hexdigest()


def compile_one(path: str, out_dir: str | None, force: bool = False) -> CompileResult:
    """Compile one recording to ``<stem>.program.json`` and ``.program.txt`` (a worker's job)."""
    p = Path(path)
    out = Path(out_dir) if out_dir else p.parent
    try:
        digest = _sha256(p)
    except OSError as e:
        return CompileResult(str(p), None, error=f"{p}: cannot read: {e.strerror}")
    jpath, tpath = out / f"{p.stem}.program.json", out / f"{p.stem}.program.txt"
    cache_file = out / CACHE_NAME
    try:
        cache = json.loads(cache_file.read_text()) if cache_file.is_file() else {}
    except (OSError, ValueError):
        cache = {}
    if not force and cache.get(p.name) == digest and jpath.is_file() and tpath.is_file():
        data = json.loads(jpath.read_text())
        s = data.get("summary", {})
        return CompileResult(str(p), str(jpath), s.get("macros", 0), s.get("risky", 0), skipped=True)
    try:
        prog = compile_recording(p)
    except RecordingError as e:
        return CompileResult(str(p), None, error=str(e))
    out.mkdir(parents=True, exist_ok=True)
    jpath.write_text(prog.dumps())
    tpath.write_text(prog.listing())
    return CompileResult(str(p), str(jpath), prog.summary["macros"], prog.summary["risky"])


def record_compiled(results: Sequence[CompileResult], out_dir: str | None) -> None:
    """Remember the content hashes of successfully compiled recordings (in the parent process)."""
    by_dir: dict[Path, dict[str, str]] = {}
    for r in results:
        if r.error is None and r.json_path is not None:
            d = Path(r.json_path).parent
            by_dir.setdefault(d, {})[Path(r.path).name] = _sha256(Path(r.path))
    for d, entries in by_dir.items():
        f = d / CACHE_NAME
        try:
            cache = json.loads(f.read_text()) if f.is_file() else {}
        except (OSError, ValueError):
            cache = {}
        cache.update(entries)
        f.write_text(json.dumps(dict(sorted(cache.items())), indent=1) + "\n")
