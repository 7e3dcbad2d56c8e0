"""The project documents its own model (issue 15, item 9): nothing cites the specification file that
is not in the repository, and docs/model.md gives the paper's sections and the parameters the code
uses, with the code's defaults."""

from __future__ import annotations

import re
from pathlib import Path

from dlovr.model.facts import ModelParams
from dlovr.model.transitions import DEFAULT_FLIGHT_S, DEFAULT_HOLD_S

ROOT = Path(__file__).resolve().parent.parent
MODEL_DOC = ROOT / "docs" / "model.md"
SPEC = "MODEL" + ".md"  # spelt in two parts so that this file does not cite it either
TEXT = (".py", ".md", ".toml", ".txt", ".json", ".html", ".cfg", ".ini", ".yml", ".yaml")


def test_nothing_cites_the_specification_that_is_not_shipped():
    assert not (ROOT / SPEC).exists()
    files = [ROOT / "README.md", ROOT / "pyproject.toml", ROOT / "setup.py"]
    for folder in ("dlovr", "docs", "examples", "benchmarks", "scenes", "tests", "recordings", ".ci"):
        files += [p for p in (ROOT / folder).rglob("*") if p.is_file() and p.suffix in TEXT]
    citing = [str(p.relative_to(ROOT)) for p in files if SPEC in p.read_text(errors="replace")]
    assert len(files) > 100 and citing == []


def test_model_doc_follows_the_papers_sections():
    doc = MODEL_DOC.read_text()
    headings = re.findall(r"^## \d+\. .*$", doc, flags=re.M)
    for section in ("§II", "§III", "§IV", "§V", "§VI"):
        assert any(h.endswith(f"({section})") for h in headings), (section, headings)
    assert "docs/model.md" in (ROOT / "README.md").read_text()


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
