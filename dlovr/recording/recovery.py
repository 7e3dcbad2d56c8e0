"""Recovery: rescue the complete chunks of a recording whose writer was killed into a new, finished
file (``dlovr recover``)."""

from __future__ import annotations

import io
import math
from dataclasses import dataclass
from pathlib import Path

from mcap.stream_reader import StreamReader
from mcap.writer import CompressionType, Writer

from dlovr import __version__
from dlovr.recording.format import MCAP_MAGIC, PROFILE, RecordingError


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
