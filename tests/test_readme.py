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


@pytest.mark.slow
@pytest.mark.parametrize("code", BLOCKS, ids=[f"block{i}" for i in range(len(BLOCKS))])
def test_readme_python_example_runs(code):
    r = subprocess.run([sys.executable, "-c", code], cwd=ROOT, capture_output=True, text=True, timeout=300)
    assert r.returncode == 0, r.stderr[-2000:]


# The shell examples of the contact model (they write their own input files): run as printed, in a
# scratch directory, with `dlovr` being this checkout's CLI.
SH_BLOCKS = [
    b for b in re.findall(r"```sh\n(.*?)```", (ROOT / "README.md").read_text(), flags=re.S)
    if "dlovr transitions" in b and "<<'X'" in b
]


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


# The README's "Layout" table names every module of the package, and the public names it lists import.
README = (ROOT / "README.md").read_text()
LAYOUT = README.split("## Layout", 1)[1].split("\n## ", 1)[0]
TABLE_ROWS = [line for line in LAYOUT.splitlines() if line.startswith("| `")]


def _package_rows(package: str) -> str:
    """The table's text for ``dlovr/<package>/``: its row and the indented rows below it."""
    out, inside = [], False
    for row in TABLE_ROWS:
        if row.startswith(f"| `dlovr/{package}/`"):
            inside = True
        elif not row.startswith("| `  "):
            inside = False
        if inside:
            out.append(row)
    return "\n".join(out)


def test_readme_layout_table_names_every_module():
    pkg = ROOT / "dlovr"
    missing = []
    for path in sorted(pkg.rglob("*.py")):
        rel = path.relative_to(pkg)
        if rel.name in ("__init__.py", "__main__.py"):
            continue
        if len(rel.parts) == 1:  # a top-level module: named with its file name somewhere in the table
            if not re.search(rf"`(dlovr/)?{re.escape(rel.name)}`", LAYOUT):
                missing.append(str(rel))
            continue
        text = _package_rows(rel.parts[0])
        if len(rel.parts) == 2:  # a module of the package: `name` or `name.py`, in backticks
            pattern = rf"`(\s*){re.escape(path.stem)}(\.py)?`"
        else:  # a module of a subpackage (ui/panels/state.py): its name in the package's row
            pattern = rf"\b{re.escape(path.stem)}\b"
        if not text or not re.search(pattern, text):
            missing.append(str(rel))
    assert not missing, f"README layout table lacks {missing}"


def test_readme_layout_table_names_only_what_exists():
    for row in TABLE_ROWS:
        first = row.split("|")[1].strip().strip("`")
        for name in re.findall(r"dlovr/[\w/.]+", row.split("|")[1]):
            assert (ROOT / name).exists(), f"README layout table names {name} ({first}), which does not exist"
    assert (ROOT / "examples").is_dir() and "`examples/`" in LAYOUT


PUBLIC = {
    "dlovr.geometry": ["SceneGeometry", "decompose", "object_faces"],
    "dlovr.sim": ["Simulator"],
    "dlovr.sim.tracker": ["ContactTracker"],
    "dlovr.recording": ["Recording", "DemoRecorder", "replay", "recover", "compile_recording"],
    "dlovr.model.network": ["build_network"],
    "dlovr.model.planning": ["NetworkProgram", "identify"],
    "dlovr.batch": ["run_batch"],
}


@pytest.mark.parametrize("module", sorted(PUBLIC))
def test_readme_public_names_import(module):
    paragraph = README.split("The packages' public names:", 1)[1].split("\n\n", 1)[0]
    code = f"from {module} import {', '.join(PUBLIC[module])}"
    r = subprocess.run([sys.executable, "-c", code], cwd=ROOT, capture_output=True, text=True, timeout=120)
    assert r.returncode == 0, r.stderr[-2000:]
    for name in PUBLIC[module]:
        assert f"`{name}`" in paragraph, f"README's public names no longer list {name}"
