"""The UI's temporary folders and its end (temporary folders removed on every exit
path): opening a recording unpacks its embedded scene into a ``dlovr-ui-*`` folder, which goes when
the process ends, normally or on SIGTERM; ``dlovr serve`` ends on SIGTERM as on Ctrl-C, finishing a
recording in progress."""

from __future__ import annotations

import os
import signal
import socket
import subprocess
import sys
from pathlib import Path

import pytest

from dlovr.recording import Recording

ROOT = Path(__file__).resolve().parents[2]
SAMPLE = ROOT / "recordings" / "table.mcap"


def _env(tmp: Path) -> dict[str, str]:
    return {**os.environ, "TMPDIR": str(tmp), "PYTHONPATH": str(ROOT)}


@pytest.mark.slow
def test_an_opened_recordings_folder_is_removed_at_exit(tmp_path):
    code = (
        "import os, tempfile\n"
        "from dlovr.ui.timeline import recording_timeline\n"
        f"tl, scene, rec = recording_timeline({str(SAMPLE)!r})\n"
        "print(sorted(p[:9] for p in os.listdir(tempfile.gettempdir())))\n"
    )
    r = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, env=_env(tmp_path))
    assert r.returncode == 0, r.stderr[-2000:]
    assert r.stdout.strip() == "['dlovr-ui-']"  # there while the process ran
    assert list(tmp_path.iterdir()) == [], "the dlovr-ui-* folder was left behind"


@pytest.mark.slow
def test_serve_stops_on_sigterm_and_removes_its_folders(tmp_path):
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        port = s.getsockname()[1]
    code = (
        "import dlovr.ui.server as server\n"
        "from dlovr.ui.timeline import recording_timeline\n"
        "start = server.DemoServer.start\n"
        "def opened(self):\n"
        "    srv = start(self)\n"
        f"    recording_timeline({str(SAMPLE)!r})\n"
        "    srv.start_recording()\n"
        "    return srv\n"
        "server.DemoServer.start = opened\n"
        f"server.serve('table', port={port}, recordings_dir={str(tmp_path / 'recs')!r})\n"
    )
    tmp = tmp_path / "tmp"
    tmp.mkdir()
    proc = subprocess.Popen(
        [sys.executable, "-c", code], stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, env=_env(tmp)
    )
    try:
        lines = []  # viser's banner, then dlovr's line
        while not (lines and lines[-1].startswith("dlovr serve: scene table")):
            lines.append(proc.stdout.readline())
            assert lines[-1], "serve ended: " + "".join(lines)
        assert any(p.name.startswith("dlovr-ui-") for p in tmp.iterdir())
        proc.send_signal(signal.SIGTERM)
        out, err = proc.communicate(timeout=60)
    finally:
        proc.kill()
    assert proc.returncode == 143, err[-2000:]
    assert "dlovr serve: stopped" in out and "Traceback" not in err, out + err
    assert not [p for p in tmp.iterdir() if p.name.startswith("dlovr-")], list(tmp.iterdir())
    (rec,) = (tmp_path / "recs").glob("*.mcap")  # the recording in progress was finished
    assert f"dlovr serve: finished recording {rec}" in out
    assert Recording(rec).checkpoints()[-1].step > 0
