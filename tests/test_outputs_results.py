"""Result files of batches and compiled programs are written atomically and never replace a file
without --force: ``run --trials`` results (trial_KKK.json, trials.csv, summary.json, plot.png),
``record --trials``'s demos.json, recordings made by runs and trials, and ``compile``'s programs
(replaced without --force only when compile wrote them there; ``--sensor-noise`` does not imply
--force)."""

from __future__ import annotations

from pathlib import Path
from types import SimpleNamespace

import pytest
from click.testing import CliRunner

from dlovr.cli import main
from dlovr.cli.common import shown_dir
from dlovr.execution.demo_sets import write_index
from dlovr.execution.trials import write_outputs
from dlovr.outputs import OutputError
from dlovr.recording import Recorder, SceneBundle

ROOT = Path(__file__).resolve().parent.parent
SAMPLE = ROOT / "recordings" / "table.mcap"
PROGRAM = ROOT / "recordings" / "programs" / "table.program.json"
TOUCH = ROOT / "tests" / "data" / "touch_table.script.toml"


def cli(*args):
    return CliRunner().invoke(main, [str(a) for a in args])


def _trial(k: int) -> dict:
    program = {"success": True, "failed_macro": None, "reason": "goal reached", "macros": []}
    return {"trial": k, "seed": 1, "values": {}, "program": program, "wall_time": 0.5}


SUMMARY = {"program": "p", "trials": 1, "seed": 1, "detect": "force", "per_parameter": {},
           "program_success_rate": 1.0, "openloop_success_rate": None}


def test_trial_results_never_replace_a_file_without_force(tmp_path):
    (tmp_path / "summary.json").write_text("precious")
    with pytest.raises(OutputError, match=r"summary\.json: exists; give --force"):
        write_outputs(tmp_path, [_trial(0)], SUMMARY)
    assert (tmp_path / "summary.json").read_text() == "precious"
    assert not [p for p in tmp_path.iterdir() if p.name.startswith(".")]  # no temporary file left
    paths = write_outputs(tmp_path, [_trial(0)], SUMMARY, force=True)
    assert sorted(p.name for p in paths) == ["plot.png", "summary.json", "trial_000.json", "trials.csv"]
    assert (tmp_path / "summary.json").read_text().startswith("{")
    assert (tmp_path / "plot.png").read_bytes().startswith(b"\x89PNG")
    assert sorted(p.name for p in tmp_path.iterdir()) == sorted(p.name for p in paths)


def test_demos_json_is_replaced_only_with_force(tmp_path):
    setup = SimpleNamespace(scene=SimpleNamespace(name="table"), base_sha256="0", script=None, seed=1,
                            variations=(), out_dir=str(tmp_path), force=False)
    (tmp_path / "demos.json").write_text("precious")
    with pytest.raises(OutputError, match="exists"):
        write_index(setup, [])  # type: ignore[arg-type]
    assert (tmp_path / "demos.json").read_text() == "precious"
    setup.force = True
    write_index(setup, [])  # type: ignore[arg-type]
    assert '"demonstrations": []' in (tmp_path / "demos.json").read_text()


def test_a_recorder_refuses_an_existing_file_unless_told(tmp_path):
    """Runs and trials record through it (``run --trials --record`` replaced trial_KKK.mcap silently)."""
    from dlovr.scene import load_scene

    bundle = SceneBundle.from_path(load_scene("table").path)
    out = tmp_path / "trial_000.mcap"
    out.write_bytes(b"precious")
    with pytest.raises(OutputError, match="exists; give --force"):
        Recorder(out, bundle, scene_name="table", dt=0.002, t0_ns=0)
    assert out.read_bytes() == b"precious"


def test_batches_refuse_existing_results_before_their_work(tmp_path):
    (tmp_path / "trials.csv").write_text("precious")
    r = cli("run", PROGRAM, "--trials", "2", "-o", tmp_path)
    assert r.exit_code == 2 and f"{tmp_path / 'trials.csv'}: exists; give --force" in r.output, r.output
    (tmp_path / "demos.json").write_text("precious")
    r = cli("record", "--script", TOUCH, "--trials", "2", "-o", str(tmp_path) + "//")
    assert r.exit_code == 2 and "demos.json: exists; give --force" in r.output, r.output
    assert sorted(p.name for p in tmp_path.iterdir()) == ["demos.json", "trials.csv"]
    assert {p.read_text() for p in tmp_path.iterdir()} == {"precious"}


def test_an_output_folder_is_printed_with_one_slash():
    assert [shown_dir(d) for d in ("demos", "demos/", "demos//", "/")] == ["demos/", "demos/", "demos/", "/"]


def test_compile_replaces_only_its_own_programs(tmp_path):
    """A program compile did not write there (or one edited since) is kept unless --force, with
    --sensor-noise too (it implied --force); the others' work goes on."""
    foreign = tmp_path / "table.program.json"
    foreign.write_text("precious")
    r = cli("compile", SAMPLE, "-o", tmp_path, "--sensor-noise", "0.02")
    assert r.exit_code == 2 and f"FAILED {foreign}: exists and is not the program compiled" in r.output
    assert "give --force" in r.output and foreign.read_text() == "precious"
    r = cli("compile", SAMPLE, "-o", tmp_path, "--sensor-noise", "0.02", "--force")
    assert r.exit_code == 0 and foreign.read_text().startswith("{"), r.output
    foreign.write_text(foreign.read_text() + " ")  # edited by hand since
    r = cli("compile", SAMPLE, "-o", tmp_path)  # another sensor noise: compiled again, not skipped
    assert r.exit_code == 2 and "exists and is not the program compiled" in r.output, r.output
    assert foreign.read_text().endswith(" ")
    assert not [p.name for p in tmp_path.iterdir() if p.name.endswith(".part")]


def _panel(tmp_path):
    from dlovr.ui.panels.recording import RecordingPanel

    session = SimpleNamespace(scene=SimpleNamespace(name="table"))
    app = SimpleNamespace(server=None, session=session, recordings_dir=tmp_path, program_text="",
                          last_program=None)
    return RecordingPanel(app), session  # type: ignore[arg-type]


def test_the_browser_writes_a_recording_s_program_only_as_a_new_file(tmp_path):
    rec = tmp_path / "table-1.mcap"
    rec.symlink_to(SAMPLE)
    (tmp_path / "table-1.program.json").write_text("precious")
    panel, _ = _panel(tmp_path)
    panel._compile(rec, "table")
    assert panel.app.program_text  # compiled, shown; not written over the file there
    assert (tmp_path / "table-1.program.json").read_text() == "precious"
    assert not [p for p in tmp_path.iterdir() if p.name.startswith(".")]


def test_the_browser_s_new_recording_takes_the_next_name_when_another_took_it(tmp_path):
    panel, session = _panel(tmp_path)
    tried: list[Path] = []

    def start_recording(path: Path) -> Path:
        tried.append(path)
        if len(tried) == 1:  # another server created it between the look and the creation
            path.write_bytes(b"another server's")
            raise OutputError(f"{path}: exists; give --force to overwrite it")
        return path

    session.start_recording = start_recording
    got = panel._start_new()
    assert got == tried[1] and got.name == tried[0].name.replace(".mcap", "-1.mcap")
    assert tried[0].read_bytes() == b"another server's"
