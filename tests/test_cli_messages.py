"""What the CLI says: scenes named by --scene and by scripts, a diverged run,
times and counts in tables, CSV and JSON, --help summaries, and replay of an embedded scene beyond
the documented limits (refused; its temporary folder removed on every exit path)."""

from __future__ import annotations

import csv
import io
import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest
from click.testing import CliRunner
from mcap_edit import rewrite_mcap

from dlovr.cli import main
from dlovr.recording import Recording, SceneBundle

ROOT = Path(__file__).resolve().parent.parent
SAMPLES = ROOT / "recordings"
TOUCH = Path(__file__).parent / "data" / "touch_table.script.toml"
SHORT = 'scene = "{scene}"\n[[waypoints]]\npos = [0.0, 0.0, 0.68]\nduration = 0.2\n'


def cli(*args):
    return CliRunner().invoke(main, [str(a) for a in args])


def decimals(x: float) -> int:
    s = repr(float(x))
    return len(s.split(".")[1]) if "." in s and "e" not in s else 0


@pytest.fixture(scope="module")
def touch(tmp_path_factory):
    """``demo --json -o`` of the touch-table script: its rows and its recording."""
    out = tmp_path_factory.mktemp("touch") / "touch.mcap"
    r = cli("demo", "--script", TOUCH, "--json", "-o", out)
    assert r.exit_code == 0, r.output
    return json.loads(r.stdout), out


# --------------------------------------------------------------------------------------------------
# Scenes named by --scene and by scripts
# --------------------------------------------------------------------------------------------------


def test_demo_with_an_unknown_scene_says_no_such_scene():
    r = cli("demo", "--scene", "nosuchscene")
    assert r.exit_code == 2
    assert "nosuchscene: no built-in scene of that name (known: " in r.output and "peg_in_hole" in r.output
    assert "demonstration script" not in r.output


def test_a_script_naming_an_unknown_scene_names_the_script(tmp_path):
    script = tmp_path / "x.script.toml"
    script.write_text(SHORT.format(scene="nosuchscene"))
    r = cli("record", "--script", script, "-o", tmp_path / "x.mcap")
    assert r.exit_code == 2 and r.output.startswith(f"Error: {script}: scene: nosuchscene: no built-in scene")
    assert not (tmp_path / "x.mcap").exists()


def test_a_scene_path_in_a_script_resolves_against_the_script_folder(tmp_path):
    (tmp_path / "scenes").mkdir()
    (tmp_path / "scenes" / "mine.toml").write_text((ROOT / "scenes" / "table.toml").read_text())
    (tmp_path / "demos").mkdir()
    script = tmp_path / "demos" / "x.script.toml"
    script.write_text(SHORT.format(scene="../scenes/mine.toml"))
    assert not Path("../scenes/mine.toml").exists()  # the tests run elsewhere
    r = cli("demo", "--script", script, "--json")
    assert r.exit_code == 0, r.output
    assert json.loads(r.stdout)[0]["discrete"] == "V/G & E/N & V/N"


# --------------------------------------------------------------------------------------------------
# A diverged run
# --------------------------------------------------------------------------------------------------


def test_a_diverged_run_says_so_once_and_its_recording_compiles_with_a_warning(tmp_path, monkeypatch):
    from dlovr.sim import SimulationDiverged, simulator

    record = simulator.Simulator._record  # what Simulator.step and Simulator.record call

    def diverge_at_step_300(self, check):
        if check and self.step_index == 300:  # the step's divergence checks fail
            raise SimulationDiverged(self.step_index, self.data.time, "NaN/inf in the state")
        return record(self, check)

    monkeypatch.setattr(simulator.Simulator, "_record", diverge_at_step_300)
    out = tmp_path / "run.mcap"
    r = cli("record", "--script", TOUCH, "-o", out)
    assert r.exit_code == 1
    assert r.output.count("simulation diverged") == 1 and "simulation diverged at step 300" in r.output
    assert f"kept: {out}" in r.output
    end = Recording(out).states()[-1]
    assert end["end"] and "simulation diverged at step 300" in end["end_reason"]
    monkeypatch.undo()
    r = CliRunner().invoke(main, ["compile", str(out), "-o", str(tmp_path / "programs")])
    assert r.exit_code == 0, r.output
    assert "warning:" in r.stderr and "ends early (simulation diverged at step 300" in r.stderr
    assert "program is partial" in r.stderr


# --------------------------------------------------------------------------------------------------
# Times, counts, help
# --------------------------------------------------------------------------------------------------


def test_times_in_json_and_csv_are_rounded(touch):
    rows, rec = touch
    assert all(decimals(r["t"]) <= 6 and decimals(r["duration"]) <= 6 for r in rows), rows
    for args in (["--format", "json"], ["--format", "json", "--raw"]):
        r = cli("states", rec, *args)
        assert r.exit_code == 0, r.output
        data = json.loads(r.output)
        assert len(data) >= 2 and all(decimals(d["t"]) <= 6 for d in data), data
        assert all(decimals(d.get("duration", 0)) <= 6 for d in data)
    r = cli("states", rec, "--format", "csv", "--raw")
    ts = [row["t"] for row in csv.DictReader(io.StringIO(r.output))]
    assert len(ts) >= 2 and all(len(t.partition(".")[2]) <= 6 for t in ts), ts
    assert "np.float64" not in r.output
    # the recording itself keeps the exact times (replay compares them bit for bit)
    assert any(decimals(p["t"]) > 6 for p in Recording(rec).states())


def test_one_macro_is_singular(tmp_path):
    from dlovr.cli.common import plural as _plural

    assert [_plural(n, "macro") for n in (1, 2, 0)] == ["1 macro", "2 macros", "0 macros"]
    r = cli("compile", SAMPLES / "l_block.mcap", "-o", tmp_path)
    n = json.loads((tmp_path / "l_block.program.json").read_text())["summary"]["macros"]
    assert r.exit_code == 0 and f": {_plural(n, 'macro')}, " in r.output, r.output


def test_help_summaries_are_whole_sentences():
    for args in (["--help"], ["scene", "--help"]):
        r = cli(*args)
        commands = r.output.split("Commands:")[1].strip().splitlines()
        assert len(commands) >= 2
        for line in commands:
            assert not line.rstrip().endswith("..."), line
            assert line.rstrip().endswith("."), line


# --------------------------------------------------------------------------------------------------
# Replay of an embedded scene beyond the limits, and its temporary folder
# --------------------------------------------------------------------------------------------------


def _edit_scene(src: Path, dst: Path, edit) -> None:
    bundle = Recording(src).scene
    toml = edit(bundle.toml)
    digest = SceneBundle(toml, bundle.files).digest
    rewrite_mcap(
        src,
        dst,
        attachment=lambda name, data: toml if name == "scene/scene.toml" else data,
        metadata=lambda name, d: {**d, "scene_sha256": digest} if name == "dlovr" else d,
    )


@pytest.mark.slow
def test_replay_refuses_an_embedded_scene_edited_beyond_the_limits(tmp_path):
    bad = tmp_path / "huge.mcap"
    _edit_scene(SAMPLES / "table.mcap", bad, lambda t: t.replace(b"segments = 40", b"segments = 100000"))
    t0 = time.monotonic()
    r = subprocess.run(
        [sys.executable, "-m", "dlovr", "replay", str(bad)], capture_output=True, text=True, timeout=120
    )
    assert time.monotonic() - t0 < 60
    assert r.returncode == 2 and "Traceback" not in r.stderr
    last = r.stderr.strip().splitlines()[-1]
    assert last.startswith(f"Error: {bad}: embedded scene is invalid: ") and "dlo.segments" in last
    assert "at most" in last or "from 2 to 200" in last


@pytest.mark.slow
@pytest.mark.parametrize("sig", [signal.SIGTERM, signal.SIGINT], ids=["SIGTERM", "SIGINT"])
def test_replay_removes_its_temporary_folder_when_interrupted(tmp_path, sig):
    """The replay is stopped while its embedded scene is unpacked (the simulator build is made to
    wait): the dlovr-replay-* folder goes with it."""
    tmp = tmp_path / "tmp"
    tmp.mkdir()
    code = (
        "import sys, time\n"
        "import dlovr.sim\n"
        "def slow(self, *a, **k):\n"
        "    print('building', flush=True)\n"
        "    time.sleep(60)\n"
        "dlovr.sim.Simulator.__init__ = slow\n"
        "from dlovr.cli import main\n"
        f"main(['replay', {str(SAMPLES / 'table.mcap')!r}])\n"
    )
    env = {**os.environ, "TMPDIR": str(tmp), "PYTHONPATH": str(ROOT)}
    proc = subprocess.Popen(
        [sys.executable, "-c", code], stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, env=env
    )
    try:
        assert proc.stdout.readline().strip() == "building"
        assert [p.name[:13] for p in tmp.iterdir()] == ["dlovr-replay-"]
        proc.send_signal(sig)
        _, err = proc.communicate(timeout=30)
    finally:
        proc.kill()
    assert list(tmp.iterdir()) == [], "the temporary folder was left behind"
    assert "Traceback" not in err
    assert proc.returncode == (143 if sig == signal.SIGTERM else 130)


def test_a_replay_divergence_names_plain_numbers(touch, tmp_path):
    """The message shows the differing values as numbers (shortest round-trip), not numpy reprs."""

    def nudge(topic, data):
        d = json.loads(data)
        if topic == "/dlovr/command" and d["step"] <= 300 < d["step"] + len(d["pos"]):
            d["pos"][300 - d["step"]][0] += 1e-4
            return json.dumps(d).encode()
        return data

    bad = tmp_path / "nudged.mcap"
    rewrite_mcap(touch[1], bad, message=nudge)
    r = cli("replay", bad, "--verify")
    # the first difference the replay meets: the wrench sampled every 10 ms, before the checkpoint at 500
    assert r.exit_code == 1 and "replay diverged: wrench sample" in r.output, r.output
    assert "np.float64" not in r.output and "recorded " in r.output
    recorded = r.output.split("recorded ")[1].split(",")[0]
    float(recorded)  # a plain number


def test_one_user_error_class_turned_from_input_errors_in_one_place():
    """``UserError`` is the CLI's only click exception class; every ``InputError`` a command (or an
    option's callback) raises becomes it in ``Group.invoke`` (one line, exit 2), not in per-command
    ``try``/``except`` copies."""
    import ast

    import click

    from dlovr.cli.common import EXIT_BAD_INPUT, EXIT_CODES, Group
    from dlovr.inputs import InputError

    pkg = ROOT / "dlovr"
    click_errors = [
        f"{path.relative_to(pkg)}:{node.name}"
        for path in sorted(pkg.rglob("*.py"))
        for node in ast.walk(ast.parse(path.read_text()))
        if isinstance(node, ast.ClassDef) and any("ClickException" in ast.unparse(b) for b in node.bases)
    ]
    assert click_errors == ["cli/common.py:UserError"]
    readers = ("SceneError", "ScriptError", "FactsError", "NetworkError", "RecordingError", "VaryError")
    for path in sorted((pkg / "cli").glob("*.py")):
        if path.name == "common.py":  # a scene a script names is worded with the script's file there
            continue
        caught = [n for n in readers if f"except {n}" in path.read_text()]
        assert not caught, f"{path.name} catches {caught} itself"

    @click.group(cls=Group)
    def group() -> None:
        pass

    @group.command()
    @click.option("--x", callback=lambda *_: (_ for _ in ()).throw(InputError("f.toml: x: bad")))
    def cmd(x: str) -> None:
        pass

    r = CliRunner().invoke(group, ["cmd", "--x", "1"])
    assert r.exit_code == EXIT_BAD_INPUT and r.output == "Error: f.toml: x: bad\n"
    assert {0, 1, 2, 130, 143} <= set(EXIT_CODES)
