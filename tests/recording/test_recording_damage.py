"""Damaged recordings: byte flips, zeroed ranges and truncations through `replay --verify`, `states`,
`compile` and `recover` (fuzzed with hypothesis); recovery of intact chunks after damaged ones; no
silent overwrites in `record` and `compile`."""

from __future__ import annotations

import io
import shutil
import struct
import subprocess
import sys
import tempfile
from pathlib import Path

import pytest
from click.testing import CliRunner
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from mcap.records import Attachment, Channel, Message, Metadata
from mcap.stream_reader import StreamReader

from dlovr.cli import main
from dlovr.recording import Recording, RecordingError, compile_recording, integrity, recover, replay

SHORT_SCRIPT = """\
# 1.2 s on the built-in table: the hanging cable's tip touches the table (V/N -> V/F).
scene = "table"

[[waypoints]]
pos = [0.0, 0.0, 0.595]
duration = 0.5

[[waypoints]]
pos = [-0.15, 0.0, 0.45]
duration = 0.7
"""
TOUCH = Path(__file__).parents[1] / "data" / "touch_table.script.toml"


def cli(*args):
    return CliRunner().invoke(main, [str(a) for a in args])


@pytest.fixture(scope="session")
def short(tmp_path_factory) -> Path:
    """A 1.2 s recording made with `dlovr record` (about 120 kB)."""
    d = tmp_path_factory.mktemp("short")
    script = d / "short.script.toml"
    script.write_text(SHORT_SCRIPT)
    out = d / "short.mcap"
    r = cli("record", "--script", script, "-o", out)
    assert r.exit_code == 0, r.output
    return out


@pytest.fixture(scope="session")
def short_without_data_crc(short, tmp_path_factory) -> Path:
    """The same file with its data-section CRC set to 0 ("not computed"), so that damage must be
    caught where it is decoded (chunk CRCs, decompression, record parsing). A dlovr recording always
    carries its CRC, so the readers call such a file damaged (:data:`DATA_CRC_REQUIRED`); the tests
    that use this file turn that check off (:func:`_checks_below_the_data_crc`) to reach the others."""
    out = tmp_path_factory.mktemp("nocrc") / "short.mcap"
    out.write_bytes(without_data_crc(short.read_bytes()))
    with pytest.raises(RecordingError, match="the data checksum is zero"):
        replay(out, verify=True)
    with pytest.MonkeyPatch.context() as mp:
        mp.setattr(integrity, "DATA_CRC_REQUIRED", False)
        assert replay(out, verify=True).divergence is None
    return out


@pytest.fixture(autouse=True)
def _checks_below_the_data_crc(request, monkeypatch):
    """Tests of the file without a data CRC check what lies below it: the zero CRC itself is not
    reported there (it is by :func:`short_without_data_crc` and test_recording_integrity)."""
    callspec = getattr(request.node, "callspec", None)
    no_crc = callspec is not None and callspec.params.get("variant") == "no-crc"
    if no_crc or "short_without_data_crc" in request.fixturenames:
        monkeypatch.setattr(integrity, "DATA_CRC_REQUIRED", False)


def without_data_crc(data: bytes) -> bytes:
    """``data`` with its data-section CRC set to 0 (found through the footer's summary offset)."""
    raw = bytearray(data)
    summary_start = struct.unpack_from("<Q", raw, len(raw) - 8 - 29 + 9)[0]
    data_end = summary_start - 13
    assert raw[data_end] == 0x0F
    raw[data_end + 9 : data_end + 13] = b"\0\0\0\0"
    return bytes(raw)


def contents(path: Path):
    """What the file holds, read without checking any CRC: (messages, metadata, attachments), or None
    when it cannot be read at all."""
    try:
        msgs, meta, att = [], [], []
        chans = {}
        for r in StreamReader(io.BytesIO(path.read_bytes())).records:
            if isinstance(r, Channel):
                chans[r.id] = r.topic
            elif isinstance(r, Message):
                msgs.append((chans.get(r.channel_id), r.log_time, r.data))
            elif isinstance(r, Metadata):
                meta.append((r.name, dict(r.metadata)))
            elif isinstance(r, Attachment):
                att.append((r.name, r.data))
        return msgs, meta, att
    except Exception:
        return None


def mutate(raw: bytes, m: tuple) -> bytes:
    kind, a, b = m
    n = len(raw)
    if kind == "flip":
        i = a % n
        return raw[:i] + bytes([raw[i] ^ b]) + raw[i + 1 :]
    if kind == "zero":
        i = a % n
        return raw[:i] + bytes(min(b, n - i)) + raw[i + b :]
    return raw[: a % n]  # truncate


MUTATIONS = st.one_of(
    st.tuples(st.just("flip"), st.integers(0, 1 << 30), st.integers(1, 255)),
    st.tuples(st.just("zero"), st.integers(0, 1 << 30), st.integers(1, 4096)),
    st.tuples(st.just("truncate"), st.integers(0, 1 << 30), st.just(0)),
)
FUZZ = settings(
    max_examples=40,
    deadline=20_000,
    derandomize=True,
    database=None,
    suppress_health_check=[HealthCheck.function_scoped_fixture, HealthCheck.too_slow],
)


def damaged(src: Path, m: tuple) -> Path:
    out = Path(tempfile.mkdtemp(prefix="dlovr-fuzz-")) / "damaged.mcap"
    out.write_bytes(mutate(src.read_bytes(), m))
    return out


def check_clean(r, allowed=(0, 2)) -> None:
    """Exit status allowed, no traceback, and an error is one line naming the file."""
    assert r.exception is None or isinstance(r.exception, SystemExit), repr(r.exception)
    assert r.exit_code in allowed, r.output
    assert "Traceback" not in r.output


@pytest.mark.parametrize("variant", ["crc", "no-crc"])
@FUZZ
@given(m=MUTATIONS)
def test_fuzz_replay_verify_never_verifies_changed_data(m, variant, short, short_without_data_crc):
    src = short if variant == "crc" else short_without_data_crc
    bad = damaged(src, m)
    r = cli("replay", bad, "--verify")
    check_clean(r, (0, 1, 2))  # 1: replay diverged (documented in --help)
    if "verified" in r.output:
        assert r.exit_code == 0
        assert contents(bad) is not None and contents(bad)[0] == contents(src)[0], m
    elif r.exit_code == 2:
        assert str(bad) in r.output
    shutil.rmtree(bad.parent)


@pytest.mark.parametrize("variant", ["crc", "no-crc"])
@FUZZ
@given(m=MUTATIONS)
def test_fuzz_states(m, variant, short, short_without_data_crc):
    src = short if variant == "crc" else short_without_data_crc
    bad = damaged(src, m)
    r = cli("states", bad, "--format", "json")
    check_clean(r)
    if r.exit_code == 0:  # only if what it read is what was recorded (or its metadata changed)
        same = contents(bad)
        assert r.output == cli("states", src, "--format", "json").output or (
            same is not None and same[1] != contents(src)[1]
        ), m
    else:
        assert str(bad) in r.output
    shutil.rmtree(bad.parent)


@FUZZ
@given(m=MUTATIONS)
def test_fuzz_compile(m, short_without_data_crc):
    bad = damaged(short_without_data_crc, m)
    r = cli("compile", bad, "-o", bad.parent / "out")
    check_clean(r)
    if r.exit_code == 2:
        assert "FAILED" in r.output and str(bad) in r.output and "0 compiled, 1 failed" in r.output
    shutil.rmtree(bad.parent)


@FUZZ
@given(m=MUTATIONS)
def test_fuzz_recover(m, short):
    bad = damaged(short, m)
    r = cli("recover", bad, "-o", bad.parent / "fixed.mcap")
    check_clean(r)
    if r.exit_code == 0:
        assert (bad.parent / "fixed.mcap").is_file()
        check_clean(cli("states", bad.parent / "fixed.mcap"))
    shutil.rmtree(bad.parent)


# The sample recordings of recordings/ (other scenes, meshes and decompositions embedded, longer),
# as shipped and without their data CRC: fewer examples, as each may replay a whole recording.
SAMPLES = sorted((Path(__file__).parents[2] / "recordings").glob("*.mcap"))
SAMPLE_FUZZ = settings(FUZZ, max_examples=25, deadline=120_000)


@pytest.fixture(scope="module")
def samples(tmp_path_factory) -> dict[tuple[str, str], tuple[Path, str]]:
    """(sample name, "crc" / "no-crc") -> (file, its `states --format json` output)."""
    d = tmp_path_factory.mktemp("samples")
    out = {}
    for p in SAMPLES:
        for variant, data in (("crc", p.read_bytes()), ("no-crc", without_data_crc(p.read_bytes()))):
            f = d / variant / p.name
            f.parent.mkdir(exist_ok=True)
            f.write_bytes(data)
            r = cli("states", f, "--format", "json")
            if variant == "no-crc":  # damage; the tests of this variant reach the checks below it
                assert r.exit_code == 2 and "the data checksum is zero" in r.output, r.output
                with pytest.MonkeyPatch.context() as mp:
                    mp.setattr(integrity, "DATA_CRC_REQUIRED", False)
                    r = cli("states", f, "--format", "json")
            assert r.exit_code == 0, r.output
            out[(p.name, variant)] = (f, r.output)
    return out


@pytest.mark.slow
@pytest.mark.parametrize("variant", ["crc", "no-crc"])
@pytest.mark.parametrize("sample", [p.name for p in SAMPLES])
@SAMPLE_FUZZ
@given(m=MUTATIONS)
def test_fuzz_sample_recordings_through_states_and_recover(m, sample, variant, samples):
    src, want = samples[(sample, variant)]
    bad = damaged(src, m)
    r = cli("states", bad, "--format", "json")
    check_clean(r)
    if r.exit_code == 0:  # only what was recorded (or its metadata changed)
        same = contents(bad)
        assert r.output == want or (same is not None and same[1] != contents(src)[1]), m
    else:
        assert str(bad) in r.output
    check_clean(cli("recover", bad, "-o", bad.parent / "fixed.mcap"))
    shutil.rmtree(bad.parent)


@pytest.mark.parametrize("variant", ["crc", "no-crc"])
@SAMPLE_FUZZ
@given(m=MUTATIONS)
def test_fuzz_a_sample_recording_through_replay_verify_and_compile(m, variant, samples):
    """l_block.mcap: the shortest replay of the samples."""
    src = samples[("l_block.mcap", variant)][0]
    bad = damaged(src, m)
    r = cli("replay", bad, "--verify")
    check_clean(r, (0, 1, 2))
    if "verified" in r.output:
        assert r.exit_code == 0
        assert contents(bad) is not None and contents(bad)[0] == contents(src)[0], m
    elif r.exit_code == 2:
        assert str(bad) in r.output
    r = cli("compile", bad, "-o", bad.parent / "out")
    check_clean(r)
    if r.exit_code == 2:
        assert "FAILED" in r.output and str(bad) in r.output and "0 compiled, 1 failed" in r.output
    shutil.rmtree(bad.parent)


@pytest.mark.slow
@pytest.mark.parametrize("m", [("flip", 5000, 0x10), ("zero", 30000, 500), ("truncate", 60000, 0)])
def test_damaged_files_through_the_real_command_line(short, tmp_path, m):
    bad = tmp_path / "bad.mcap"
    bad.write_bytes(mutate(short.read_bytes(), m))
    for args in (["replay", bad, "--verify"], ["states", bad], ["compile", bad, "-o", tmp_path / "o"]):
        r = subprocess.run(
            [sys.executable, "-m", "dlovr", *map(str, args)], capture_output=True, text=True, timeout=120
        )
        assert r.returncode == 2 and "Traceback" not in r.stderr and str(bad) in r.stderr, r.stderr
        errors = [x for x in r.stderr.splitlines() if x.startswith(("Error", "FAILED"))]
        assert len(errors) == 1, r.stderr
    r = subprocess.run(
        [sys.executable, "-m", "dlovr", "recover", str(bad), "-o", str(tmp_path / "fixed.mcap")],
        capture_output=True,
        text=True,
        timeout=120,
    )
    assert r.returncode in (0, 2) and "Traceback" not in r.stderr


# --------------------------------------------------------------------------------------------------
# recover: every intact chunk
# --------------------------------------------------------------------------------------------------


def chunk_offsets(raw: bytes) -> list[tuple[int, int]]:
    """(offset, length) of every chunk record, from the file's chunk index."""
    out, pos = [], 8
    while pos < len(raw) - 8:
        op, n = raw[pos], struct.unpack_from("<Q", raw, pos + 1)[0]
        if op == 0x06:
            out.append((pos, n))
        if op == 0x0F:
            break
        pos += 9 + n
    return out


@pytest.fixture(scope="module")
def touch(tmp_path_factory) -> Path:
    out = tmp_path_factory.mktemp("touch") / "touch.mcap"
    assert cli("record", "--script", TOUCH, "-o", out).exit_code == 0
    return out


def test_recover_keeps_every_chunk_after_a_damaged_one(touch, tmp_path):
    raw = touch.read_bytes()
    chunks = chunk_offsets(raw)
    pos, n = chunks[len(chunks) // 2]
    bad = tmp_path / "bad.mcap"
    bad.write_bytes(raw[: pos + 40 + n // 2] + bytes([raw[pos + 40 + n // 2] ^ 1]) + raw[pos + 41 + n // 2 :])
    with pytest.raises(RecordingError, match="checksum"):
        Recording(bad)
    rep = recover(bad, tmp_path / "fixed.mcap")
    fixed = Recording(tmp_path / "fixed.mcap")
    want = Recording(touch)
    # the end is there, the damaged chunk is named with its time range, nothing else is missing
    assert fixed.checkpoints()[-1].step == want.checkpoints()[-1].step
    assert len(rep.skipped) >= 1 and "t=" in rep.skipped[0] and "chunk" in rep.skipped[0]
    lost = contents(touch)[0]
    got = contents(tmp_path / "fixed.mcap")[0]
    assert 0 < len(lost) - len(got) < len(lost) / 2
    assert set(got) <= set(lost)
    r = cli("recover", bad, "-o", tmp_path / "fixed2.mcap")
    assert r.exit_code == 0 and "skipped chunk at bytes" in r.output


def test_recover_with_a_damaged_first_chunk_uses_the_summary(touch, tmp_path):
    raw = touch.read_bytes()
    pos, _ = chunk_offsets(raw)[0]  # schemas, channels and the first checkpoint
    bad = tmp_path / "bad.mcap"
    bad.write_bytes(raw[: pos + 60] + bytes([raw[pos + 60] ^ 0xFF]) + raw[pos + 61 :])
    rep = recover(bad, tmp_path / "fixed.mcap")
    fixed = Recording(tmp_path / "fixed.mcap")
    steps = fixed.commands()[0]
    assert steps[0] == 1 and steps[-1] == Recording(touch).commands()[0][-1]  # every command kept
    assert fixed.states() == Recording(touch).states()
    assert rep.skipped and "t=0.000" in rep.skipped[0]

    def macros(path):
        return [(m.classes, m.from_situation, m.to_situation) for m in compile_recording(path).macros]

    assert macros(tmp_path / "fixed.mcap") == macros(touch)


def test_recover_of_a_killed_file_without_channel_definitions_uses_the_format_layout(touch, tmp_path):
    raw = touch.read_bytes()
    chunks = chunk_offsets(raw)
    pos, _ = chunks[0]
    cut = chunks[-3][0]  # killed: no summary, the last chunks missing
    bad = tmp_path / "bad.mcap"
    bad.write_bytes(raw[: pos + 60] + bytes([raw[pos + 60] ^ 0xFF]) + raw[pos + 61 : cut + 100])
    rep = recover(bad, tmp_path / "fixed.mcap")
    assert any("fixed channel layout" in line for line in rep.skipped)
    fixed = Recording(tmp_path / "fixed.mcap")
    steps = fixed.commands()[0]
    assert steps[0] == 1 and steps[-1] == fixed.checkpoints()[-1].step > 500
    assert fixed.states()[-1]["end"] and fixed.states()[-1]["step"] == steps[-1]


def test_recover_of_an_intact_file_is_an_identical_recording(touch, tmp_path):
    rep = recover(touch, tmp_path / "same.mcap")
    assert rep.skipped == ()
    assert contents(tmp_path / "same.mcap")[0] == contents(touch)[0]
    assert replay(tmp_path / "same.mcap", verify=True).divergence is None


def test_nothing_recoverable_only_when_nothing_is(touch, tmp_path):
    bad = tmp_path / "head.mcap"
    bad.write_bytes(touch.read_bytes()[:2000])  # header, metadata, attachments: no chunk
    with pytest.raises(RecordingError, match="nothing recoverable"):
        recover(bad, tmp_path / "x.mcap")
    noise = tmp_path / "noise.mcap"
    noise.write_bytes(b"\x89MCAP0\r\n" + bytes(range(256)) * 40)
    r = cli("recover", noise, "-o", tmp_path / "y.mcap")
    assert r.exit_code == 2 and "nothing recoverable" in r.output


# --------------------------------------------------------------------------------------------------
# No silent overwrites
# --------------------------------------------------------------------------------------------------


def test_record_refuses_to_overwrite_unless_forced(short, tmp_path):
    out = tmp_path / "x.mcap"
    out.write_bytes(b"precious")
    r = cli("record", "--script", TOUCH, "-o", out)
    assert r.exit_code == 2 and "--force" in r.output and str(out) in r.output
    assert out.read_bytes() == b"precious" and len(r.output.strip().splitlines()) == 1
    r = cli("recover", short, "-o", out)
    assert r.exit_code == 2 and out.read_bytes() == b"precious"
    r = cli("recover", short, "-o", out, "--force")
    assert r.exit_code == 0 and Recording(out).commands()[0][-1] == Recording(short).commands()[0][-1]


def test_record_force_overwrites(tmp_path):
    out = tmp_path / "x.mcap"
    out.write_bytes(b"old")
    script = tmp_path / "s.script.toml"
    script.write_text(SHORT_SCRIPT)
    r = cli("record", "--script", script, "-o", out, "--force")
    # the script's 600 steps, and 68 more at its last pose while the gripper (0.25 m/s) arrives there
    assert r.exit_code == 0 and Recording(out).commands()[0][-1] == 668


def test_compile_refuses_two_recordings_into_one_program(short, tmp_path):
    for d in ("a", "b"):
        (tmp_path / d).mkdir()
        shutil.copy(short, tmp_path / d / "demo.mcap")
    r = cli("compile", tmp_path / "a" / "demo.mcap", tmp_path / "b" / "demo.mcap", "-o", tmp_path / "out")
    assert r.exit_code == 2 and len(r.output.strip().splitlines()) == 1
    assert str(tmp_path / "a" / "demo.mcap") in r.output and str(tmp_path / "b" / "demo.mcap") in r.output
    assert not (tmp_path / "out").exists()
    r = cli("compile", tmp_path / "a" / "demo.mcap", tmp_path / "b" / "demo.mcap")  # beside each: fine
    assert r.exit_code == 0 and "2 compiled, 0 failed" in r.output
    assert all((tmp_path / d / "demo.program.json").is_file() for d in ("a", "b"))
    same = cli("compile", tmp_path / "a" / "demo.mcap", tmp_path / "a" / ".." / "a" / "demo.mcap", "--force")
    assert same.exit_code == 0 and "1 compiled, 0 failed" in same.output  # one file named twice: once


def test_compile_of_a_folder_with_a_damaged_file_compiles_the_others(short, tmp_path):
    src = tmp_path / "in"
    src.mkdir()
    raw = short.read_bytes()
    (src / "a.mcap").write_bytes(raw)
    (src / "b.mcap").write_bytes(raw)
    pos, n = chunk_offsets(raw)[1]
    (src / "bad.mcap").write_bytes(raw[: pos + n // 2] + b"\0" * 64 + raw[pos + n // 2 + 64 :])
    for workers in ("1", "2"):
        r = cli("compile", src, "-o", tmp_path / f"out{workers}", "--workers", workers)
        assert r.exit_code == 2 and "2 compiled, 1 failed" in r.output, r.output
        failed = [x for x in r.output.splitlines() if x.startswith("FAILED")]
        assert len(failed) == 1 and str(src / "bad.mcap") in failed[0]
        assert (tmp_path / f"out{workers}" / "a.program.json").is_file()
    again = cli("compile", src, "-o", tmp_path / "out1")
    assert "0 compiled, 2 skipped (unchanged), 1 failed" in again.output and again.exit_code == 2


# --------------------------------------------------------------------------------------------------
# A chunk whose header reads as an empty chunk
# --------------------------------------------------------------------------------------------------


def _chunks_of(path: Path, topic: str) -> list[int]:
    """Offsets of the chunks that hold messages of ``topic`` only (from the summary's chunk index)."""
    from mcap.reader import make_reader

    with open(path, "rb") as fh:
        summary = make_reader(fh).get_summary()
    return [
        ci.chunk_start_offset
        for ci in summary.chunk_indexes
        if {summary.channels[c].topic for c in ci.message_index_offsets} == {topic}
    ]


@pytest.mark.parametrize("topic", ["/dlovr/checkpoint", "/dlovr/contact_states"])
def test_a_chunk_that_reads_as_empty_is_not_silently_skipped(short_without_data_crc, tmp_path, topic):
    """Zeroed from its length to its records' length (CRC 0: unchecked; compression "": none), a chunk
    parses as an intact chunk without messages: what it held is missing, and the summary's message
    counts say so. Found by fuzzing a sample recording (l_block.mcap without its data CRC), whose
    replay was then "verified" with one checkpoint fewer."""
    raw = short_without_data_crc.read_bytes()
    offsets = _chunks_of(short_without_data_crc, topic)
    assert offsets, topic
    pos = offsets[len(offsets) // 2]
    bad = tmp_path / "bad.mcap"
    bad.write_bytes(raw[: pos + 1] + bytes(48) + raw[pos + 49 :])
    r = cli("replay", bad, "--verify")
    check_clean(r, (2,))
    assert "verified" not in r.output and str(bad) in r.output and topic in r.output, r.output
    if topic == "/dlovr/contact_states":
        r = cli("states", bad)
        check_clean(r, (2,))
        assert str(bad) in r.output and topic in r.output, r.output
