"""What ``dlovr run`` prints and writes of a result: macros that ended by motion are marked, and the
numbers in result files are rounded (issue 31, item 16)."""

from __future__ import annotations

import json

from dlovr.execution.scoring import MacroScore, RunResult, format_result
from dlovr.execution.trials import write_outputs
from dlovr.outputs import rounded


def _result(ended: str) -> RunResult:
    m = MacroScore(1, "E", "E/F", 0.0, 0.43 + 1e-16, 0.4300000000000003, 0.1, "ok", 0.01, 0.02, "", ended)
    return RunResult("p", "s", "force", True, True, ("E/F",), "E/F", ("E/F",), None, "", (m,), 1.0, 2.0)


def test_a_macro_that_ended_by_motion_is_marked_and_the_mark_explained():
    text = format_result(_result("motion"))
    assert "(by motion)" in text.splitlines()[2]
    assert "ended when its demonstrated motion was done" in text
    assert "(by motion)" not in format_result(_result("detected"))


def test_rounded_rounds_every_float_and_keeps_the_rest():
    data = {"a": 0.4300000000000003, "b": [1, True, (0.1 + 0.2, "x")], "c": None}
    assert rounded(data) == {"a": 0.43, "b": [1, True, [0.3, "x"]], "c": None}
    assert json.dumps(rounded(_result("motion").to_json())).count("0.4300000000000003") == 0


def test_trial_files_carry_rounded_numbers(tmp_path, monkeypatch):
    monkeypatch.setattr("dlovr.execution.trials.plot", lambda summary, path: path)
    res = _result("detected").to_json()
    trial = {"trial": 0, "values": {"dlo.young": 0.1 + 0.2}, "program": res, "wall_time": 1.23456}
    write_outputs(tmp_path, [trial], {"success_rate": 0.1 + 0.2})
    for name in ("trial_000.json", "trials.csv", "summary.json"):
        text = (tmp_path / name).read_text()
        assert "0.30000000000000004" not in text and "0.4300000000000003" not in text, name


def test_the_sensed_goal_check_is_printed_with_its_angle():
    from dataclasses import replace

    doubted = replace(_result("detected"), goal_sensed=False, goal_angle=14.2)
    assert "contact vector does NOT confirm the goal (14.2 deg" in format_result(doubted)
    assert "sensed goal check" not in format_result(_result("detected"))  # no check: nothing said
