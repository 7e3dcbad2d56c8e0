"""Sets of perturbed demonstrations (``dlovr record --trials N --vary ... -o DIR``): one file per trial
that replays bit for bit, deterministic from the seed, merged by ``dlovr network DIR``. Short
simulations only: the 0.9 s table demonstration of the execution tests."""

from __future__ import annotations

import json
from pathlib import Path

import pytest
from click.testing import CliRunner

from dlovr.cli import main

ROOT = Path(__file__).resolve().parents[2]
SCRIPT = ROOT / "tests" / "data" / "touch_press.script.toml"
VARY = ["--vary", "dlo.young=0.5..2", "--vary", "objects.pos=0.002", "--vary", "dlo.friction=30%"]


def cli(*args):
    return CliRunner().invoke(main, [str(a) for a in args])


@pytest.fixture(scope="module")
def demos(tmp_path_factory):
    d = tmp_path_factory.mktemp("demos") / "set"
    r = cli("record", "--script", SCRIPT, "--trials", 3, "--seed", 11, *VARY, "-o", d)
    assert r.exit_code == 0, r.output
    assert "wrote 3 recordings of table" in r.output
    return d


@pytest.mark.slow
def test_each_trial_is_a_recording_of_its_perturbed_scene(demos):
    from dlovr.recording import Recording, replay
    from dlovr.recording.bundle import SceneBundle
    from dlovr.scene import load_scene

    names = sorted(p.name for p in demos.glob("*.mcap"))
    assert names == ["demo_000.mcap", "demo_001.mcap", "demo_002.mcap"]
    index = json.loads((demos / "demos.json").read_text())
    assert index["seed"] == 11 and len(index["demonstrations"]) == 3
    base = SceneBundle.from_path(load_scene("table").path).digest
    hashes = set()
    for k, name in enumerate(names):
        meta = Recording(demos / name).metadata
        assert meta["base_scene_sha256"] == base and meta["trial"] == str(k)
        assert json.loads(meta["vary"]) == index["demonstrations"][k]["values"]
        hashes.add(meta["scene_sha256"])
    assert len(hashes) == 3 and base not in hashes  # each its own perturbed scene
    assert not replay(demos / names[1], verify=True).divergence


@pytest.mark.slow
def test_the_same_seed_records_the_same_demonstrations(demos, tmp_path):
    from dlovr.recording import Recording

    r = cli("record", "--script", SCRIPT, "--trials", 2, "--seed", 11, *VARY, "-o", tmp_path)
    assert r.exit_code == 0, r.output
    for name in ("demo_000.mcap", "demo_001.mcap"):
        assert Recording(tmp_path / name).states() == Recording(demos / name).states()
    r = cli("record", "--script", SCRIPT, "--trials", 2, "--seed", 11, *VARY, "-o", tmp_path)
    assert r.exit_code == 2 and "--force" in r.output


@pytest.mark.slow
def test_network_merges_the_perturbed_demonstrations(demos, tmp_path):
    r = cli("network", demos, "-o", tmp_path / "net.json")
    assert r.exit_code == 0, r.output
    assert "from 3 recordings of table" in r.output
    assert len(json.loads((tmp_path / "net.json").read_text())["demonstrations"]) == 3


@pytest.mark.parametrize(
    ("args", "message"),
    [
        (["--vary", "dlo.length=10%", "-o", "x.mcap"], "need --trials"),
        (["--trials", "2", "--vary", "dlo.colour=3%", "-o", "OUT"], "unknown key"),
        (["--trials", "2", "--vary", "objects.pos=5%", "-o", "OUT"], "absolute offset"),
        (["--trials", "0", "-o", "OUT"], "--trials"),
        (["--trials", "2", "--cluster", "nowhere", "-o", "OUT"], "--cluster nowhere"),
    ],
)
def test_bad_inputs_are_one_line_exit_2(args, message, tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    r = cli("record", "--script", SCRIPT, *args)
    assert r.exit_code == 2, r.output
    assert message in r.output and "Traceback" not in r.output
