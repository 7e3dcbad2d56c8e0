"""The benchmarks run (a short smoke run each where one is cheap; their figures are not checked)."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]

#: Down onto the table and up again: 0.8 s simulated.
SHORT = """scene = "table"
[[waypoints]]
pos = [0.0, 0.0, 0.56]
duration = 0.4
[[waypoints]]
pos = [0.0, 0.0, 0.62]
duration = 0.4
"""


@pytest.mark.slow
def test_bench_recording_runs_repeated_rounds(tmp_path):
    """Each round records again into the same file (the recorder never overwrites one: the benchmark
    removes the last round's first)."""
    script = tmp_path / "short.script.toml"
    script.write_text(SHORT)
    cmd = [sys.executable, str(ROOT / "benchmarks" / "bench_recording.py"), "--scene", "table", "--script",
           str(script), "--repeat", "2", "--replays", "1", "--no-compile"]
    run = subprocess.run(cmd, capture_output=True, text=True, timeout=300, cwd=ROOT)
    assert run.returncode == 0, run.stderr[-2000:]
    assert "simulation + recording" in run.stdout and "divergence: None" in run.stdout


@pytest.mark.slow
@pytest.mark.parametrize("bench", sorted(p.name for p in (ROOT / "benchmarks").glob("*.py")))
def test_every_benchmark_says_how_to_run_it(bench):
    run = subprocess.run([sys.executable, str(ROOT / "benchmarks" / bench), "--help"], capture_output=True,
                         text=True, timeout=120, cwd=ROOT)
    assert run.returncode == 0 and "usage:" in run.stdout, run.stderr[-2000:]
