"""The named corruptions of issue 31 through `recover` and the readers: a flipped bit in a chunk's
length field, a damaged leading magic byte or header profile, a chunk cut out, a zeroed data CRC. Each
is named (what, where, when); nothing intact is skipped."""

from __future__ import annotations

import struct
from pathlib import Path

import pytest
from click.testing import CliRunner
from mcap.reader import make_reader
from test_recording_damage import chunk_offsets, contents, without_data_crc

from dlovr.cli import main
from dlovr.recording import Recording, RecordingError, recover

TOUCH = Path(__file__).parents[1] / "data" / "touch_table.script.toml"


def cli(*args):
    return CliRunner().invoke(main, [str(a) for a in args])


@pytest.fixture(scope="module")
def touch(tmp_path_factory) -> Path:
    out = tmp_path_factory.mktemp("touch") / "touch.mcap"
    assert cli("record", "--script", TOUCH, "-o", out).exit_code == 0
    return out


def write(path: Path, raw: bytes) -> Path:
    path.write_bytes(raw)
    return path


def test_a_flipped_bit_in_a_chunk_length_skips_nothing_intact_and_is_named(touch, tmp_path):
    raw = touch.read_bytes()
    chunks = chunk_offsets(raw)
    k = next(i for i in range(len(chunks) // 2, len(chunks)) if chunks[i][1] > 3000)
    pos, n = chunks[k]
    start, end = struct.unpack_from("<QQ", raw, pos + 9)
    bit = max(b for b in range(8, 40) if pos + 9 + (n | 1 << b) < len(raw) - 2000 and not n & 1 << b)
    bad = bytearray(raw)
    struct.pack_into("<Q", bad, pos + 1, n | 1 << bit)  # longer: reaches over intact chunks
    rep = recover(write(tmp_path / "bad.mcap", bytes(bad)), tmp_path / "fixed.mcap")
    lost = set(contents(touch)[0]) - set(contents(tmp_path / "fixed.mcap")[0])
    assert all(start <= t <= end for _, t, _ in lost), "intact data was skipped"
    line = next(x for x in rep.skipped if f"at bytes {pos}-" in x)
    assert "t=" in line and "chunk length field" in line


def test_a_damaged_magic_byte_keeps_the_header_metadata_and_scene(touch, tmp_path):
    raw = touch.read_bytes()
    rep = recover(write(tmp_path / "bad.mcap", bytes([raw[0] ^ 0x01]) + raw[1:]), tmp_path / "fixed.mcap")
    fixed = Recording(tmp_path / "fixed.mcap")  # the profile, the metadata and the scene are there
    assert fixed.scene.digest == Recording(touch).scene.digest
    assert any(line.startswith("magic bytes at bytes 0-8") for line in rep.skipped)


def test_a_damaged_header_profile_is_named_and_written_right(touch, tmp_path):
    raw = touch.read_bytes()
    i = raw.index(b"dlovr", 8)
    assert i < 40  # the header's profile
    bad = raw[:i] + b"dlovq" + raw[i + 5 :]
    rep = recover(write(tmp_path / "bad.mcap", bad), tmp_path / "fixed.mcap")
    assert any("header: profile damaged ('dlovq')" in line for line in rep.skipped)
    with open(tmp_path / "fixed.mcap", "rb") as fh:
        assert make_reader(fh).get_header().profile == "dlovr"
    Recording(tmp_path / "fixed.mcap")


def test_a_chunk_cut_out_is_listed_and_verify_names_the_damage(touch, tmp_path):
    """Chunks of the middle cut out (commands and frames, contact states, a checkpoint: the layout
    depends on the wall clock): the recovered file lists the messages missing; a replay that then
    fails names that, exit 2 (was: "replay diverged", exit 1); one with only frames missing verifies."""
    raw = touch.read_bytes()
    chunks = chunk_offsets(raw)
    failed = 0
    for k in range(len(chunks) // 2, len(chunks) // 2 + 4):
        pos, n = chunks[k]
        fixed = tmp_path / f"fixed{k}.mcap"
        rep = recover(write(tmp_path / f"cut{k}.mcap", raw[:pos] + raw[pos + 9 + n :]), fixed)
        assert any("messages missing" in line and "t=" in line for line in rep.skipped), rep.skipped
        r = cli("replay", "--verify", fixed)
        if r.exit_code == 0:
            continue
        failed += 1
        assert r.exit_code == 2, r.output
        last = r.output.strip().splitlines()[-1]
        note = "(recovered from a damaged recording with parts missing: "
        assert note in last and "missing" in last.split(note)[1]
    assert failed


def test_a_zeroed_data_crc_is_damage(touch, tmp_path):
    """With the data CRC zeroed, an edited metadata value went unnoticed (the CRC is the only check of
    the metadata): a dlovr recording always carries it, so a zero one is damage."""
    raw = without_data_crc(touch.read_bytes())
    bad = write(tmp_path / "nocrc.mcap", raw)
    with pytest.raises(RecordingError, match=r"nocrc\.mcap: corrupt MCAP data: the data checksum is zero"):
        Recording(bad)
    edited = write(tmp_path / "edited.mcap", raw.replace(b'"hold"', b'"hold"', 1))
    i = raw.find(b"hold")
    assert i > 0
    r = cli("states", edited)
    assert r.exit_code == 2 and "the data checksum is zero" in r.output
