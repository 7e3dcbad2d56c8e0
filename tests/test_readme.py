"""The README stays a short front page: its Python example runs as written, it has at most 250 lines,
its links into docs/ and its picture exist, its command table names every command, and its test
command is the one .ci/run runs. The pages it links to are tested in tests/test_docs.py."""

from __future__ import annotations

import re
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parent.parent
README = (ROOT / "README.md").read_text()
BLOCKS = re.findall(r"```python\n(.*?)```", README, flags=re.S)
MAX_LINES = 250


def test_readme_is_short():
    assert len(README.splitlines()) <= MAX_LINES


def test_readme_has_a_python_example():
    assert BLOCKS


@pytest.mark.slow
@pytest.mark.parametrize("code", BLOCKS, ids=[f"block{i}" for i in range(len(BLOCKS))])
def test_readme_python_example_runs(code):
    r = subprocess.run([sys.executable, "-c", code], cwd=ROOT, capture_output=True, text=True, timeout=300)
    assert r.returncode == 0, r.stderr[-2000:]


def test_readme_links_into_docs_exist_and_reach_every_page():
    links = set(re.findall(r"\]\((docs/[^)#\s]+)(?:#[^)]*)?\)", README))
    assert links, "the README links to no page of docs/"
    missing = sorted(link for link in links if not (ROOT / link).is_file())
    assert not missing, f"README links to missing pages: {missing}"
    pages = {f"docs/{p.name}" for p in (ROOT / "docs").glob("*.md")}
    assert pages <= links, f"pages of docs/ the README does not link to: {sorted(pages - links)}"


def test_readme_picture_exists():
    images = re.findall(r"!\[[^\]]*\]\(([^)\s]+)\)", README)
    assert images, "the README shows no picture"
    assert all((ROOT / image).is_file() for image in images), images


def _commands() -> list[str]:
    """The commands `dlovr --help` lists."""
    r = subprocess.run([sys.executable, "-m", "dlovr", "--help"], cwd=ROOT, capture_output=True, text=True)
    assert r.returncode == 0, r.stderr
    listing = r.stdout.split("Commands:", 1)[1]
    return [line.split()[0] for line in listing.splitlines() if line.strip()]


def test_readme_command_table_names_every_command():
    table = README.split("## Commands", 1)[1].split("\n## ", 1)[0]
    rows = [line for line in table.splitlines() if line.startswith("| `dlovr ")]
    named = {row.split("`")[1].split()[1] for row in rows}
    commands = _commands()
    assert len(commands) >= 10
    assert set(commands) <= named, f"README's command table lacks {sorted(set(commands) - named)}"


def test_readme_test_command_is_the_one_ci_runs():
    quick_start = README.split("## Quick start", 1)[1].split("\n## ", 1)[0]
    (command,) = [b.strip() for b in re.findall(r"```sh\n(.*?)```", quick_start, flags=re.S) if "pytest" in b]
    ci = (ROOT / ".ci" / "run").read_text()
    assert command in ci, f".ci/run does not run the README's test command {command!r}"
    assert ".ci/run" in quick_start
