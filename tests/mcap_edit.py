"""Test helper: copy an MCAP file, changing attachments or messages on the way (to forge bad input)."""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path

from mcap.reader import make_reader
from mcap.writer import Writer


def rewrite_mcap(
    src: Path,
    dst: Path,
    attachment: Callable[[str, bytes], bytes] = lambda name, data: data,
    message: Callable[[str, bytes], bytes] = lambda topic, data: data,
    metadata: Callable[[str, dict[str, str]], dict[str, str]] = lambda name, data: data,
    keep: Callable[[str], bool] = lambda topic: True,
) -> None:
    """Write ``dst`` as a copy of ``src`` with metadata, attachments and messages edited (and the
    messages of topics that ``keep`` refuses left out)."""
    with open(src, "rb") as fh, open(dst, "wb") as oh:
        rd = make_reader(fh)
        w = Writer(oh, enable_data_crcs=True)  # as dlovr writes (a zero data CRC is damage)
        w.start(profile=rd.get_header().profile)
        for m in rd.iter_metadata():
            w.add_metadata(m.name, metadata(m.name, dict(m.metadata)))
        for a in rd.iter_attachments():
            w.add_attachment(a.create_time, a.log_time, a.name, a.media_type, attachment(a.name, a.data))
        chans: dict[int, int] = {}
        for schema, ch, msg in rd.iter_messages():
            if not keep(ch.topic):
                continue
            if ch.id not in chans:
                sid = w.register_schema(schema.name, schema.encoding, schema.data)
                chans[ch.id] = w.register_channel(ch.topic, ch.message_encoding, sid)
            w.add_message(chans[ch.id], msg.log_time, message(ch.topic, msg.data), msg.publish_time)
        w.finish()
