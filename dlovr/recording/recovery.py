"""Recovery: rescue every intact chunk of a damaged recording, or of one whose writer was killed, into a
new, finished file (``dlovr recover``).

What is kept: every chunk that decompresses and passes its CRC, wherever it lies (damaged chunks are
skipped, not the rest of the file); schema and channel definitions from wherever they survive (the
chunks, the summary section at the end, or else the dlovr format's fixed channel layout); metadata and
attachments that pass their checks. A file whose writer was killed (no end of data section) is cut at
its last checkpoint: the writer puts every command and contact state up to a checkpoint in the file
before the checkpoint, so the recovered file is consistent and replays (``dlovr replay --verify``).
What was skipped is reported as byte and time ranges.
"""

from __future__ import annotations

import itertools
import json
import math
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from mcap.writer import CompressionType, Writer

from dlovr import __version__
from dlovr.inputs import read_bytes
from dlovr.outputs import being_written
from dlovr.recording.format import (
    CHANNELS,
    DECODE_ERRORS,
    MCAP_MAGIC,
    PROFILE,
    TOPIC_CHECKPOINT,
    TOPIC_COMMAND,
    TOPIC_STATES,
    RecordingError,
    dumps,
)
from dlovr.recording.integrity import ScanResult, scan

#: The metadata record of a recovered file that lists what was skipped (one line each).
RECOVERY_METADATA = "dlovr_recovery"


@dataclass(frozen=True)
class RecoveryReport:
    """``messages`` and ``attachments`` written; ``last_time_s``: seconds from the first to the last
    message kept; ``skipped``: one line per skipped part (what, where, time range, why)."""

    messages: int
    attachments: int
    last_time_s: float
    skipped: tuple[str, ...] = ()


def recover(src: str | Path, dst: str | Path) -> RecoveryReport:
    """Copy every intact part of a damaged or unfinished recording into a new, finished file."""
    src, dst = Path(src), Path(dst)
    if src.resolve() == dst.resolve():
        raise RecordingError(f"{dst}: recover writes a new file; choose another output path")
    if being_written(src):
        raise RecordingError(f"{src}: still being written (a recording in progress); recover it once ended")
    raw = read_bytes(src, RecordingError, "recording", "recording_bytes")  # bounded: not /dev/zero
    res = scan(raw)
    if not raw.startswith(MCAP_MAGIC) and not res.chunks:
        raise RecordingError(f"{src}: not an MCAP file (bad magic bytes)")
    meta = next((dict(m.metadata) for m in res.metadata if m.name == "dlovr"), {})
    clock = _Clock.of(meta, res)
    skipped = [_describe(d, clock, res) for d in res.damage]
    skipped += _profile_damage(res, meta)
    schemas = {**res.summary_schemas, **res.schemas}
    channels = {**res.summary_channels, **res.channels}
    if not channels and (res.profile == PROFILE or meta.get("format_version")):
        channels, schemas = _dlovr_layout()
        skipped.append("channel definitions: lost; used the dlovr format's fixed channel layout")
    chunks = [[m for m in c if m.channel_id in channels] for c in res.chunks]
    orphans = sum(len(c) for c in res.chunks) - sum(len(c) for c in chunks)
    if orphans:
        skipped.append(f"{orphans} messages whose channel definition was lost")
    topic = {cid: c.topic for cid, c in channels.items()}
    if not res.data_end:
        chunks = _cut_at_last_checkpoint(chunks, topic, clock, skipped)
    messages = [m for c in chunks for m in c]
    if not messages:
        raise RecordingError(f"{src}: nothing recoverable (no intact chunk with messages)")
    if not any(topic[m.channel_id] == TOPIC_COMMAND for m in messages):
        raise RecordingError(
            f"{src}: nothing recoverable: no intact chunk holds gripper commands"
            + (" (the writer was stopped within its first second?)" if not res.data_end else "")
        )
    skipped += _command_gaps(messages, topic, clock)
    skipped += _sequence_gaps(messages, clock)
    try:
        _write(dst, res, schemas, channels, chunks, skipped)
    except OSError as e:
        raise RecordingError(f"{dst}: cannot write: {e.strerror or e}") from None
    first, last = min(m.log_time for m in messages), max(m.log_time for m in messages)
    return RecoveryReport(
        len(messages), len(res.attachments), (last - first) / 1e9 if messages else math.nan, tuple(skipped)
    )


@dataclass(frozen=True)
class _Clock:
    """Log time (ns) to recording time (s): ``(ns - t0_ns) / 1e9``; the time step when known."""

    t0_ns: int
    dt: float | None

    @staticmethod
    def of(meta: dict[str, str], res: ScanResult) -> _Clock:
        try:
            t0 = int(meta["t0_ns"])
        except (KeyError, ValueError):
            t0 = min((m.log_time for c in res.chunks for m in c), default=0)
        try:
            dt: float | None = float(meta["timestep"])
            if not (0 < dt < 1):
                dt = None
        except (KeyError, ValueError):
            dt = None
        return _Clock(t0, dt)

    def t(self, ns: int) -> float:
        return (ns - self.t0_ns) / 1e9

    def span(self, a_ns: int, b_ns: int) -> str:
        a, b = self.t(a_ns), self.t(b_ns)
        if not (-1.0 <= a <= b <= 1e7):
            return "time unknown"
        return f"t={a:.3f}-{b:.3f} s"


def _describe(d: Any, clock: _Clock, res: ScanResult) -> str:
    """One line for a damaged part: where (bytes), when (the chunk header's times, else the times of
    the intact chunks around it), why."""
    span = clock.span(*d.time_ns) if d.time_ns else "time unknown"
    if span == "time unknown":
        placed = list(zip(res.chunks, res.chunk_at, strict=False))
        before = [m.log_time for c, at in placed if at < d.start for m in c]
        after = [m.log_time for c, at in placed if at >= d.end for m in c]
        if before and after and (d.what in ("chunk", "record")):
            span = f"between {clock.span(max(before), min(after))}"
    when = f", {span}" if d.time_ns or span != "time unknown" else ""
    return f"{d.what} at bytes {d.start}-{d.end} ({d.end - d.start} bytes){when}: {d.reason}"


def _profile_damage(res: ScanResult, meta: dict[str, str]) -> list[str]:
    """A dlovr recording (its metadata says so) whose header profile is damaged or lost: said, and
    the recovered file gets the right one (:func:`_write`)."""
    if res.profile == PROFILE or not meta.get("format_version"):
        return []
    was = "lost" if res.profile is None else f"damaged ({res.profile!r})"
    return [f"header: profile {was}; written as {PROFILE!r}"]


def _sequence_gaps(messages: list[Any], clock: _Clock) -> list[str]:
    """Messages missing between recovered ones, by the writer's sequence numbers (1, 2, 3, ...): a
    chunk cut out of the file leaves no damaged bytes, but a gap here."""
    seq = sorted((m.sequence, m.log_time) for m in messages if m.sequence > 0)
    out = []
    for (a, ta), (b, tb) in itertools.pairwise(seq):
        if b > a + 1:
            when = clock.span(min(ta, tb), max(ta, tb))  # states are written after the steps they cover
            out.append(f"{b - a - 1} messages missing (a chunk cut out?), around {when}")
    return out


def _dlovr_layout() -> tuple[dict[int, Any], dict[int, Any]]:
    from mcap.records import Channel, Schema

    from dlovr.recording.writer import schemas

    data = schemas()
    sch = {
        i: Schema(id=i, data=data[name], encoding="jsonschema", name=name)
        for i, (_, name) in enumerate(CHANNELS, 1)
    }
    chs = {
        i: Channel(id=i, topic=topic, message_encoding="json", metadata={}, schema_id=i)
        for i, (topic, _) in enumerate(CHANNELS, 1)
    }
    return chs, sch


def _cut_at_last_checkpoint(
    chunks: list[list[Any]], topic: dict[int, str], clock: _Clock, skipped: list[str]
) -> list[list[Any]]:
    """Keep what precedes the last checkpoint (an unfinished file's consistent part) and end the
    contact states there as the writer does when it closes."""
    cps = [m for c in chunks for m in c if topic[m.channel_id] == TOPIC_CHECKPOINT]
    if not cps:
        return chunks
    last = max(cps, key=lambda m: m.log_time)
    try:
        step = int(json.loads(last.data)["step"])
    except (*DECODE_ERRORS, AttributeError):
        return chunks
    cut = last.log_time
    dropped = [m.log_time for c in chunks for m in c if m.log_time > cut]
    out = []
    for c in chunks:
        kept = []
        for m in c:
            if m.log_time > cut:
                continue
            if topic[m.channel_id] == TOPIC_COMMAND:
                m = _trim_commands(m, step)
            kept.append(m)
        out.append(kept)
    if dropped:
        skipped.append(
            f"the unfinished end after the last checkpoint ({clock.span(cut, max(dropped))}): "
            "the writer was stopped before it was complete"
        )
    states = [m for c in out for m in c if topic[m.channel_id] == TOPIC_STATES]
    end = _end_marker(states, step, clock)
    if end is not None:
        cid = next(cid for cid, t in topic.items() if t == TOPIC_STATES)
        from mcap.records import Message

        out.append([Message(channel_id=cid, log_time=cut, data=end, publish_time=cut, sequence=0)])
    return out


def _trim_commands(m: Any, last_step: int) -> Any:
    """A command batch cut to the steps up to ``last_step`` (unchanged if it ends before)."""
    from mcap.records import Message

    try:
        d = json.loads(m.data)
        keep = last_step - int(d["step"]) + 1
        if keep >= len(d["pos"]):
            return m
        d["pos"], d["quat"] = d["pos"][:keep], d["quat"][:keep]
    except (*DECODE_ERRORS, AttributeError):
        return m
    return Message(
        channel_id=m.channel_id,
        log_time=m.log_time,
        data=dumps(d),
        publish_time=m.publish_time,
        sequence=m.sequence,
    )


def _end_marker(states: list[Any], step: int, clock: _Clock) -> bytes | None:
    """The end-of-recording contact state at ``step`` (the last situation, unchanged), or None."""
    if not states or clock.dt is None:
        return None
    try:
        last = json.loads(max(states, key=lambda m: m.log_time).data)
        if last.get("end"):
            return None
        t = float(last["t"]) + (step - int(last["step"])) * clock.dt
    except (*DECODE_ERRORS, AttributeError):
        return None
    return dumps({**last, "classes": [], "step": step, "t": round(t, 9), "end": True})


def _command_gaps(messages: list[Any], topic: dict[int, str], clock: _Clock) -> list[str]:
    """Time ranges without gripper commands between the first and the last recovered command."""
    if clock.dt is None:
        return []
    spans = []
    for m in messages:
        if topic[m.channel_id] == TOPIC_COMMAND:
            try:
                d = json.loads(m.data)
                spans.append((int(d["step"]), int(d["step"]) + len(d["pos"])))
            except (*DECODE_ERRORS, AttributeError):
                continue
    spans.sort()
    out, reach = [], spans[0][1] if spans else 0
    for a, b in spans[1:]:
        if a > reach:
            out.append(f"gripper commands missing for t={reach * clock.dt:.3f}-{a * clock.dt:.3f} s")
        reach = max(reach, b)
    return out


def _write(
    dst: Path,
    res: ScanResult,
    schemas: dict[int, Any],
    channels: dict[int, Any],
    chunks: list[list[Any]],
    skipped: list[str],
) -> None:
    """Write the recovered file (one output chunk per input chunk, so contact states stay apart); what
    was skipped goes into its ``dlovr_recovery`` metadata (a replay that diverges names it)."""
    dst.parent.mkdir(parents=True, exist_ok=True)
    dlovr = any(m.name == "dlovr" for m in res.metadata)
    with open(dst, "wb") as fh:
        w = Writer(fh, compression=CompressionType.ZSTD, enable_data_crcs=True)
        w.start(profile=PROFILE if dlovr else res.profile or PROFILE, library=f"dlovr {__version__} recover")
        for m in res.metadata:
            if m.name != RECOVERY_METADATA:
                w.add_metadata(m.name, dict(m.metadata))
        if skipped:
            w.add_metadata(RECOVERY_METADATA, {"skipped": "\n".join(skipped)})
        for a in res.attachments:
            w.add_attachment(a.create_time, a.log_time, a.name, a.media_type, a.data)
        sid_map = {sid: w.register_schema(s.name, s.encoding, s.data) for sid, s in sorted(schemas.items())}
        cid_map = {
            cid: w.register_channel(
                c.topic, c.message_encoding, sid_map.get(c.schema_id, 0), dict(c.metadata)
            )
            for cid, c in sorted(channels.items())
        }
        for c in chunks:
            for m in c:
                w.add_message(cid_map[m.channel_id], m.log_time, m.data, m.publish_time, m.sequence)
            w.flush()
        w.finish()
