"""MCAP below the record reader: whole-file checksums (:func:`check_checksums`) and a tolerant scan of
every record (:func:`scan`) that skips damaged ones, for ``dlovr recover``.

An MCAP file is ``magic, records..., magic``; a record is an opcode (1 byte), a length (uint64 LE)
and that many bytes. Chunks hold compressed records (schemas, channels, messages) with a CRC of the
uncompressed bytes; the data section ends with a ``DataEnd`` record holding a CRC of everything
before it (0 when the writer did not compute one: damage in a dlovr recording, whose writer always
does); the summary section after it repeats the schemas
and channels, and the footer holds a CRC of the summary.
"""

from __future__ import annotations

import io
import struct
import zlib
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from mcap.opcode import Opcode

from dlovr.recording.format import DECODE_ERRORS, MCAP_MAGIC, PROFILE, RecordingError, one_line

FOOTER_LEN = 1 + 8 + 8 + 8 + 4
DATA_END_LEN = 1 + 8 + 4
_U64 = struct.Struct("<Q")
_U32 = struct.Struct("<I")
_KNOWN = {int(o) for o in Opcode}


def check_checksums(path: Path, size: int) -> None:
    """Check the footer, the summary CRC and the data-section CRC (when the writer computed them).

    Expects a file that starts and ends with the MCAP magic. Raises :class:`RecordingError`.
    """
    hint = f"the file was damaged; try `dlovr recover {path} -o FIXED.mcap`"
    with open(path, "rb") as fh:
        footer_pos = size - len(MCAP_MAGIC) - FOOTER_LEN
        if footer_pos < len(MCAP_MAGIC):
            raise RecordingError(f"{path}: corrupt MCAP data: too short for a footer")
        fh.seek(footer_pos)
        footer = fh.read(FOOTER_LEN)
        if footer[0] != Opcode.FOOTER or _U64.unpack_from(footer, 1)[0] != FOOTER_LEN - 9:
            raise RecordingError(f"{path}: corrupt MCAP data: bad footer ({hint})")
        summary_start, summary_offset_start = _U64.unpack_from(footer, 9)[0], _U64.unpack_from(footer, 17)[0]
        summary_crc = _U32.unpack_from(footer, 25)[0]
        end = summary_start or footer_pos
        if not (len(MCAP_MAGIC) + DATA_END_LEN <= end <= footer_pos) or not (
            summary_offset_start == 0 or summary_start <= summary_offset_start <= footer_pos
        ):
            raise RecordingError(f"{path}: corrupt MCAP data: bad footer offsets ({hint})")
        if summary_start and summary_crc:
            fh.seek(summary_start)
            crc = _crc_of(fh, footer_pos - summary_start)
            if zlib.crc32(footer[: FOOTER_LEN - 4], crc) != summary_crc:
                raise RecordingError(f"{path}: corrupt MCAP data: summary checksum mismatch ({hint})")
        fh.seek(end - DATA_END_LEN)
        data_end = fh.read(DATA_END_LEN)
        if data_end[0] != Opcode.DATA_END or _U64.unpack_from(data_end, 1)[0] != 4:
            raise RecordingError(f"{path}: corrupt MCAP data: no data-end record ({hint})")
        data_crc = _U32.unpack_from(data_end, 9)[0]
        if not data_crc and DATA_CRC_REQUIRED and _profile(fh) == PROFILE:
            why = "the data checksum is zero, and a dlovr recording always carries one"
            raise RecordingError(f"{path}: corrupt MCAP data: {why} ({hint})")
        if data_crc:
            fh.seek(0)
            if _crc_of(fh, end - DATA_END_LEN) != data_crc:
                raise RecordingError(f"{path}: corrupt MCAP data: data checksum mismatch ({hint})")


#: Whether a zero data-section CRC in a dlovr recording is damage (it is: the writer always computes
#: it, and with it switched off an edited metadata value would go unnoticed). Tests of the checks
#: below it turn it off.
DATA_CRC_REQUIRED = True


def _profile(fh: io.BufferedReader | Any) -> str | None:
    """The profile of the header record right after the magic (None if it is not there)."""
    fh.seek(len(MCAP_MAGIC))
    head = fh.read(9 + 4)
    if len(head) < 13 or head[0] != Opcode.HEADER:
        return None
    n = _U32.unpack_from(head, 9)[0]
    if n > 256:
        return None
    return fh.read(n).decode("utf-8", "replace")


def _crc_of(fh: io.BufferedReader | Any, n: int, crc: int = 0) -> int:
    while n > 0:
        block = fh.read(min(n, 1 << 20))
        if not block:
            break
        crc = zlib.crc32(block, crc)
        n -= len(block)
    return crc


# --------------------------------------------------------------------------------------------------
# Tolerant scan (recovery)
# --------------------------------------------------------------------------------------------------


@dataclass(frozen=True)
class Damage:
    """A part of the file that could not be read: byte range, what it was, and (for a chunk) the
    log-time range (ns) its header claims, when plausible."""

    start: int
    end: int
    what: str
    reason: str
    time_ns: tuple[int, int] | None = None


@dataclass
class ScanResult:
    """Everything readable in a file, in file order."""

    profile: str | None = None
    schemas: dict[int, Any] = field(default_factory=dict)
    channels: dict[int, Any] = field(default_factory=dict)
    summary_schemas: dict[int, Any] = field(default_factory=dict)
    summary_channels: dict[int, Any] = field(default_factory=dict)
    chunks: list[list[Any]] = field(default_factory=list)
    """Messages of each intact chunk (a message outside chunks counts as a chunk of its own)."""
    chunk_at: list[int] = field(default_factory=list)
    """Byte offset of each of :attr:`chunks` in the file."""
    attachments: list[Any] = field(default_factory=list)
    metadata: list[Any] = field(default_factory=list)
    damage: list[Damage] = field(default_factory=list)
    data_end: bool = False
    """Whether the data section's end was reached (a finished file)."""


def scan(raw: bytes) -> ScanResult:
    """Read every record of ``raw`` that is intact; skip (and list) damaged ones.

    A chunk counts as damaged when it does not decompress, fails its CRC or holds malformed records;
    the scan then goes on with the next record. Where a record's length is damaged, it resumes at the
    next byte sequence that parses as a chunk header. Schemas and channels also come from the summary
    section (found through the footer) when the footer survives.
    """
    out = ScanResult()
    pos = len(MCAP_MAGIC) if raw.startswith(MCAP_MAGIC) else 0
    if pos == 0 and len(raw) > 9 + len(MCAP_MAGIC) and raw[len(MCAP_MAGIC)] == Opcode.HEADER:
        pos = len(MCAP_MAGIC)  # damaged magic bytes, intact header: keep the header and what follows
        out.damage.append(Damage(0, pos, "magic bytes", "damaged (the records after them are intact)"))
    n = len(raw)
    tail = n - len(MCAP_MAGIC) if raw.endswith(MCAP_MAGIC) else n
    in_summary = False
    while pos < tail:
        if pos + 9 > tail:
            out.damage.append(Damage(pos, tail, "record", "incomplete record at the end"))
            break
        op, length = raw[pos], _U64.unpack_from(raw, pos + 1)[0]
        end = pos + 9 + length
        if op not in _KNOWN or end > tail:
            nxt = _next_chunk(raw, pos + 1, tail)
            cut = op in _KNOWN and nxt is None
            reason = "incomplete record at the end" if cut else "damaged record header"
            out.damage.append(Damage(pos, nxt if nxt is not None else tail, "record", reason))
            if nxt is None:
                break
            pos = nxt
            continue
        body = raw[pos + 9 : end]
        try:
            if op == Opcode.FOOTER:
                break
            if op == Opcode.DATA_END:
                in_summary = out.data_end = True
            else:
                before = len(out.chunks)
                used = _take(out, op, body, in_summary)
                out.chunk_at.extend([pos] * (len(out.chunks) - before))
                if op == Opcode.CHUNK and used < length:  # a damaged length reaching over what follows
                    why = f"damaged ({length} bytes for a chunk of {used}); the chunk itself is intact"
                    times = _chunk_times(body)
                    out.damage.append(Damage(pos, pos + 9 + used, "chunk length field", why, times))
                    end = pos + 9 + used
        except DECODE_ERRORS as e:
            what = Opcode(op).name.lower().replace("_", " ")
            time_ns = _chunk_times(body) if op == Opcode.CHUNK else None
            nxt = _next_chunk(raw, pos + 1, tail)  # a damaged length may reach over intact chunks
            if nxt is not None and nxt < end:
                end = nxt
            out.damage.append(Damage(pos, end, what, one_line(e), time_ns))
        pos = end
    if not in_summary:
        _summary_from_footer(raw, out)
    return out


def _take(out: ScanResult, op: int, body: bytes, in_summary: bool) -> int:
    """Take one record's contents into ``out``; the bytes of ``body`` it used."""
    from mcap.data_stream import ReadDataStream
    from mcap.records import Attachment, Channel, Chunk, Header, Message, Metadata, Schema
    from mcap.stream_reader import breakup_chunk

    stream = ReadDataStream(io.BytesIO(body))
    if op == Opcode.HEADER:
        out.profile = Header.read(stream).profile
    elif op == Opcode.SCHEMA:
        s = Schema.read(stream)
        (out.summary_schemas if in_summary else out.schemas).setdefault(s.id, s)
    elif op == Opcode.CHANNEL:
        c = Channel.read(stream)
        (out.summary_channels if in_summary else out.channels).setdefault(c.id, c)
    elif op == Opcode.MESSAGE and not in_summary:
        out.chunks.append([Message.read(stream, len(body))])
    elif op == Opcode.CHUNK and not in_summary:
        chunk = Chunk.read(stream)
        if chunk.uncompressed_size > 1 << 32:
            raise ValueError(f"implausible uncompressed size {chunk.uncompressed_size}")
        records = breakup_chunk(chunk, validate_crc=True)  # all or nothing
        for r in records:
            if isinstance(r, Schema):
                out.schemas.setdefault(r.id, r)
            elif isinstance(r, Channel):
                out.channels.setdefault(r.id, r)
        out.chunks.append([r for r in records if isinstance(r, Message)])
    elif op == Opcode.ATTACHMENT and not in_summary:
        stored = _U32.unpack_from(body, len(body) - 4)[0]
        if stored and zlib.crc32(body[:-4]) != stored:
            raise ValueError("attachment CRC mismatch")
        out.attachments.append(Attachment.read(stream))
    elif op == Opcode.METADATA and not in_summary:
        out.metadata.append(Metadata.read(stream))
    if stream.count > len(body):
        raise ValueError("record longer than its length field")
    return stream.count


def _chunk_times(body: bytes) -> tuple[int, int] | None:
    if len(body) < 16:
        return None
    start, end = _U64.unpack_from(body, 0)[0], _U64.unpack_from(body, 8)[0]
    return (start, end) if start <= end else None


def _next_chunk(raw: bytes, start: int, tail: int) -> int | None:
    """Offset of the next plausible (zstd or lz4 compressed) chunk record at or after ``start``."""
    best = None
    for comp in (b"zstd", b"lz4"):
        pat = _U32.pack(len(comp)) + comp
        i = start + 37
        while (j := raw.find(pat, i, tail)) >= 0:
            q = j - 37
            if raw[q] == Opcode.CHUNK and _chunk_header_ok(raw, q, len(comp), tail):
                best = q if best is None else min(best, q)
                break
            i = j + 1
    return best


def _chunk_header_ok(raw: bytes, q: int, comp_len: int, tail: int) -> bool:
    length = _U64.unpack_from(raw, q + 1)[0]
    off = q + 9 + 8 + 8 + 8 + 4 + 4 + comp_len
    if q + 9 + length > tail or off + 8 > tail:
        return False
    records_len = _U64.unpack_from(raw, off)[0]
    return off + 8 + records_len == q + 9 + length


def _summary_from_footer(raw: bytes, out: ScanResult) -> None:
    """Schemas and channels of the summary section, read through the footer (if both survive)."""
    if not raw.endswith(MCAP_MAGIC) or len(raw) < 2 * len(MCAP_MAGIC) + FOOTER_LEN:
        return
    fpos = len(raw) - len(MCAP_MAGIC) - FOOTER_LEN
    if raw[fpos] != Opcode.FOOTER:
        return
    pos = _U64.unpack_from(raw, fpos + 9)[0]
    if not (len(MCAP_MAGIC) < pos < fpos):
        return
    while pos + 9 <= fpos:
        op, length = raw[pos], _U64.unpack_from(raw, pos + 1)[0]
        end = pos + 9 + length
        if op not in _KNOWN or end > fpos:
            return
        if op in (Opcode.SCHEMA, Opcode.CHANNEL):
            try:
                _take(out, op, raw[pos + 9 : end], True)
            except DECODE_ERRORS:
                pass  # a damaged summary record: the chunks' copies (if any) are used
        pos = end
