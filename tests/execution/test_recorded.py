"""A program run recorded as MCAP (``dlovr run -o run.mcap``, ``--trials --record``): it replays and
verifies bit for bit like a demonstration (also in a perturbed scene that exists only in memory), and
its events channel holds the macro starts, the detections and the result. Short simulations only."""

from __future__ import annotations

import json
from pathlib import Path

import pytest
from click.testing import CliRunner
from mcap.reader import make_reader

from dlovr.cli import main
from dlovr.execution.executor import ExecOptions
from dlovr.execution.recorded import TOPIC_EVENTS, record_run, scene_bundle
from dlovr.execution.run import run_program
from dlovr.execution.variation import parse_vary, perturb


def events(path: Path) -> list[dict]:
    with open(path, "rb") as fh:
        return [json.loads(m.data) for _, _, m in make_reader(fh).iter_messages(topics=[TOPIC_EVENTS])]


@pytest.mark.slow
def test_a_recorded_run_verifies_and_carries_its_events(touch, tmp_path):
    from dlovr.recording import Recording, replay

    program, scene, track, pieces = touch
    out = tmp_path / "run.mcap"
    res = record_run(program, scene, out, ExecOptions(), track=track, pieces=pieces)
    plain = run_program(program, scene, ExecOptions(), track=track, pieces=pieces)
    assert res.success, res.reason
    assert res.to_json() | {"wall_time": 0} == plain.to_json() | {"wall_time": 0}  # recording changes nothing
    rec = Recording(out)
    assert rec.metadata["source"] == "dlovr run" and rec.metadata["program"] == program.name
    r = replay(out, verify=True)
    assert not r.divergence, r.divergence
    ev = events(out)
    kinds = [e["kind"] for e in ev]
    assert kinds[0] == "start" and "macro" in kinds and "detected" in kinds and kinds[-1] == "result"
    assert kinds.index("macro") < kinds.index("detected")
    assert ev[-1]["result"]["success"] is True
    assert [e["step"] for e in ev] == sorted(e["step"] for e in ev)


def test_a_perturbed_scene_is_embedded_and_replays(touch, tmp_path):
    from dlovr.recording import replay
    from dlovr.scene import load_scene

    program, scene, track, pieces = touch
    vs = (parse_vary("dlo.length=10%"), parse_vary("objects.pos=0.003"), parse_vary("dlo.young=0.5..2"))
    moved, _ = perturb(scene, vs, 7, 1)
    bundle = scene_bundle(moved)
    (tmp_path / "scene").mkdir()
    back = load_scene(bundle.materialize(tmp_path / "scene"))
    assert back.dlo == moved.dlo and back.gripper == moved.gripper
    assert [(o.name, o.pos, o.size) for o in back.objects] == [(o.name, o.pos, o.size) for o in moved.objects]
    out = tmp_path / "moved.mcap"
    record_run(program, moved, out, ExecOptions(), track=track, pieces=pieces)
    assert not replay(out, verify=True).divergence


def test_mesh_scenes_embed_their_meshes():
    from dlovr.scene import load_scene

    scene = load_scene("peg_in_hole")
    b = scene_bundle(scene)
    assert [n for n, _ in b.files] == ["meshes/hole_block.obj"]
    assert b"mesh = \"meshes/hole_block.obj\"" in b.toml


@pytest.mark.slow
def test_cli_records_a_run_and_trials(touch, tmp_path):
    program, *_ = touch
    out = tmp_path / "run.mcap"
    r = CliRunner().invoke(main, ["run", str(program.path), "--scene", "table", "-o", str(out)])
    assert r.exit_code == 0, r.output
    assert out.is_file() and events(out)[-1]["kind"] == "result"
    r = CliRunner().invoke(main, ["run", str(program.path), "--scene", "table", "-o", str(tmp_path / "x")])
    assert r.exit_code == 2 and ".mcap" in r.output
    d = tmp_path / "trials"
    args = ["run", str(program.path), "--scene", "table", "--trials", "2", "--vary", "dlo.length=5%"]
    r = CliRunner().invoke(main, [*args, "--record", "-o", str(d)])
    assert r.exit_code == 0, r.output
    assert sorted(p.name for p in d.glob("*.mcap")) == ["trial_000.mcap", "trial_001.mcap"]
    # recorded trials carry the unperturbed scene's hash: they merge into one network
    r = CliRunner().invoke(main, ["network", str(d), "-o", str(tmp_path / "net.json")])
    assert r.exit_code == 0 and "from 2 recordings of table" in r.output, r.output
