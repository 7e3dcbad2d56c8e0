"""Hostile inputs of the command line (issue 31): a device given as a recording or a script is refused
at once (it was read without bound: `recover /dev/zero` took 4.8 GB in 4 s), an address `serve` cannot
listen on is one line (it hung silently), and a recording still being written is named so."""

from __future__ import annotations

import time
from pathlib import Path

import pytest
from click.testing import CliRunner

from dlovr.cli import main
from dlovr.recording import Recorder, Recording, RecordingError, SceneBundle, recover

DEVICE = Path("/dev/zero")


def cli(*args):
    return CliRunner().invoke(main, [str(a) for a in args])


def one_line_exit_2(r, start: str, why: str) -> None:
    assert r.exit_code == 2, r.output
    last = r.output.strip().splitlines()[-1]
    assert start in last and why in last, r.output
    assert "Traceback" not in r.output


@pytest.mark.skipif(not DEVICE.exists(), reason="needs /dev/zero")
@pytest.mark.parametrize(
    "args",
    [("recover", DEVICE, "-o", "{tmp}/z.mcap"), ("states", DEVICE), ("replay", DEVICE), ("compile", DEVICE),
     ("record", "--script", DEVICE, "-o", "{tmp}/r.mcap"), ("scene", "show", DEVICE)],
    ids=["recover", "states", "replay", "compile", "record-script", "scene"],
)
def test_a_device_is_refused_at_once(tmp_path, args):
    t0 = time.monotonic()
    r = cli(*[str(a).format(tmp=tmp_path) for a in args])
    assert time.monotonic() - t0 < 30
    assert r.exit_code == 2, r.output
    assert "/dev/zero: not a regular file (a device or a pipe)" in r.output, r.output
    assert "Traceback" not in r.output and list(tmp_path.iterdir()) == []


@pytest.mark.parametrize(
    ("host", "why"),
    [("192.0.2.1", "cannot serve on 192.0.2.1:"), ("999.1.1.1", "not an address of this machine")],
)
def test_serve_on_an_address_that_is_not_this_machines_is_one_line(host, why):
    t0 = time.monotonic()
    r = cli("serve", "--host", host, "--port", "18080")
    assert time.monotonic() - t0 < 10
    one_line_exit_2(r, f"Error: --host {host}: ", why)


def test_a_recording_still_being_written_is_named_so(tmp_path):
    from dlovr.scene import load_scene

    out = tmp_path / "live.mcap"
    bundle = SceneBundle.from_path(load_scene("table").path)
    rec = Recorder(out, bundle, scene_name="table", dt=0.002, t0_ns=0)
    try:
        for what in (lambda: Recording(out), lambda: recover(out, tmp_path / "fixed.mcap")):
            with pytest.raises(RecordingError, match=r"live\.mcap: still being written"):
                what()
    finally:
        rec.close()
    assert not (tmp_path / "fixed.mcap").exists()
