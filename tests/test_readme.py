"""The README's Python examples run as written (from the repository root)."""

from __future__ import annotations

import re
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parent.parent
BLOCKS = re.findall(r"```python\n(.*?)```", (ROOT / "README.md").read_text(), flags=re.S)


def test_readme_has_python_examples():
    assert len(BLOCKS) >= 2


@pytest.mark.parametrize("code", BLOCKS, ids=[f"block{i}" for i in range(len(BLOCKS))])
def test_readme_python_example_runs(code):
    r = subprocess.run([sys.executable, "-c", code], cwd=ROOT, capture_output=True, text=True, timeout=300)
    assert r.returncode == 0, r.stderr[-2000:]


# The shell examples of the contact model (they write their own input files): run as printed, in a
# scratch directory, with `dlovr` being this checkout's CLI.
SH_BLOCKS = [
    b for b in re.findall(r"```sh\n(.*?)```", (ROOT / "README.md").read_text(), flags=re.S)
    if "dlovr transitions" in b and "<<'X'" in b
]  # fmt: skip


def test_readme_has_the_transitions_examples_with_and_without_facts():
    assert any("--facts" in b for b in SH_BLOCKS) and any("--facts" not in b for b in SH_BLOCKS)


@pytest.mark.parametrize("code", SH_BLOCKS, ids=[f"sh{i}" for i in range(len(SH_BLOCKS))])
def test_readme_transitions_example_runs(code, tmp_path):
    prelude = f'dlovr() {{ "{sys.executable}" -m dlovr "$@"; }}\nset -eo pipefail\n'
    env = {**__import__("os").environ, "PYTHONPATH": str(ROOT)}
    r = subprocess.run(
        ["bash", "-c", prelude + code], cwd=tmp_path, capture_output=True, text=True, timeout=120, env=env
    )
    assert r.returncode == 0, r.stderr[-2000:]
    rows = r.stdout.splitlines()[1:]
    assert rows and all(row.split()[0].isdigit() for row in rows), r.stdout
    if "--facts" in code:
        assert "E/E^P[box.F1,box.F2]" in rows[-1] and rows[-1].split()[1] == "C"
