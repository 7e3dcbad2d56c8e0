"""A batch stops like `record` on a signal: its workers are stopped (none lives on holding the caller's
pipes), the results finished before the signal come with the interruption (the commands write them),
and workers end when their parent process is killed."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import threading
import time
from pathlib import Path

import pytest
from batch_tasks import pid_then_sleep
from click.testing import CliRunner

from dlovr import signals
from dlovr.batch import Task, TaskResult, finished, run_batch

HERE = Path(__file__).parent
ROOT = HERE.parents[1]


def alive(pid: int) -> bool:
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    try:  # a zombie (exited, not yet reaped) is not alive
        return Path(f"/proc/{pid}/status").read_text().split("State:")[1].split()[0] != "Z"
    except (OSError, IndexError):
        return True


def wait_pids(folder: Path, n: int, timeout: float = 60.0) -> list[int]:
    end = time.monotonic() + timeout
    while time.monotonic() < end:
        files = list(folder.glob("*.pid"))
        if len(files) >= n:
            time.sleep(0.05)
            return [int(p.read_text()) for p in files]
        time.sleep(0.02)
    raise AssertionError("the workers never started")


@pytest.mark.parametrize("sig", [signal.SIGTERM, signal.SIGINT], ids=["SIGTERM", "SIGINT"])
def test_a_signal_stops_the_workers_and_keeps_the_finished_results(tmp_path, sig):
    tasks = [Task(f"t{k}", (k, str(tmp_path))) for k in range(4)]
    expected = signals.SignalExit if sig == signal.SIGTERM else KeyboardInterrupt
    with signals.installed(), pytest.raises(expected) as info:
        for r in run_batch(pid_then_sleep, tasks, workers=2, progress=False):
            if r.key == "t0":  # task 0 finished; task 1 sleeps in the other worker
                wait_pids(tmp_path, 2)
                threading.Timer(0.2, os.kill, (os.getpid(), sig)).start()
    signals.clear()
    done = finished(info.value)
    assert [r.key for r in done] == ["t0"] and isinstance(done[0], TaskResult) and done[0].value == 0
    pids = [int(p.read_text()) for p in tmp_path.glob("*.pid") if p.stem != "0"]
    assert pids and not any(alive(p) for p in pids), "a worker lives on"


@pytest.mark.slow
def test_workers_end_when_their_parent_is_killed(tmp_path):
    """SIGKILL to the batch's process: its workers notice within a second and end (before, they
    lived on and held the caller's pipes, so `| tee` hung)."""
    code = (
        "import sys\n"
        f"sys.path[:0] = [{str(HERE)!r}, {str(ROOT)!r}]\n"
        "from batch_tasks import pid_then_sleep\n"
        "from dlovr.batch import Task, run_batch\n"
        f"tasks = [Task(f't{{k}}', (k + 1, {str(tmp_path)!r})) for k in range(2)]\n"
        "list(run_batch(pid_then_sleep, tasks, workers=2, progress=False))\n"
    )
    proc = subprocess.Popen([sys.executable, "-c", code], stdout=subprocess.PIPE, stderr=subprocess.PIPE)
    try:
        pids = wait_pids(tmp_path, 2)
        proc.kill()
        proc.wait(timeout=30)
        t0 = time.monotonic()
        while any(alive(p) for p in pids) and time.monotonic() - t0 < 15:
            time.sleep(0.1)
        assert not any(alive(p) for p in pids), "orphaned workers live on"
        assert time.monotonic() - t0 < 5
    finally:
        proc.kill()
        for p in wait_pids(tmp_path, 0, 0.1):
            if alive(p):
                os.kill(p, signal.SIGKILL)


def test_record_trials_interrupted_lists_the_finished_demonstrations(tmp_path, monkeypatch):
    """Ctrl-C on `record --trials`: the demonstrations finished so far go into demos.json, one line,
    exit 130 (before: `Aborted!`, exit 1, no index)."""
    import json

    import dlovr.execution.demo_sets as demo_sets
    from dlovr.batch import FINISHED
    from dlovr.cli import main

    script = tmp_path / "s.script.toml"
    script.write_text('scene = "table"\n[[waypoints]]\npos = [0.0, 0.0, 0.68]\nduration = 0.2\n')
    out = tmp_path / "demos"
    first = {"trial": 0, "seed": 0, "path": str(out / "demo_000.mcap"), "error": None, "situations": 2}

    def interrupted(setup, n, **kw):
        e = KeyboardInterrupt()
        setattr(e, FINISHED, [TaskResult("demo 0", 0, first)])
        raise e

    monkeypatch.setattr(demo_sets, "record_demos", interrupted)
    r = CliRunner().invoke(main, ["record", "--script", str(script), "-o", f"{out}/", "--trials", "3"])
    assert r.exit_code == 130, r.output
    assert "Aborted" not in r.output and "Traceback" not in r.output
    assert r.output.strip().splitlines()[-1] == (
        f"interrupted (SIGINT): 1 of 3 demonstrations finished, listed in {out}/demos.json "
        "(a recording in progress is kept, finished where it stopped)"
    )
    index = json.loads((out / "demos.json").read_text())
    assert [d["trial"] for d in index["demonstrations"]] == [0]


def test_run_trials_interrupted_is_one_line_and_130(tmp_path, monkeypatch):
    """Ctrl-C on `run --trials`: one line, exit 130 (before: `Aborted!`, exit 1); a folder checked
    before the batch."""
    import dlovr.execution.trials as trials
    from dlovr.batch import FINISHED
    from dlovr.cli import main

    def interrupted(setup, n, **kw):
        e = KeyboardInterrupt()
        setattr(e, FINISHED, [])
        raise e

    monkeypatch.setattr(trials, "run_trials", interrupted)
    prog = ROOT / "recordings" / "programs" / "table.program.json"
    out = tmp_path / "t"
    r = CliRunner().invoke(main, ["run", str(prog), "--trials", "3", "-o", str(out)])
    assert r.exit_code == 130, r.output
    last = r.output.strip().splitlines()[-1]
    assert last == "interrupted (SIGINT): 0 of 3 trials finished, no results written"
    assert "Aborted" not in r.output and out.is_dir() and list(out.iterdir()) == []
