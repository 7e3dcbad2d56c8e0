"""Inputs missing a field dlovr always writes give one line naming the field, never Python's
``KeyError: 'scene_name'``; a program run that cannot follow its demonstration says so (the command
line, the browser's run panel and ``generate`` alike)."""

from __future__ import annotations

from dataclasses import replace
from pathlib import Path
from types import SimpleNamespace

import pytest
from click.testing import CliRunner
from mcap_edit import rewrite_mcap

from dlovr.cli import main
from dlovr.execution.network_run import network_scene
from dlovr.model.network import NetworkError
from dlovr.model.planning import PROGRAM_VERSION, NetworkProgram
from dlovr.model.program import Program, ProgramError
from dlovr.recording.format import one_line

ROOT = Path(__file__).resolve().parent.parent
SAMPLE = ROOT / "recordings" / "table.mcap"
PROGRAM = ROOT / "recordings" / "programs" / "table.program.json"


def test_a_recording_without_its_scene_name_is_one_line(tmp_path):
    bad = tmp_path / "noname.mcap"
    rewrite_mcap(SAMPLE, bad, metadata=lambda name, d: {k: v for k, v in d.items() if k != "scene_name"})
    for cmd in ("states", "compile", "network"):
        args = [cmd, str(bad)] + (["-o", str(tmp_path / "n.json")] if cmd == "network" else [])
        r = CliRunner().invoke(main, args)
        assert r.exit_code == 2, (cmd, r.output)
        assert f"{bad}: metadata scene_name: missing" in r.output and "KeyError" not in r.output, r.output


def test_a_network_program_without_a_field_names_it():
    with pytest.raises(NetworkError, match=r"^reach_m: missing$"):
        NetworkProgram.from_json({"kind": "network-program", "version": PROGRAM_VERSION})


def test_a_network_without_a_scene_name_asks_for_scene():
    nprog = SimpleNamespace(name="p", network=SimpleNamespace(scene_name=""))
    with pytest.raises(ProgramError, match="names no scene: give --scene"):
        network_scene(nprog, None)  # type: ignore[arg-type]  # it looked for a scene file named ''


def test_a_missing_field_is_named():
    assert one_line(KeyError("t")) == "field 't' missing"


def test_the_run_panel_says_when_the_demonstration_is_not_followed(tmp_path, monkeypatch):
    from dlovr.ui.panels.run import demonstration

    monkeypatch.chdir(tmp_path)
    program = replace(Program.load(PROGRAM), source="gone.mcap")
    track, note = demonstration(program)
    assert track is None and note == (
        "its demonstration 'gone.mcap' was not found: the macros move along the program's poses"
    )
    track, note = demonstration(Program.load(PROGRAM))
    assert track is not None and note == ""
