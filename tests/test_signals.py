"""SIGINT (Ctrl-C) and SIGTERM at any moment of a command, start-up included: one line, exit 130 or 143,
never lost (a dependency that swallows ``KeyboardInterrupt`` while it is imported does not make the
command run to the end with exit 0), and a recording in progress kept, finished."""

from __future__ import annotations

import importlib
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest
from click.testing import CliRunner

from dlovr import signals
from dlovr.cli import main
from dlovr.recording import Recording, StopSignals

ROOT = Path(__file__).resolve().parent.parent
TOUCH = Path(__file__).parent / "data" / "touch_table.script.toml"


@pytest.fixture(autouse=True)
def _no_pending():
    signals.clear()
    yield
    signals.clear()


@pytest.mark.parametrize("sig", [signal.SIGINT, signal.SIGTERM], ids=["SIGINT", "SIGTERM"])
def test_a_swallowed_signal_still_ends_the_command(monkeypatch, sig):
    """What trimesh's ``except BaseException`` around its imports did: the signal's exception is
    caught inside a dependency; the command goes on, and ends with the signal's status when it
    returns."""
    import dlovr.cli.scene as scene_cli

    real = scene_cli.scenes_cmd.callback
    assert real is not None

    def swallowing(*a, **kw):
        try:
            signal.raise_signal(sig)
        except BaseException:  # what the dependency does
            pass
        return real(*a, **kw)

    monkeypatch.setattr(scene_cli.scenes_cmd, "callback", swallowing)
    r = CliRunner().invoke(main, ["scenes"])
    assert r.exit_code == 128 + sig, r.output
    assert r.output.strip().splitlines()[-1] == f"interrupted ({sig.name})"
    assert "Aborted" not in r.output and signals.pending() is None


def test_a_signal_during_start_up_ends_the_command_when_it_is_ready():
    signals.note(signal.SIGTERM)
    r = CliRunner().invoke(main, ["scenes"])
    assert r.exit_code == 143 and r.output.strip() == "interrupted (SIGTERM)", r.output


def test_ctrl_c_inside_a_command_is_130_without_aborted(monkeypatch):
    import dlovr.cli.scene as scene_cli

    def interrupted(*a, **kw):
        raise KeyboardInterrupt

    monkeypatch.setattr(scene_cli.scenes_cmd, "callback", interrupted)
    r = CliRunner().invoke(main, ["scenes"])
    assert r.exit_code == 130 and "Aborted" not in r.output
    assert r.output.strip().splitlines()[-1] == "interrupted (SIGINT)"


def test_a_recording_loop_takes_a_pending_signal_as_its_stop_request():
    signals.note(signal.SIGINT)
    with StopSignals() as stop:
        assert stop.signum == signal.SIGINT and stop.exit_code == 130
    assert signals.pending() is None  # handled there: the command says so itself


def _record(out: Path) -> subprocess.Popen:
    env = {**os.environ, "PYTHONPATH": str(ROOT)}
    cmd = [sys.executable, "-m", "dlovr", "record", "--script", str(TOUCH), "-o", str(out)]
    return subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, env=env)


def _wait_until_dlovr_runs(pid: int) -> None:
    """Until the process catches SIGTERM (``dlovr/__init__.py`` has run :func:`signals.defer`): before
    that, Python itself is starting and a signal ends it the default way (status -2/-15)."""
    deadline = time.monotonic() + 30
    while time.monotonic() < deadline:
        with open(f"/proc/{pid}/status") as fh:
            caught = next(int(x.split()[1], 16) for x in fh if x.startswith("SigCgt:"))
        if caught >> (signal.SIGTERM - 1) & 1:
            return
        time.sleep(0.002)
    raise AssertionError("the command never started")


@pytest.mark.slow
@pytest.mark.skipif(not Path("/proc/self/status").exists(), reason="reads /proc")
def test_signals_at_every_moment_of_record_start_up(tmp_path):
    """Signals sent from the first moment dlovr's code runs (the command line still being imported)
    to the recording under way: each ends `dlovr record` with one line and 130/143, and a file left
    behind is a finished recording. Before, a signal in the first 0.5-2 s was lost (exit 0, the whole
    recording ran) or gave a traceback or `Aborted!` with exit 1. (The last moment is when the
    recording's file appears, not a fixed 2 s: on a fast machine the whole command takes 2 s.)"""
    moments = [(signal.SIGINT, 0.0), (signal.SIGTERM, 0.1), (signal.SIGINT, 0.4), (signal.SIGTERM, 0.9),
               (signal.SIGINT, None)]
    for k, (sig, delay) in enumerate(moments):
        out = tmp_path / f"rec{k}.mcap"
        proc = _record(out)
        _wait_until_dlovr_runs(proc.pid)
        if delay is None:  # while it records
            deadline = time.monotonic() + 60
            while not out.exists() and proc.poll() is None and time.monotonic() < deadline:
                time.sleep(0.002)
        else:
            time.sleep(delay)
        proc.send_signal(sig)
        _, err = proc.communicate(timeout=120)
        text = err.replace("\r", "\n")
        assert proc.returncode == 128 + sig, (sig.name, delay, text[-2000:])
        assert "Traceback" not in text and "Aborted" not in text, text
        last = [x for x in text.splitlines() if x.strip()][-1]
        assert last.startswith(f"interrupted ({sig.name})"), (delay, last)
        if out.exists():  # it had begun recording: the file is finished and valid
            assert str(out) in last
            assert Recording(out).checkpoints()


def test_a_signal_during_an_import_is_remembered_not_raised(tmp_path, monkeypatch):
    """A SIGINT while a module is being imported must not interrupt the import (a dependency would be
    left half-imported): it stays pending and ends the command at its next check."""
    mod = tmp_path / "sig_during_import_mod.py"
    mod.write_text("import os, signal\nos.kill(os.getpid(), signal.SIGINT)\nDONE = True\n")
    monkeypatch.syspath_prepend(str(tmp_path))
    signals.clear()
    try:
        with signals.installed():
            assert importlib.import_module("sig_during_import_mod").DONE
            assert signals.pending() == signal.SIGINT
            with pytest.raises(KeyboardInterrupt):
                signals.check()
    finally:
        signals.clear()


def test_a_signal_inside_numba_s_compiler_is_remembered_not_raised():
    """numba's compiler calls back into Python through ctypes (llvmlite), which prints and drops an
    exception raised there: a signal arriving in such a frame stays pending instead."""
    text = "import os, signal\nos.kill(os.getpid(), signal.SIGINT)\n"
    code = compile(text, "/x/llvmlite/binding/fake.py", "exec")
    signals.clear()
    try:
        with signals.installed():
            exec(code, {})
            assert signals.pending() == signal.SIGINT
            with pytest.raises(KeyboardInterrupt):
                signals.check()
    finally:
        signals.clear()


@pytest.mark.parametrize("how", ["script", "-m"])
def test_the_first_of_dlovr_s_code_takes_the_signals_over(how):
    """``import dlovr`` in the ``dlovr`` script or ``python -m dlovr`` defers SIGINT and SIGTERM at
    once, before the command line's heavy imports (numpy, mujoco...); as a library it leaves them
    alone. A signal sent then is remembered (the command ends with it when it is ready)."""
    fake = ("import sys, types; m = types.ModuleType('__main__'); m.__file__ = '/usr/bin/dlovr'; "
            "sys.modules['__main__'] = m" if how == "script" else
            "import sys; sys.orig_argv = [sys.executable, '-m', 'dlovr', 'scenes']")
    code = (f"{fake}\nimport os, signal\nimport dlovr\nfrom dlovr import signals\n"
            "assert 'numpy' not in sys.modules and 'dlovr.cli' not in sys.modules\n"
            "os.kill(os.getpid(), signal.SIGTERM)\nprint(signals.pending())\n")
    env = {**os.environ, "PYTHONPATH": str(ROOT)}
    r = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, env=env, timeout=60)
    assert r.returncode == 0 and r.stdout.strip() == str(int(signal.SIGTERM)), r.stderr
    lib = "import signal, dlovr\nassert signal.getsignal(signal.SIGTERM) == signal.SIG_DFL\n"
    r = subprocess.run([sys.executable, "-c", lib], capture_output=True, text=True, env=env, timeout=60)
    assert r.returncode == 0, r.stderr


@pytest.mark.parametrize("sig", [signal.SIGINT, signal.SIGTERM], ids=["SIGINT", "SIGTERM"])
def test_dlovr_serve_ends_on_a_signal_that_came_while_the_kernels_compiled(monkeypatch, sig):
    """A signal inside numba's compiler is only noted (above): ``dlovr serve``, which compiles the
    kernels after printing its URL, then ends as it would have (it ran on, serving, and ignored it)."""
    import dlovr.sim.warmup as warmup
    import dlovr.ui as ui

    served = []
    monkeypatch.setattr(warmup, "warm_up", lambda notice=None: signals.note(sig))  # the signal came then
    monkeypatch.setattr(ui, "serve", lambda *a, **k: served.append(a))
    result = CliRunner().invoke(main, ["serve", "--port", "8791"])
    assert result.exit_code == signals.exit_code(sig) and not served, result.output
    if sig == signal.SIGTERM:  # and the serving loop ends on one (SIGINT: it returns, as on Ctrl-C)
        from dlovr.ui.server import serve

        signals.clear()
        signals.note(sig)
        with pytest.raises(signals.SignalExit):
            serve("table", port=8790)
