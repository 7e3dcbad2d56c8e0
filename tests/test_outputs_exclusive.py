"""Outputs are created exclusively and written atomically: two writers of one file never share it
(the second is refused, or with --force the first finished file is replaced whole), a full disk leaves
the previous file whole, every command refuses an existing output without --force, and a batch
checks its output folder before its work."""

from __future__ import annotations

import errno
import os
import subprocess
import sys
from pathlib import Path

import pytest
from click.testing import CliRunner
from mcap.reader import make_reader

from dlovr.cli import main
from dlovr.outputs import (
    OutputError,
    StreamOutput,
    atomic_output,
    being_written,
    check_writable_dir,
    write_output,
)
from dlovr.recording import Recorder, SceneBundle

ROOT = Path(__file__).resolve().parent.parent
SAMPLE = ROOT / "recordings" / "table.mcap"
SHORT = 'scene = "table"\n[[waypoints]]\npos = [0.0, 0.0, 0.68]\nduration = 0.2\n'


def cli(*args):
    return CliRunner().invoke(main, [str(a) for a in args])


def one_line_exit_2(r, path, why: str) -> None:
    assert r.exit_code == 2, r.output
    last = r.output.strip().splitlines()[-1]
    assert last.startswith(f"Error: {path}: ") and why in last, r.output
    assert "Traceback" not in r.output


@pytest.fixture(scope="module")
def bundle() -> SceneBundle:
    from dlovr.scene import load_scene

    return SceneBundle.from_path(load_scene("table").path)


def recorder(path: Path, bundle: SceneBundle, overwrite: bool) -> Recorder:
    return Recorder(path, bundle, scene_name="table", dt=0.002, t0_ns=0, overwrite=overwrite)


def valid_mcap(path: Path) -> int:
    """Messages in a finished MCAP file whose CRCs all check."""
    with open(path, "rb") as fh:
        return sum(1 for _ in make_reader(fh, validate_crcs=True).iter_messages())


def write_steps(rec: Recorder, n: int) -> None:
    for k in range(n):
        rec.command(k, [0.0, 0.0, 0.6 + k * 1e-4], [1.0, 0.0, 0.0, 0.0])


def test_a_second_writer_of_one_recording_is_refused(tmp_path, bundle):
    out = tmp_path / "same.mcap"
    first = recorder(out, bundle, overwrite=False)
    with pytest.raises(OutputError, match=r"same\.mcap: exists; give --force"):
        recorder(out, bundle, overwrite=False)
    assert being_written(out)  # the first writer holds it
    write_steps(first, 300)
    first.close()
    assert not being_written(out)
    assert valid_mcap(out) > 0
    assert sorted(p.name for p in tmp_path.iterdir()) == ["same.mcap"]


def test_overwriting_writers_each_leave_a_whole_file(tmp_path, bundle):
    """With --force two writers at once: the old file stays whole until a new one is finished, and the
    file is always one whole recording (never two interleaved: the checksum mismatch of issue 31)."""
    out = tmp_path / "same.mcap"
    out.write_bytes(b"old recording")
    a, b = recorder(out, bundle, overwrite=True), recorder(out, bundle, overwrite=True)
    write_steps(a, 700)
    write_steps(b, 500)
    assert out.read_bytes() == b"old recording"
    a.close()
    n_a = valid_mcap(out)
    b.close()
    assert valid_mcap(out) > 0 and valid_mcap(out) != n_a  # b's, whole
    assert sorted(p.name for p in tmp_path.iterdir()) == ["same.mcap"]


def test_a_writer_that_fails_leaves_the_previous_file(tmp_path, bundle, monkeypatch):
    out = tmp_path / "r.mcap"
    out.write_bytes(b"previous")
    rec = recorder(out, bundle, overwrite=True)

    def full(*a, **k):
        raise OSError(errno.ENOSPC, "No space left on device")

    monkeypatch.setattr(rec._w, "finish", full)
    with pytest.raises(OSError):
        rec.close()
    assert out.read_bytes() == b"previous"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["r.mcap"]


def test_record_refuses_a_file_another_writer_created_meanwhile(tmp_path, monkeypatch):
    """The race of issue 31: the other writer creates the file after this one checked for it."""
    import dlovr.cli.record as record_cli

    script = tmp_path / "s.script.toml"
    script.write_text(SHORT)
    out = tmp_path / "same.mcap"
    real = record_cli.refuse_existing

    def then_the_other_writer(path, force):
        real(path, force)
        Path(path).write_bytes(b"the other writer's recording")

    monkeypatch.setattr(record_cli, "refuse_existing", then_the_other_writer)
    one_line_exit_2(cli("record", "--script", script, "-o", out), out, "exists; give --force")
    assert out.read_bytes() == b"the other writer's recording"


def test_atomic_output_without_force_never_replaces(tmp_path):
    target = tmp_path / "n.json"
    with pytest.raises(OutputError, match="exists"), atomic_output(target, force=False) as tmp:
        tmp.write_text("mine")
        target.write_text("theirs")  # another writer, meanwhile
    assert target.read_text() == "theirs"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["n.json"]


def test_a_full_disk_keeps_the_previous_file(tmp_path, monkeypatch):
    """`dlovr network -o existing.json` on a full disk destroyed the previous file (issue 31, item 6)."""
    target = tmp_path / "net.json"
    target.write_text("previous")

    def full(self, *a, **k):
        raise OSError(errno.ENOSPC, "No space left on device")

    monkeypatch.setattr(Path, "write_text", full)
    with pytest.raises(OutputError, match=r"net\.json: cannot write: No space left on device"):
        write_output(target, "{}", force=True)
    monkeypatch.undo()
    assert target.read_text() == "previous"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["net.json"]


def test_every_command_refuses_an_existing_output_without_force(tmp_path):
    existing = tmp_path / "old.txt"
    existing.write_text("precious")
    for args in (
        ("scene", "export", "table", "-o", existing),
        ("network", SAMPLE, "-o", existing),
        ("network", SAMPLE, "-o", tmp_path / "n.json", "--html", existing),
        ("compile", "--network", existing, "-o", existing),
        ("recover", SAMPLE, "-o", existing),
    ):
        one_line_exit_2(cli(*args), existing, "exists; give --force")
    assert existing.read_text() == "precious"
    assert not (tmp_path / "n.json").exists()
    r = cli("scene", "export", "table", "-o", existing, "--force")
    assert r.exit_code == 0 and existing.read_text().startswith("<mujoco"), r.output


def test_a_batch_output_folder_is_checked_before_the_batch(tmp_path):
    if os.geteuid() != 0:  # a read-only folder
        d = tmp_path / "ro"
        d.mkdir()
        d.chmod(0o500)
        try:
            with pytest.raises(OutputError, match=r"ro: cannot write: Permission denied"):
                check_writable_dir(d)
        finally:
            d.chmod(0o700)
    elif Path("/proc/self").is_dir():  # root writes into read-only folders, not into /proc
        with pytest.raises(OutputError, match=r"^/proc/self: cannot write: "):
            check_writable_dir("/proc/self")
    assert check_writable_dir(tmp_path / "new") == tmp_path / "new" and not list((tmp_path / "new").iterdir())


def test_stream_output_refuses_and_replaces(tmp_path):
    out = tmp_path / "x.bin"
    s = StreamOutput(out)
    s.fh.write(b"one")
    assert s.commit() == out and out.read_bytes() == b"one"
    with pytest.raises(OutputError, match="exists"):
        StreamOutput(out)
    s = StreamOutput(out, overwrite=True)
    s.fh.write(b"two")
    assert out.read_bytes() == b"one"
    s.commit()
    assert out.read_bytes() == b"two" and sorted(p.name for p in tmp_path.iterdir()) == ["x.bin"]


@pytest.mark.slow
def test_two_record_commands_at_once(tmp_path):
    """Two `dlovr record -o same.mcap` at once (issue 31: both said "wrote" and the file's checksum
    failed): one writes it, the other is refused with one line and exit 2; the file verifies."""
    script = tmp_path / "s.script.toml"
    script.write_text(SHORT)
    out = tmp_path / "same.mcap"
    cmd = [sys.executable, "-m", "dlovr", "record", "--script", str(script), "-o", str(out)]
    procs = [subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True) for _ in "ab"]
    results = [(p.wait(timeout=120), p.stdout.read(), p.stderr.read()) for p in procs]  # type: ignore[union-attr]
    codes = sorted(rc for rc, _, _ in results)
    assert codes == [0, 2], results
    (loser,) = [err for rc, _, err in results if rc == 2]
    assert loser.strip().splitlines()[-1] == f"Error: {out}: exists; give --force to overwrite it"
    assert valid_mcap(out) > 0
