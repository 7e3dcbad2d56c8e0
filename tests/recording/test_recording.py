"""Recording a scripted demonstration, exact replay, states, recovery and compiling (CLI and API)."""

from __future__ import annotations

import json
import os
import shutil
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from click.testing import CliRunner
from mcap_edit import rewrite_mcap

from dlovr.cli import main
from dlovr.recording import (
    Recording,
    RecordingError,
    compile_recording,
    replay,
)

SCRIPT = Path(__file__).parents[1] / "data" / "touch_table.script.toml"


def cli(*args):
    return CliRunner().invoke(main, [str(a) for a in args])


@pytest.fixture(scope="module")
def recorded(tmp_path_factory):
    out = tmp_path_factory.mktemp("rec") / "touch.mcap"
    r = cli("record", "--script", SCRIPT, "-o", out)
    assert r.exit_code == 0, r.output
    return out


@pytest.mark.slow
def test_record_then_replay_verify_is_bit_exact(recorded):
    res = replay(recorded, verify=True)
    assert res.divergence is None and res.warnings == ()
    assert res.steps == len(Recording(recorded).commands()[0])
    r = cli("replay", recorded, "--verify")
    assert r.exit_code == 0 and "verified" in r.output


def test_replay_tracks_behind_with_the_same_states_as_inline(recorded):
    """Without on_step the tracker works beside the simulation (dlovr.sim.behind.tracking_behind); an
    on_step may read the states, so with one it tracks inline: the same states either way."""
    seen = []
    inline = replay(recorded, verify=True, on_step=lambda sim, r: seen.append(r.state))
    behind = replay(recorded, verify=True)
    assert behind.divergence is None and inline.divergence is None
    assert behind.states == inline.states and len(behind.states) >= 2
    assert all(s is not None for s in seen[1:])  # every step past the first checkpoint tracked


def test_recording_holds_everything_needed(recorded):
    rec = Recording(recorded)
    assert rec.metadata["scene_name"] == "table" and rec.metadata["mujoco_version"].startswith("4.0")
    assert b"[dlo]" in rec.scene.toml
    cps = rec.checkpoints()
    assert cps[0].step == 0 and len(cps) >= 3  # start + every second + end
    states = rec.states()
    assert states[0]["discrete"] == "V/G & E/N & V/N"
    assert any("V/F[table.F1]" in s["discrete"] for s in states)
    for s in states:
        assert {"t", "step", "topological", "discrete", "classes", "contacts"} <= set(s)


def test_replay_detects_a_changed_command_stream(recorded, tmp_path):
    """A recording whose checkpoints do not match its commands is reported with time and element."""

    def nudge(topic, data):
        d = json.loads(data)
        if topic == "/dlovr/command" and d["step"] <= 300 < d["step"] + len(d["pos"]):
            d["pos"][300 - d["step"]][0] += 1e-4  # a nudge of 0.1 mm at step 300
            return json.dumps(d).encode()
        return data

    bad = tmp_path / "bad.mcap"
    rewrite_mcap(recorded, bad, message=nudge)
    res = replay(bad, verify=True)
    # the wrench sampled every 5 steps shows it first (the checkpoint at step 500 would too)
    assert res.divergence and "wrench sample 60 (t=0.600 s) differs in" in res.divergence
    r = cli("replay", bad, "--verify")
    assert r.exit_code == 1 and "diverged" in r.output


def test_states_formats_read_only_the_states_channel(recorded):
    t = cli("states", recorded)
    assert t.exit_code == 0 and "V/F[table.F1]" in t.output and "VS/G" in t.output
    j = cli("states", recorded, "--format", "json")
    rows = json.loads(j.output)
    assert rows[0]["classes"] == [] and rows[1]["classes"] == ["E"]
    assert {"t", "topological", "discrete", "classes"} <= set(rows[0])
    c = cli("states", recorded, "--format", "csv")
    assert c.output.splitlines()[0] == "t,classes,topological,discrete"
    raw = json.loads(cli("states", recorded, "--format", "json", "--raw").output)
    assert len(raw) >= len(rows)


def test_program_of_a_recording(recorded):
    prog = compile_recording(recorded)
    assert prog.macros and prog.macros[0].label == "E"
    assert prog.macros[0].to_situation == "V/G & E/N & V/F[table.F1]"
    assert prog.macros[0].to_contacts[0].vector == pytest.approx((0.0, 0.0, -1.0))


def test_detection_parameters_come_from_the_recorded_wrench(recorded, tmp_path):
    """The recording carries the gripper's wrench every few steps; the compiler derives each macro's
    thresholds from it, and without the channel (older recordings) falls back to marked defaults."""
    rec = Recording(recorded)
    w = rec.wrench()
    assert w is not None and len(w.t) > 100
    assert np.allclose(np.diff(w.t), 5 * rec.dt)
    first = compile_recording(recorded).macros[0].detection[0]
    assert first.derivation["force_threshold_n"].startswith("derived: ")
    assert "step along -v" in first.derivation["force_threshold_n"]
    assert 0 < first.params["force_threshold_n"] != 0.5
    old = tmp_path / "no_wrench.mcap"
    rewrite_mcap(recorded, old, keep=lambda topic: topic != "/dlovr/wrench")
    assert Recording(old).wrench() is None
    prog = compile_recording(old)
    for m in prog.macros:
        for d in m.detection:
            assert all(v == "default: no wrench signal in the recording" for v in d.derivation.values())
    assert prog.macros[0].detection[0].params["force_threshold_n"] == 0.5


def test_compile_one_and_two_workers_identical_and_failures_reported(recorded, tmp_path):
    src = tmp_path / "in"
    src.mkdir()
    shutil.copy(recorded, src / "a.mcap")
    shutil.copy(recorded, src / "b.mcap")
    (src / "broken.mcap").write_bytes(b"not an mcap file")
    r1 = cli("compile", src, "-o", tmp_path / "o1", "--workers", "1")
    r2 = cli("compile", src, "-o", tmp_path / "o2", "--workers", "2")
    for r in (r1, r2):
        assert r.exit_code == 2 and "2 compiled, 1 failed" in r.output and "broken.mcap" in r.output
    for name in ("a.program.json", "a.program.txt", "b.program.json"):
        assert (tmp_path / "o1" / name).read_bytes() == (tmp_path / "o2" / name).read_bytes()
    (src / "broken.mcap").unlink()
    again = cli("compile", src, "-o", tmp_path / "o1")
    assert again.exit_code == 0 and again.output.count("unchanged, skipped") == 2
    assert "0 compiled, 2 skipped (unchanged), 0 failed" in again.output


@pytest.mark.parametrize(
    ("content", "message"),
    [(b"", "empty file"), (b"PK\x03\x04 zip", "not an MCAP file")],
)
@pytest.mark.slow
def test_cli_errors_are_one_line_exit_2(tmp_path, content, message):
    f = tmp_path / "x.mcap"
    f.write_bytes(content)
    for cmd in ("states", "replay", "compile"):
        r = subprocess.run([sys.executable, "-m", "dlovr", cmd, str(f)], capture_output=True, text=True)
        assert r.returncode in (1, 2) and message in r.stderr + r.stdout and "Traceback" not in r.stderr
    r = subprocess.run([sys.executable, "-m", "dlovr", "states", str(f)], capture_output=True, text=True)
    assert r.returncode == 2 and len(r.stderr.strip().splitlines()) == 1


def test_truncated_recording_points_to_recover(recorded, tmp_path):
    f = tmp_path / "cut.mcap"
    f.write_bytes(recorded.read_bytes()[: os.path.getsize(recorded) // 2])
    r = cli("states", f)
    assert r.exit_code == 2 and "dlovr recover" in r.output
    with pytest.raises(RecordingError, match="truncated"):
        Recording(f)


def test_scene_export_loads_in_plain_mujoco(tmp_path):
    import mujoco

    out = tmp_path / "model.xml"
    r = cli("scene", "export", "peg_in_hole", "-o", out)
    assert r.exit_code == 0, r.output
    m = mujoco.MjModel.from_xml_path(str(out))
    assert m.nflex == 1 and m.nmocap == 1
    bad = cli("scene", "export", "no_such_scene", "-o", out)
    assert bad.exit_code == 2


@pytest.mark.slow
def test_version_mismatch_is_a_clear_warning(recorded, tmp_path):
    other = tmp_path / "old.mcap"
    rewrite_mcap(recorded, other, metadata=lambda name, d: {**d, "mujoco_version": "3.3.0"})
    res = replay(other)
    assert res.warnings and "mujoco 3.3.0" in res.warnings[0]
    r = subprocess.run([sys.executable, "-m", "dlovr", "replay", str(other)], capture_output=True, text=True)
    assert r.returncode == 0 and "warning: recorded with mujoco 3.3.0" in r.stderr


@pytest.mark.slow
def test_demo_prints_the_fig11_style_table_and_bad_scripts_exit_2(tmp_path):
    r = cli("demo", "--script", SCRIPT, "--json")
    rows = json.loads(r.stdout)
    assert (
        r.exit_code == 0
        and rows[1]["discrete"] == "V/G & E/N & V/F[table.F1]"
        and rows[1]["classes"] == ["E"]
    )
    assert rows[1]["topological"].startswith("VS/G")
    bad = tmp_path / "bad.script.toml"
    bad.write_text('scene = "table"\n[[waypoints]]\npos = [0, 0]\nduration = 1\n')
    r = subprocess.run(
        [sys.executable, "-m", "dlovr", "demo", "--script", str(bad)], capture_output=True, text=True
    )
    assert r.returncode == 2 and str(bad) in r.stderr and "Traceback" not in r.stderr
    r = cli("record", "--scene", "nonexistent_scene", "--script", SCRIPT, "-o", tmp_path / "x.mcap")
    assert r.exit_code == 2 and not (tmp_path / "x.mcap").exists()


def test_replay_uses_the_embedded_decomposition(recorded, tmp_path, monkeypatch):
    """A recording keeps the convex pieces it was simulated with: its replay does not depend on
    today's decomposition algorithm or on a (possibly stale) decomposition cache."""
    from dlovr import geometry
    from dlovr.geometry import objects as geometry_objects
    from dlovr.scene import load_scene

    pieces = Recording(recorded).pieces
    assert pieces is not None
    today = geometry.scene_pieces(load_scene("table"))
    assert set(pieces) == {"table"} and np.array_equal(pieces["table"][0][0], today["table"][0][0])

    def no_decomposition(*a, **kw):
        raise AssertionError("replay decomposed a mesh instead of using the recording's pieces")

    monkeypatch.setattr(geometry_objects, "decompose", no_decomposition)
    assert replay(recorded, verify=True).divergence is None
    bad = tmp_path / "tampered.mcap"
    rewrite_mcap(
        recorded, bad, attachment=lambda n, d: d.replace(b"0.5", b"0.6") if n == "model/pieces.json" else d
    )
    with pytest.raises(RecordingError, match="decomposition was modified"):
        Recording(bad)
