"""The benchmarks run (a short smoke run each where one is cheap; their figures are not checked)."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
#: The recording tests' short demonstration on the table (3.7 s simulated).
TOUCH = Path(__file__).parent / "data" / "touch_table.script.toml"


def bench(name: str, *args: str, timeout: float = 300) -> subprocess.CompletedProcess[str]:
    """``benchmarks/NAME`` run with ``args`` from the project's root."""
    return subprocess.run([sys.executable, str(ROOT / "benchmarks" / name), *args], capture_output=True,
                          text=True, timeout=timeout, cwd=ROOT)


@pytest.mark.slow
def test_bench_recording_runs_repeated_rounds():
    """Each round records again into the same file (the recorder never overwrites one: the benchmark
    removes the last round's first)."""
    run = bench("bench_recording.py", "--scene", "table", "--script", str(TOUCH), "--repeat", "2",
                "--replays", "1", "--no-compile")
    assert run.returncode == 0, run.stderr[-2000:]
    assert "simulation + recording" in run.stdout and "divergence: None" in run.stdout


@pytest.mark.slow
@pytest.mark.parametrize("name", sorted(p.name for p in (ROOT / "benchmarks").glob("*.py")))
def test_every_benchmark_says_how_to_run_it(name):
    run = bench(name, "--help", timeout=120)
    assert run.returncode == 0 and "usage:" in run.stdout, run.stderr[-2000:]
