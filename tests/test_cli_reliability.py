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


ROOT = Path(__file__).resolve().parent.parent
TABLE = ROOT / "scenes" / "table.toml"
L_BLOCK = ROOT / "scenes" / "l_block.toml"


def test_a_mesh_symlink_loop_is_one_line(tmp_path):
    text = L_BLOCK.read_text()
    mesh = next(line.split('"')[1] for line in text.splitlines() if line.strip().startswith("mesh"))
    (tmp_path / "meshes").mkdir()
    (tmp_path / "meshes" / "a.obj").symlink_to("b.obj")
    (tmp_path / "meshes" / "b.obj").symlink_to("a.obj")
    scene = tmp_path / "loop.toml"
    scene.write_text(text.replace(mesh, "meshes/a.obj"))
    one_line_exit_2(cli("scene", "show", scene), f"Error: {scene}: ", "cannot be resolved")


def with_dlo(key: str, value: str) -> str:
    """The table scene with ``[dlo] key = value``."""
    lines = TABLE.read_text().splitlines()
    return "\n".join(f"{key} = {value}" if line.strip().startswith(f"{key} ") else line for line in lines)


def test_an_overflowing_young_modulus_is_refused_and_leaves_no_file(tmp_path):
    scene = tmp_path / "young.toml"
    scene.write_text(with_dlo("young", "1e308"))
    assert "young = 1e308" in scene.read_text()
    script = tmp_path / "y.script.toml"
    script.write_text(f'scene = "{scene}"\n[[waypoints]]\npos = [0.0, 0.0, 0.6]\nduration = 0.1\n')
    r = cli("record", "--script", script, "-o", tmp_path / "y.mcap")
    one_line_exit_2(r, "dlo.young: ", "must be at most 1e+12 Pa")
    assert not (tmp_path / "y.mcap").exists()


def test_a_huge_number_is_shown_short(tmp_path):
    scene = tmp_path / "seg.toml"
    scene.write_text(with_dlo("segments", "1" + "0" * 180))
    assert "0" * 180 in scene.read_text()
    r = cli("scene", "show", scene)
    one_line_exit_2(r, "dlo.segments: ", "an integer of about 181 digits")
    assert len(r.output.strip().splitlines()[-1]) < 200


@pytest.mark.parametrize(("opt", "value"), [("--hold", "nan"), ("--flight", "inf"), ("--hold", "-1")])
def test_timed_options_must_be_finite(tmp_path, opt, value):
    f = tmp_path / "t.txt"
    f.write_text("0.0 V/G & E/N & V/N\n0.5 V/G & E/N & V/F\n")
    r = cli("transitions", f, opt, value)
    assert r.exit_code == 2 and f"Invalid value for '{opt}'" in r.output and "finite" in r.output, r.output


def test_a_program_whose_demonstration_is_missing_says_how_it_runs(tmp_path, monkeypatch):
    import dlovr.cli.run as run_cli

    (tmp_path / "a").mkdir()
    prog = tmp_path / "a" / "table.program.json"
    prog.write_bytes((ROOT / "recordings" / "programs" / "table.program.json").read_bytes())
    monkeypatch.chdir(tmp_path)  # the working directory is searched too
    monkeypatch.setattr(run_cli, "_single", lambda *a, **k: None)  # only what is said before it runs
    r = CliRunner().invoke(main, ["run", str(prog)])
    assert r.exit_code == 0, r.output
    said = "its demonstration 'table.mcap' was not found, so the macros move along the program's poses"
    assert said in r.output
