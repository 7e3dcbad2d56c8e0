"""Reading recordings: :class:`Recording` opens and validates a file and reads its channels;
:func:`kept_states` turns its contact-state messages into the debounced situations a program is
compiled from (reading only the states channel)."""

from __future__ import annotations

import hashlib
import json
import stat
from collections.abc import Iterator, Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
from mcap.reader import make_reader
from mcap.records import Header
from mcap.summary import Summary

from dlovr import __version__
from dlovr.model.transitions import DEFAULT_FLIGHT_S, DEFAULT_HOLD_S
from dlovr.outputs import being_written
from dlovr.plausibility import Implausible, implausible_from_payload
from dlovr.recording.bundle import SceneBundle, pieces_from_json, safe_relpath
from dlovr.recording.format import (
    DECODE_ERRORS,
    FORMAT_VERSION,
    MAX_ATTACHMENT_BYTES,
    MCAP_MAGIC,
    PIECES_JSON,
    PROFILE,
    REQUIRED_TOPICS,
    SCENE_PREFIX,
    SCENE_TOML,
    TOPIC_CHECKPOINT,
    TOPIC_COMMAND,
    TOPIC_SCENE,
    TOPIC_STATES,
    TOPIC_TF,
    TOPIC_WARNINGS,
    TOPIC_WRENCH,
    RecordingError,
    one_line,
)
from dlovr.recording.foxglove import stamp_ns
from dlovr.recording.integrity import check_checksums


@dataclass(frozen=True)
class Checkpoint:
    step: int
    state: np.ndarray
    target_pos: np.ndarray
    target_quat: np.ndarray


class Recording:
    """A validated recording opened for reading. Raises :class:`RecordingError` on any problem.

    Opening checks the file's checksums (summary, data section when written) and its metadata; reading
    a channel checks its chunks' CRCs and the messages' JSON. ``dt``: time step (s); ``t0_ns``: log
    time of step 0; ``hold``: the debouncing hold time (s) it was recorded with.
    """

    def __init__(self, path: str | Path):
        self.path = Path(path)
        p = self.path
        header, summary, meta, attachments = _open_mcap(p)
        if header.profile != PROFILE or "dlovr" not in meta:
            raise RecordingError(f"{p}: an MCAP file but not a dlovr recording (profile {header.profile!r})")
        self.metadata: dict[str, str] = meta["dlovr"]
        #: What ``dlovr recover`` skipped when it wrote this file (one line each; "" if not recovered
        #: or nothing was skipped).
        self.recovery_skipped: str = meta.get("dlovr_recovery", {}).get("skipped", "")
        version = self.metadata.get("format_version")
        if version != FORMAT_VERSION:
            raise RecordingError(
                f"{p}: recording format {version}, this dlovr {__version__} reads format {FORMAT_VERSION}"
            )
        if not self.metadata.get("scene_name"):  # every dlovr recording names its scene
            why = "metadata scene_name: missing (not a recording dlovr wrote, or edited)"
            raise RecordingError(f"{p}: {why}")
        self._counts = _message_counts(p, summary)
        self.scene = _embedded_scene(p, attachments)
        self.pieces: dict[str, tuple[list[np.ndarray], bool]] | None = _embedded_pieces(
            p, attachments, self.metadata
        )
        if self.scene.digest != self.metadata.get("scene_sha256"):
            raise RecordingError(
                f"{p}: the embedded scene was modified (its sha256 does not match the metadata)"
            )
        self.dt, self.t0_ns, self.hold, self.flight = _timing(p, self.metadata)


    @property
    def recovery_note(self) -> str:
        """`` (recovered from a damaged recording with parts missing: ...)`` when ``dlovr recover``
        wrote this file and skipped something (the reason its replay may fail), else ``""``."""
        missing = self.recovery_skipped.splitlines()
        if not missing:
            return ""
        more = f"; and {len(missing) - 1} more" if len(missing) > 1 else ""
        return f" (recovered from a damaged recording with parts missing: {missing[0]}{more})"
    def count(self, topic: str) -> int:
        return self._counts.get(topic, 0)

    def _iter(self, topic: str) -> Iterator[dict[str, Any]]:
        """The messages of ``topic`` as JSON objects; any decoding problem is a RecordingError.

        Read to the end, they must be as many as the summary's statistics count (when it has them): a
        chunk whose header was zeroed (no CRC, no compression, no records) reads as an intact empty
        chunk, and only the count shows that its messages are missing.
        """
        n = 0
        try:
            with open(self.path, "rb") as fh:
                reader = make_reader(fh, validate_crcs=True)
                for _, _, msg in reader.iter_messages(topics=[topic]):
                    obj = json.loads(msg.data)
                    if not isinstance(obj, dict):
                        raise ValueError(f"a message is {type(obj).__name__}, not an object")
                    n += 1
                    yield obj
        except DECODE_ERRORS as e:
            raise RecordingError(f"{self.path}: corrupt data in {topic}: {one_line(e)}") from None
        if self._counts and n != self.count(topic):
            raise RecordingError(
                f"{self.path}: corrupt data in {topic}: {n} messages read, the summary counts "
                f"{self.count(topic)} (a damaged chunk?); try `dlovr recover {self.path} -o FIXED.mcap`"
            )

    def messages(self, topic: str) -> list[dict[str, Any]]:
        """The messages of any channel ``topic`` as JSON objects (none when it has no such channel)."""
        return list(self._iter(topic)) if self.count(topic) else []

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
        except RecordingError:  # already names the file and the problem
            raise
        except _FIELD_ERRORS as e:
            raise RecordingError(f"{self.path}: bad gripper command message: {one_line(e)}") from None
        if not steps:
            raise RecordingError(f"{self.path}: recording has no gripper commands")
        s = np.concatenate(steps)
        if np.any(np.diff(s) != 1):
            why = "gripper command stream has gaps or is out of order"
            raise RecordingError(f"{self.path}: {why}{self.recovery_note}")
        return s, np.concatenate(pos), np.concatenate(quat)

    def frames(self) -> Iterator[tuple[float, np.ndarray, np.ndarray, np.ndarray]]:
        """The ~30 Hz visual frames: (time s, cable points (n+1, 3), gripper pos (3,), quat wxyz (4,)).

        Read from the Foxglove channels (this decompresses the bulk chunks: slower than states()).
        """
        poses: dict[int, tuple[np.ndarray, np.ndarray]] = {}
        try:
            for m in self._iter(TOPIC_TF):
                for tf in m.get("transforms", []):
                    tr, ro = tf["translation"], tf["rotation"]
                    poses[stamp_ns(tf["timestamp"])] = (
                        np.array([tr["x"], tr["y"], tr["z"]], dtype=float),
                        np.array([ro["w"], ro["x"], ro["y"], ro["z"]], dtype=float),
                    )
            frames = []
            for m in self._iter(TOPIC_SCENE):
                for ent in m.get("entities", []):
                    if ent.get("id") != "cable" or not ent.get("lines"):
                        continue
                    ns = stamp_ns(ent["timestamp"])
                    pts = [[p["x"], p["y"], p["z"]] for p in ent["lines"][0]["points"]]
                    frames.append((ns, np.array(pts, dtype=float).reshape(-1, 3)))
        except RecordingError:  # already names the file and the problem
            raise
        except _FIELD_ERRORS as e:
            raise RecordingError(f"{self.path}: bad visual frame message: {one_line(e)}") from None
        for ns, pts in frames:
            gp, gq = poses.get(ns, (pts[0], np.array([1.0, 0.0, 0.0, 0.0])))
            yield (ns - self.t0_ns) / 1e9, pts, gp, gq

    def warnings(self) -> list[Implausible]:
        """The plausibility warnings (docs/recordings.md): stretches of steps where a cable point went
        deeper into an obstacle or faster than the bounds; none in files recorded before they existed."""
        if self._counts and self.count(TOPIC_WARNINGS) == 0:
            return []
        try:
            return [implausible_from_payload(m) for m in self._iter(TOPIC_WARNINGS)]
        except RecordingError:  # already names the file and the problem
            raise
        except _FIELD_ERRORS as e:
            raise RecordingError(f"{self.path}: bad warning message: {one_line(e)}") from None

    def wrench(self) -> Any:
        """The sensed gripper wrench as a ``WrenchSeries`` (times s, force N, torque N m, world frame),
        or None when the recording has no wrench channel (recorded before it existed)."""
        from dlovr.model.derivation import WrenchSeries

        if self.count(TOPIC_WRENCH) == 0:
            return None
        t, f, tq = [], [], []
        try:
            for m in self._iter(TOPIC_WRENCH):
                ti = np.asarray(m["t"], float).ravel()
                fi, tqi = np.asarray(m["force"], float), np.asarray(m["torque"], float)
                if fi.shape != (len(ti), 3) or tqi.shape != (len(ti), 3):
                    raise ValueError("t, force, torque must be (k,), (k, 3), (k, 3)")
                t.append(ti)
                f.append(fi)
                tq.append(tqi)
            if not t:
                return None
            return WrenchSeries(np.concatenate(t), np.concatenate(f), np.concatenate(tq))
        except RecordingError:  # already names the file and the problem
            raise
        except _FIELD_ERRORS as e:
            raise RecordingError(f"{self.path}: bad wrench message: {one_line(e)}") from None

    def checkpoints(self) -> list[Checkpoint]:
        """The full simulator states, in order."""
        try:
            out = [
                Checkpoint(int(m["step"]), np.asarray(m["state"], float).ravel(),
                           np.asarray(m["target_pos"], float).reshape(3),
                           np.asarray(m["target_quat"], float).reshape(4))
                for m in self._iter(TOPIC_CHECKPOINT)
            ]
        except RecordingError:  # already names the file and the problem
            raise
        except _FIELD_ERRORS as e:
            raise RecordingError(f"{self.path}: bad checkpoint message: {one_line(e)}") from None
        if not out:
            raise RecordingError(f"{self.path}: recording has no checkpoints")
        return out


def _open_mcap(p: Path) -> tuple[Header, Summary | None, dict[str, dict[str, str]], dict[str, bytes]]:
    """The MCAP file ``p``'s header, summary, metadata records (by name) and attachments (by
    name), after checking that it is a whole MCAP file with valid checksums."""
    try:
        st = p.stat()
    except OSError as e:
        raise RecordingError(f"{p}: cannot read: {e.strerror}") from None
    size = st.st_size
    if p.is_dir():
        raise RecordingError(f"{p}: is a directory, not a recording")
    if not stat.S_ISREG(st.st_mode):
        raise RecordingError(f"{p}: not a regular file (a device or a pipe), not a recording")
    if being_written(p):
        raise RecordingError(f"{p}: still being written (a recording in progress); open it once finished")
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
    check_checksums(p, size)
    try:
        with open(p, "rb") as fh:
            reader = make_reader(fh, validate_crcs=True)
            header = reader.get_header()
            summary = reader.get_summary()
            meta = {m.name: dict(m.metadata) for m in reader.iter_metadata()}
            attachments = {a.name: a.data for a in reader.iter_attachments()}
    except DECODE_ERRORS as e:
        raise RecordingError(f"{p}: corrupt MCAP data: {one_line(e)}") from None
    return header, summary, meta, attachments


def _message_counts(p: Path, summary: Summary | None) -> dict[str, int]:
    """The number of messages per topic, after checking that the summary has every required
    channel."""
    if summary is None:
        raise RecordingError(f"{p}: recording has no summary section")
    topics = {c.topic for c in summary.channels.values()}
    missing = [t for t in REQUIRED_TOPICS if t not in topics]
    if missing:
        raise RecordingError(f"{p}: recording has no channel {missing[0]}")
    return {
        summary.channels[cid].topic: n for cid, n in (summary.statistics.channel_message_counts.items()
                                                     if summary.statistics else [])
    }


def _embedded_scene(p: Path, attachments: Mapping[str, bytes]) -> SceneBundle:
    """The scene embedded in the recording: its TOML and the files beside it (safe relative paths,
    each at most :data:`MAX_ATTACHMENT_BYTES`)."""
    if SCENE_TOML not in attachments:
        raise RecordingError(f"{p}: recording has no embedded scene ({SCENE_TOML})")
    files = []
    for name, data in attachments.items():
        if name.startswith(SCENE_PREFIX) and name != SCENE_TOML:
            rel = name[len(SCENE_PREFIX) :]
            try:
                safe_relpath(rel)
            except RecordingError as e:
                raise RecordingError(f"{p}: {e}") from None
            if len(data) > MAX_ATTACHMENT_BYTES:
                raise RecordingError(f"{p}: embedded file {rel} is too large")
            files.append((rel, bytes(data)))
    return SceneBundle(bytes(attachments[SCENE_TOML]), tuple(sorted(files)))


def _embedded_pieces(
    p: Path, attachments: Mapping[str, bytes], metadata: Mapping[str, str]
) -> dict[str, tuple[list[np.ndarray], bool]] | None:
    """The convex decomposition embedded in the recording (checked against its sha256 in the
    metadata), or ``None`` for a recording without one."""
    if PIECES_JSON not in attachments:
        return None
    if hashlib.sha256(attachments[PIECES_JSON]).hexdigest() != metadata.get("pieces_sha256"):
        raise RecordingError(f"{p}: the embedded convex decomposition was modified")
    try:
        return pieces_from_json(bytes(attachments[PIECES_JSON]))
    except ValueError as e:
        raise RecordingError(f"{p}: bad {PIECES_JSON}: {e}") from None


def _timing(p: Path, metadata: Mapping[str, str]) -> tuple[float, int, float, float]:
    """The metadata's time step (s), log time of step 0 (ns), hold and flight times (s), each
    checked to be plausible."""
    try:
        dt = float(metadata["timestep"])
        t0_ns = int(metadata["t0_ns"])
    except (KeyError, ValueError):
        raise RecordingError(f"{p}: metadata lacks a valid timestep / t0_ns") from None
    if not (0 < dt < 1):
        raise RecordingError(f"{p}: implausible timestep {dt}")
    try:
        hold = float(metadata.get("hold", DEFAULT_HOLD_S))
    except ValueError:
        raise RecordingError(f"{p}: metadata has an invalid hold time") from None
    if not (0 <= hold < 1e3):
        raise RecordingError(f"{p}: implausible hold time {hold}")
    try:  # recordings made before flights were debounced carry none: the default
        flight = float(metadata.get("flight", DEFAULT_FLIGHT_S))
    except ValueError:
        raise RecordingError(f"{p}: metadata has an invalid flight time") from None
    if not (0 <= flight < 1e3):
        raise RecordingError(f"{p}: implausible flight time {flight}")
    return dt, t0_ns, hold, flight


_FIELD_ERRORS = (KeyError, IndexError, TypeError, ValueError, AttributeError, OverflowError)
"""What a JSON message with missing or wrongly typed fields raises when its fields are used."""


# --------------------------------------------------------------------------------------------------
# From recorded contact states to kept situations (reads only the states channel)
# --------------------------------------------------------------------------------------------------


def situation_from_payload(payload: Mapping[str, Any]) -> Any:
    """The discrete situation of a contact-state message, with its contact vectors."""

    from dlovr.model.discrete import DiscreteSituation, parse_discrete_situation

    sit = parse_discrete_situation(payload["discrete"])
    contacts = payload.get("contacts") or []
    if len(contacts) == len(sit.contacts):
        sit = DiscreteSituation(
            tuple(
                _restored(c, m)
                for c, m in zip(sit.contacts, contacts, strict=True)
            )
        )
    return sit


def _restored(contact: Any, message: Mapping[str, Any]) -> Any:
    """A parsed discrete contact with the contact vector and DLO span its message carries."""
    from dataclasses import replace

    changes: dict[str, Any] = {}
    if message.get("vector") is not None:
        changes["vector"] = tuple(message["vector"])
    span = message.get("span")
    if span is not None:
        changes["span"] = (int(span[0]), int(span[1]))
    return replace(contact, **changes) if changes else contact


def kept_states(recording: Recording, hold: float | None = None) -> list[Any]:
    """The recording's contact situations debounced as in docs/model.md (section 5: flicker, brief
    intermediate states, flights), as ``TimedSituation``s."""
    from dlovr.model.program import TimedSituation
    from dlovr.model.transitions import Debouncer, is_transient

    payloads = recording.states()
    if not payloads:
        raise RecordingError(f"{recording.path}: recording has no contact states")
    hold = recording.hold if hold is None else hold
    deb: Debouncer[Any] = Debouncer(hold, is_transient, flight=recording.flight)
    first: dict[Any, Mapping[str, Any]] = {}
    out = []
    try:
        for p in payloads:
            sit = situation_from_payload(p)
            deb.push(float(p["t"]), sit)
            first.setdefault((float(p["t"]), sit), p)
        end = float(payloads[-1]["t"])  # the last message is written when the recording ends
        for i, k in enumerate(deb.kept):
            p = first.get((k.start, k.situation), {})
            stop = k.end if i + 1 < len(deb.kept) else end
            force = max((c.get("force", 0.0) for c in p.get("contacts", [])), default=0.0)
            top = p.get("topological")
            out.append(
                TimedSituation(k.start, round(stop - k.start, 9), k.situation, top, force, k.through_free)
            )
    except RecordingError:  # already names the file and the problem
        raise
    except _FIELD_ERRORS as e:  # NotationError is a ValueError
        raise RecordingError(f"{recording.path}: bad contact-state message: {one_line(e)}") from None
    return out
