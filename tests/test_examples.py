"""Every script in examples/ runs as written and prints what its docstring promises."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parent.parent
EXAMPLES = sorted((ROOT / "examples").glob("*.py"))


def run(name: str, *args: str, env: dict[str, str] | None = None) -> str:
    r = subprocess.run(
        [sys.executable, str(ROOT / "examples" / name), *args],
        cwd=ROOT,
        capture_output=True,
        text=True,
        timeout=300,
        env=env,
    )
    assert r.returncode == 0, r.stderr
    assert "Traceback" not in r.stderr
    return r.stdout


def test_every_example_is_tested():
    tested = {"simulate_script.py", "classify_sequence.py", "compile_recordings.py"}
    assert {p.name for p in EXAMPLES} == tested


def test_classify_sequence_prints_fig11_classes():
    rows = [line.split()[:2] for line in run("classify_sequence.py").splitlines()]
    assert rows == [["0", "-"], ["1", "E"], ["2", "C"], ["3", "-"], ["4", "C"], ["5", "C"]]


@pytest.mark.slow
def test_simulate_script_prints_kept_situations():
    out = run("simulate_script.py", "scenes/table.script.toml").splitlines()
    assert out, "no situation printed"
    assert all(" s  " in line for line in out)
    assert any("V/F[table.F1]" in line for line in out)
    assert any("E/F[table.F1]" in line for line in out)


@pytest.mark.parametrize("folder", ["recordings"])
def test_compile_recordings_writes_programs(tmp_path, folder):
    out = run("compile_recordings.py", folder, str(tmp_path))
    samples = sorted(p.stem for p in (ROOT / folder).glob("*.mcap"))
    assert sorted(p.name.removesuffix(".program.json") for p in tmp_path.glob("*.program.json")) == samples
    for stem in samples:
        assert f"{stem}.mcap:" in out


def test_compile_recordings_without_an_output_folder_leaves_no_temporary_folder(tmp_path):
    """Without an output folder the programs go to a temporary one, removed at the end."""
    src, tmp = tmp_path / "src", tmp_path / "tmp"
    src.mkdir()
    tmp.mkdir()
    (src / "table.mcap").symlink_to(ROOT / "recordings" / "table.mcap")
    out = run("compile_recordings.py", str(src), env={**os.environ, "TMPDIR": str(tmp)})
    assert "table.mcap: " in out and "-> " + str(tmp) in out
    assert not list(tmp.iterdir())
