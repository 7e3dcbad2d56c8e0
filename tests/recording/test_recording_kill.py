"""Signals during `dlovr record`: SIGTERM and Ctrl-C (SIGINT) at several moments leave a finished file
that verifies; after SIGKILL, `recover` gives a file that verifies and lacks at most the last 2 s."""

from __future__ import annotations

import json
import shutil
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

from dlovr.recording import Recording, recover, replay
from dlovr.recording.format import TOPIC_CHECKPOINT
from dlovr.recording.integrity import scan

SCRIPT = Path(__file__).parents[1] / "data" / "touch_table.script.toml"


@pytest.fixture(scope="module")
def long_script(tmp_path_factory) -> Path:
    """The touch script followed by a 30 s drag (it never ends before the signal)."""
    p = tmp_path_factory.mktemp("kill") / "long.script.toml"
    p.write_text(SCRIPT.read_text() + "\n[[waypoints]]\npos = [-0.45, 0.3, 0.03]\nduration = 30.0\n")
    return p


def recorded_seconds(path: Path) -> float:
    """Simulated time up to the last checkpoint already in the (unfinished) file; -1 if none yet."""
    if not path.exists():
        return -1.0
    res = scan(path.read_bytes())
    ids = {cid for cid, c in {**res.summary_channels, **res.channels}.items() if c.topic == TOPIC_CHECKPOINT}
    steps = [json.loads(m.data)["step"] for c in res.chunks for m in c if m.channel_id in ids]
    return max(steps, default=-500) * 0.002


def start(script: Path, out: Path, err: Path) -> subprocess.Popen:
    with open(err, "w") as fh:
        return subprocess.Popen(
            [sys.executable, "-m", "dlovr", "record", "--script", str(script), "-o", str(out)],
            stdout=subprocess.DEVNULL,
            stderr=fh,
        )


def wait_for(proc: subprocess.Popen, out: Path, err: Path, seconds: float, extra: float) -> None:
    """Until the file holds ``seconds`` of simulated time, then ``extra`` s more (wall time)."""
    deadline = time.time() + 90
    while recorded_seconds(out) < seconds:
        assert proc.poll() is None, f"recording ended early: {err.read_text()[-2000:]}"
        assert time.time() < deadline, "recording too slow"
        time.sleep(0.05)
    time.sleep(extra)
    assert proc.poll() is None, f"recording ended early: {err.read_text()[-2000:]}"


def verified(path: Path) -> float:
    """Replay with --verify; return the recording's length (s of simulated time)."""
    res = replay(path, verify=True)
    assert res.divergence is None, res.divergence
    return res.sim_time


@pytest.mark.parametrize(
    ("sig", "seconds", "extra"),
    [
        (signal.SIGTERM, 0.0, 0.0),  # at once: the first second is not even complete
        (signal.SIGTERM, 1.0, 0.13),
        (signal.SIGTERM, 2.0, 0.37),
        (signal.SIGINT, 0.0, 0.05),
        (signal.SIGINT, 2.0, 0.21),
    ],
)
@pytest.mark.slow
def test_signal_leaves_a_finished_file_that_verifies(long_script, tmp_path, sig, seconds, extra):
    out, err = tmp_path / "rec.mcap", tmp_path / "stderr.txt"
    proc = start(long_script, out, err)
    wait_for(proc, out, err, seconds, extra)
    proc.send_signal(sig)
    rc = proc.wait(timeout=60)
    text = err.read_text()
    assert rc == 128 + sig, text
    assert "Traceback" not in text and "Aborted" not in text
    lines = [x for x in text.splitlines() if x.startswith("interrupted")]
    assert len(lines) == 1 and f"({sig.name})" in lines[0] and str(out) in lines[0], text
    length = verified(out)
    assert f"{length:.3f} s of simulated time" in lines[0]
    assert length >= seconds


@pytest.mark.slow
def test_sigkill_then_recover_verifies_and_loses_at_most_2_s(long_script, tmp_path):
    """The file a SIGKILL leaves is the file on disk at that moment: freeze the writer (SIGSTOP) and
    copy it; then let it finish on SIGTERM, which says how far it had got; then kill another writer
    for real."""
    out, err = tmp_path / "rec.mcap", tmp_path / "stderr.txt"
    proc = start(long_script, out, err)
    wait_for(proc, out, err, 2.0, 0.45)
    proc.send_signal(signal.SIGSTOP)
    time.sleep(0.2)
    frozen = tmp_path / "frozen.mcap"
    shutil.copy(out, frozen)
    proc.send_signal(signal.SIGTERM)
    proc.send_signal(signal.SIGCONT)
    assert proc.wait(timeout=60) == 143
    reached = verified(out)  # where the writer was when frozen (plus at most one step)
    rep = recover(frozen, tmp_path / "fixed.mcap")
    kept = verified(tmp_path / "fixed.mcap")
    assert reached - 2.0 <= kept <= reached, (reached, kept, rep.skipped)
    assert Recording(tmp_path / "fixed.mcap").states()[-1]["end"]

    out2, err2 = tmp_path / "killed.mcap", tmp_path / "stderr2.txt"
    proc = start(long_script, out2, err2)
    wait_for(proc, out2, err2, 3.0, 0.29)
    proc.kill()
    proc.wait(timeout=30)
    r = subprocess.run(
        [sys.executable, "-m", "dlovr", "recover", str(out2), "-o", str(tmp_path / "fixed2.mcap")],
        capture_output=True,
        text=True,
        timeout=60,
    )
    assert r.returncode == 0, r.stderr
    r = subprocess.run(
        [sys.executable, "-m", "dlovr", "replay", "--verify", str(tmp_path / "fixed2.mcap")],
        capture_output=True,
        text=True,
        timeout=120,
    )
    assert r.returncode == 0 and "verified" in r.stdout, r.stdout + r.stderr
    assert verified(tmp_path / "fixed2.mcap") >= 3.0
