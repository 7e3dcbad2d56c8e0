"""The pages of docs/ hold: their Python and `dlovr transitions` examples run as written, their links
reach pages and headings that exist, nothing cites files the repository does not ship, docs/model.md
gives the paper's sections and the parameters the code uses (with the code's defaults), and the layout
table of docs/architecture.md names every module of the package and only what exists."""

from __future__ import annotations

import os
import re
import subprocess
import sys
from pathlib import Path

import pytest

from dlovr.model.facts import ModelParams
from dlovr.model.transitions import DEFAULT_FLIGHT_S, DEFAULT_HOLD_S

ROOT = Path(__file__).resolve().parent.parent
DOCS = ROOT / "docs"
PAGES = sorted(DOCS.glob("*.md"))
MODEL_DOC = DOCS / "model.md"
ARCHITECTURE = DOCS / "architecture.md"
# spelt in parts so that this file does not cite them either
UNSHIPPED = ("MODEL" + ".md", "NOTES" + ".md")
TEXT = (".py", ".md", ".toml", ".txt", ".json", ".html", ".cfg", ".ini", ".yml", ".yaml")


def _blocks(language: str) -> list[tuple[str, str]]:
    """(page name, code) of every fenced block of ``language`` in docs/."""
    return [
        (page.name, code)
        for page in PAGES
        for code in re.findall(rf"```{language}\n(.*?)```", page.read_text(), flags=re.S)
    ]


# --------------------------------------------------------------------------------------------------
# Citations and links
# --------------------------------------------------------------------------------------------------


def test_nothing_cites_files_that_are_not_shipped():
    files = [ROOT / "README.md", ROOT / "pyproject.toml", ROOT / "setup.py"]
    for folder in ("dlovr", "docs", "examples", "benchmarks", "scenes", "tests", "recordings", ".ci"):
        files += [p for p in (ROOT / folder).rglob("*") if p.is_file() and p.suffix in TEXT]
    assert len(files) > 100
    for name in UNSHIPPED:
        assert not (ROOT / name).exists()
        citing = [str(p.relative_to(ROOT)) for p in files if name in p.read_text(errors="replace")]
        assert citing == [], f"{name} is cited by {citing}"


def _slug(heading: str) -> str:
    """The anchor GitHub gives a heading: lower case, punctuation dropped, spaces as hyphens."""
    text = re.sub(r"[^\w\- ]", "", heading.strip().lower().replace("`", ""))
    return text.replace(" ", "-")


def _anchors(page: Path) -> set[str]:
    text = re.sub(r"```.*?```", "", page.read_text(), flags=re.S)
    return {_slug(h) for h in re.findall(r"^#+ (.*)$", text, flags=re.M)}


@pytest.mark.parametrize("page", PAGES, ids=[p.name for p in PAGES])
def test_links_reach_pages_and_headings_that_exist(page):
    broken = []
    for target in re.findall(r"\]\(([^)\s]+)\)", page.read_text()):
        if target.startswith(("http://", "https://")):
            continue
        path, _, anchor = target.partition("#")
        file = (page.parent / path).resolve() if path else page
        if not file.exists():
            broken.append(target)
        elif anchor and file.suffix == ".md" and anchor not in _anchors(file):
            broken.append(target)
    assert not broken, f"{page.name}: broken links {broken}"


def test_readme_links_model_doc():
    assert "docs/model.md" in (ROOT / "README.md").read_text()


# --------------------------------------------------------------------------------------------------
# Examples run as written
# --------------------------------------------------------------------------------------------------

PYTHON = _blocks("python")


def test_docs_have_python_examples():
    assert {page for page, _ in PYTHON} >= {"scaling.md", "transitions.md"}


@pytest.mark.parametrize("page,code", PYTHON, ids=[f"{p}-{i}" for i, (p, _) in enumerate(PYTHON)])
def test_python_example_runs(page, code, tmp_path):
    """Each example runs as printed and leaves no temporary folder behind (TMPDIR stays empty)."""
    tmp = tmp_path / "tmp"
    tmp.mkdir()
    env = {**os.environ, "TMPDIR": str(tmp)}
    r = subprocess.run(
        [sys.executable, "-c", code], cwd=ROOT, capture_output=True, text=True, timeout=300, env=env
    )
    assert r.returncode == 0, f"{page}: {r.stderr[-2000:]}"
    assert not list(tmp.iterdir()), f"{page}: left behind {sorted(p.name for p in tmp.iterdir())}"


# The shell examples of `dlovr transitions` (they write their own input files): run as printed, in a
# scratch directory, with `dlovr` being this checkout's CLI.
TRANSITIONS = [(p, b) for p, b in _blocks("sh") if "dlovr transitions" in b and "<<'X'" in b]


def test_the_transitions_examples_with_and_without_facts_are_there():
    assert any("--facts" in b for _, b in TRANSITIONS) and any("--facts" not in b for _, b in TRANSITIONS)


@pytest.mark.parametrize("page,code", TRANSITIONS, ids=[f"{p}-{i}" for i, (p, _) in enumerate(TRANSITIONS)])
def test_transitions_example_runs(page, code, tmp_path):
    prelude = f'dlovr() {{ "{sys.executable}" -m dlovr "$@"; }}\nset -eo pipefail\n'
    env = {**os.environ, "PYTHONPATH": str(ROOT)}
    r = subprocess.run(
        ["bash", "-c", prelude + code], cwd=tmp_path, capture_output=True, text=True, timeout=120, env=env
    )
    assert r.returncode == 0, f"{page}: {r.stderr[-2000:]}"
    rows = r.stdout.splitlines()[1:]
    assert rows and all(row.split()[0].isdigit() for row in rows), r.stdout
    if "--facts" in code:
        assert "E/E^P[box.F1,box.F2]" in rows[-1] and rows[-1].split()[1] == "C"


# --------------------------------------------------------------------------------------------------
# docs/model.md: the paper's sections and the code's parameters
# --------------------------------------------------------------------------------------------------


def test_model_doc_follows_the_papers_sections():
    doc = MODEL_DOC.read_text()
    headings = re.findall(r"^## \d+\. .*$", doc, flags=re.M)
    for section in ("§II", "§III", "§IV", "§V", "§VI"):
        assert any(h.endswith(f"({section})") for h in headings), (section, headings)


def _parameter(doc: str, name: str) -> str:
    (row,) = [line for line in doc.splitlines() if line.startswith(f"| {name} |")]
    return row.split("|")[2].strip()


def test_model_doc_gives_the_parameters_with_the_codes_defaults():
    doc = MODEL_DOC.read_text().split("## 7. Parameters", 1)[1]
    p = ModelParams()
    assert _parameter(doc, "tip angle") == f"{p.tip_angle_deg:g}°"
    assert _parameter(doc, "critical angle") == f"{p.critical_angle_deg:g}°"
    assert _parameter(doc, "parallel tolerance") == f"{p.parallel_tol_deg:g}°"
    assert _parameter(doc, "hold time") == f"{DEFAULT_HOLD_S:g} s"
    assert _parameter(doc, "flight time") == f"{DEFAULT_FLIGHT_S:g} s"
    from dlovr.sim.tracker import ContactTracker

    bands = {k: f.default for k, f in ContactTracker.__dataclass_fields__.items() if k.endswith("_band_deg")}
    assert _parameter(doc, "tip angle band") == f"{bands['tip_band_deg']:g}°"
    assert _parameter(doc, "parallel tolerance band") == f"{bands['line_band_deg']:g}°"


# --------------------------------------------------------------------------------------------------
# docs/architecture.md: the "Layout" table names every module, and the public names it lists import
# --------------------------------------------------------------------------------------------------

ARCH = ARCHITECTURE.read_text()
LAYOUT = ARCH.split("## Layout", 1)[1].split("\n## ", 1)[0]
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


def test_layout_table_names_every_module():
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
    assert not missing, f"docs/architecture.md's layout table lacks {missing}"


def test_layout_table_names_only_what_exists():
    for row in TABLE_ROWS:
        first = row.split("|")[1].strip().strip("`")
        for name in re.findall(r"dlovr/[\w/.]+", row.split("|")[1]):
            assert (ROOT / name).exists(), f"the layout table names {name} ({first}), which does not exist"
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
def test_public_names_import(module):
    paragraph = ARCH.split("The packages' public names:", 1)[1].split("\n\n", 1)[0]
    code = f"from {module} import {', '.join(PUBLIC[module])}"
    r = subprocess.run([sys.executable, "-c", code], cwd=ROOT, capture_output=True, text=True, timeout=120)
    assert r.returncode == 0, r.stderr[-2000:]
    for name in PUBLIC[module]:
        assert f"`{name}`" in paragraph, f"docs/architecture.md's public names no longer list {name}"


def test_the_docs_say_who_writes_the_trial_files_and_when():
    """``trial_KKK.json`` and the other result files are written by the command after the batch
    (execution.trials.write_outputs, called by cli/run.py once run_trials returned), not by the
    workers as they finish: the docs say so and claim nothing else."""
    rows = [line for line in (DOCS / "scaling.md").read_text().splitlines() if "`trial_KKK.json`" in line]
    assert rows and all("the command, after the batch" in row for row in rows)
    text = " ".join(p.read_text() for p in [*PAGES, ROOT / "README.md"])
    assert not re.search(r"trial_KKK\.json[^.|]*as (they|each) finish", text)


def test_every_example_script_is_listed():
    listed = set(re.findall(r"`examples/(\w+\.py)`", ARCH))
    assert listed == {p.name for p in (ROOT / "examples").glob("*.py")}


def test_inputs_doc_lists_every_limit_with_the_codes_value():
    """docs/inputs.md's table of limits is ``dlovr.inputs.LIMITS``: every key, with its value."""
    from dlovr.inputs import LIMITS

    rows = {
        line.split("|")[1].strip().strip("`"): line.split("|")[2].strip()
        for line in (ROOT / "docs" / "inputs.md").read_text().splitlines()
        if line.startswith("| `")
    }
    assert set(rows) == set(LIMITS)
    for key, value in LIMITS.items():
        number, _, unit = rows[key].partition(" ")
        scale = {"MiB": 1024 * 1024, "m": 1, "s": 1, "": 1}[unit]
        assert float(number) * scale == value, f"docs/inputs.md says {key} = {rows[key]}, the code {value}"
