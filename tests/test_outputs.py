"""Output files of every command: unwritable paths give one line and exit 2, missing parent
directories are created, and a failed write leaves no partial file."""

from __future__ import annotations

import os
import resource
import signal
import subprocess
import sys
from pathlib import Path

import pytest
from click.testing import CliRunner

from dlovr.cli import main
from dlovr.outputs import OutputError, atomic_output

ROOT = Path(__file__).resolve().parent.parent
SAMPLE = ROOT / "recordings" / "table.mcap"
LINUX = sys.platform.startswith("linux") and Path("/proc/self").is_dir() and Path("/dev/full").exists()


def cli(*args):
    return CliRunner().invoke(main, [str(a) for a in args])


@pytest.fixture(scope="module")
def short_script(tmp_path_factory) -> Path:
    """A 0.2 s demonstration on the table (a quick record)."""
    p = tmp_path_factory.mktemp("script") / "short.script.toml"
    p.write_text('scene = "table"\n[[waypoints]]\npos = [0.0, 0.0, 0.68]\nduration = 0.2\n')
    return p


def one_line_exit_2(r, path: str, why: str) -> None:
    assert r.exit_code == 2, r.output
    lines = r.output.strip().splitlines()
    assert lines[-1].startswith(f"Error: {path}: ") and why in lines[-1], r.output
    assert "Traceback" not in r.output and isinstance(r.exception, SystemExit)


@pytest.mark.skipif(not LINUX, reason="needs Linux's /proc and /dev/full")
def test_unwritable_outputs_give_one_line_and_exit_2(short_script, tmp_path):
    for args, path, why in (
        (("record", "--script", short_script, "-o", "/proc/x.mcap"), "/proc/x.mcap", "No such file"),
        (("record", "--script", short_script, "-o", "/dev/full", "--force"), "/dev/full", "No space left"),
        (("demo", "--script", short_script, "-o", "/proc/d.mcap"), "/proc/d.mcap", "No such file"),
        (("recover", SAMPLE, "-o", "/proc/f.mcap"), "/proc/f.mcap", "No such file"),
        (("recover", SAMPLE, "-o", "/dev/full", "--force"), "/dev/full", "No space left"),
        (("compile", SAMPLE, "-o", "/proc/xx"), "/proc/xx", "cannot create directory"),
        (("scene", "export", "table", "-o", "/proc/m.xml"), "/proc/m.xml", "No such file"),
        (("scene", "export", "table", "-o", "/dev/full", "--force"), "/dev/full", "No space left"),
    ):
        one_line_exit_2(cli(*args), path, why)
    assert not Path("/proc/x.mcap").exists() and Path("/dev/full").is_char_device()
    # without --force an existing output (even a device) is refused before anything is written
    one_line_exit_2(cli("record", "--script", short_script, "-o", "/dev/full"), "/dev/full", "exists")


@pytest.mark.slow
@pytest.mark.skipif(not LINUX, reason="needs Linux's /dev/full")
def test_unwritable_output_in_a_fresh_process_has_no_traceback(short_script):
    r = subprocess.run(
        [sys.executable, "-m", "dlovr", "record", "--script", str(short_script), "-o", "/dev/full", "-f"],
        capture_output=True,
        text=True,
    )
    assert r.returncode == 2 and "Traceback" not in r.stderr
    assert r.stderr.strip().splitlines()[-1] == "Error: /dev/full: cannot write: No space left on device"


def test_missing_parent_directories_are_created_by_every_command(short_script, tmp_path):
    rec = tmp_path / "a" / "b" / "rec.mcap"
    r = cli("record", "--script", short_script, "-o", rec)
    assert r.exit_code == 0 and rec.is_file(), r.output
    r = cli("demo", "--script", short_script, "-o", tmp_path / "c" / "demo.mcap")
    assert r.exit_code == 0 and (tmp_path / "c" / "demo.mcap").is_file(), r.output
    r = cli("recover", rec, "-o", tmp_path / "d" / "e" / "fixed.mcap")
    assert r.exit_code == 0 and (tmp_path / "d" / "e" / "fixed.mcap").is_file(), r.output
    r = cli("compile", rec, "-o", tmp_path / "f" / "g")
    assert r.exit_code == 0 and (tmp_path / "f" / "g" / "rec.program.json").is_file(), r.output
    r = cli("scene", "export", "table", "-o", tmp_path / "h" / "model.xml")
    assert r.exit_code == 0 and (tmp_path / "h" / "model.xml").is_file(), r.output
    leftovers = [p for p in tmp_path.rglob("*") if p.name.endswith(".part")]
    assert leftovers == []


def _small_files(limit: int):
    def apply() -> None:  # in the child: writes beyond `limit` bytes fail with EFBIG ("File too large")
        signal.signal(signal.SIGXFSZ, signal.SIG_IGN)
        resource.setrlimit(resource.RLIMIT_FSIZE, (limit, limit))

    return apply


@pytest.mark.slow
@pytest.mark.skipif(not LINUX, reason="needs RLIMIT_FSIZE")
def test_a_write_that_fails_halfway_leaves_no_partial_file(short_script, tmp_path):
    """A file-size limit makes the disk "full" halfway through each output: one line, exit 2, and
    neither the output nor a temporary file is left."""
    cases = (
        (["record", "--script", str(short_script), "-o", str(tmp_path / "rec.mcap")], 60_000),
        (["recover", str(SAMPLE), "-o", str(tmp_path / "fixed.mcap")], 60_000),
        (["scene", "export", "table", "-o", str(tmp_path / "model.xml")], 2_000),
    )
    for args, limit in cases:
        cmd = [sys.executable, "-m", "dlovr", *args]
        r = subprocess.run(cmd, capture_output=True, text=True, preexec_fn=_small_files(limit))
        assert r.returncode == 2, (args, r.stderr[-2000:])
        assert "Traceback" not in r.stderr and "cannot write: File too large" in r.stderr, r.stderr[-2000:]
    assert sorted(p.name for p in tmp_path.iterdir()) == []


def test_atomic_output_removes_its_temporary_file_on_any_failure(tmp_path):
    target = tmp_path / "out.txt"
    target.write_text("old")
    for exc in (OSError(28, "No space left on device"), KeyboardInterrupt(), SystemExit(143)):
        with pytest.raises((OutputError, type(exc))), atomic_output(target) as tmp:
            tmp.write_text("half")
            raise exc
        assert target.read_text() == "old" and sorted(p.name for p in tmp_path.iterdir()) == ["out.txt"]
    with atomic_output(tmp_path / "new" / "x.txt") as tmp:
        tmp.write_text("done")
    assert (tmp_path / "new" / "x.txt").read_text() == "done"
    assert sorted(p.name for p in (tmp_path / "new").iterdir()) == ["x.txt"]
    mode = (tmp_path / "new" / "x.txt").stat().st_mode & 0o777
    umask = os.umask(0)
    os.umask(umask)
    assert mode == 0o666 & ~umask  # the usual permissions, not a temporary file's 0600


def test_demo_refuses_to_overwrite_a_recording_unless_forced(short_script, tmp_path):
    out = tmp_path / "d.mcap"
    out.write_bytes(b"precious")
    one_line_exit_2(cli("demo", "--script", short_script, "-o", out), str(out), "exists")
    assert out.read_bytes() == b"precious"
    r = cli("demo", "--script", short_script, "-o", out, "--force")
    assert r.exit_code == 0, r.output
    assert out.read_bytes()[:8] == b"\x89MCAP0\r\n"
