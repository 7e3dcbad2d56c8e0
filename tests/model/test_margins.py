"""The margin a demonstration left past a transition that no force shows (dlovr.model.margins)."""

from __future__ import annotations

from types import SimpleNamespace

import numpy as np
import pytest

from dlovr.model.margins import DRAG_MIN_M, PLACEMENT_M, blind, blind_margins, margin_warning, went_on
from dlovr.model.program import ContactSpec, Detection

T = np.linspace(0.0, 3.0, 301)  # 10 ms samples


def _track(stop_at: float) -> np.ndarray:
    """A gripper dragging 40 mm along -y in 2 s, then holding, stopping at ``stop_at`` m of the drag."""
    y = -np.minimum(T * 0.02, stop_at)
    return np.stack([np.zeros_like(T), y, np.full_like(T, 0.1)], axis=1)


def _macro(index: int = 6, classes: tuple[str, ...] = ("I",), step_n: float = 0.0, t: float = 1.0,
           world: tuple[float, float, float] = (0.0, -0.02, 0.0), final: bool = False,
           new: str = "V/VI[block.F3,block.F5,holeblock.F2,holeblock.F11]") -> SimpleNamespace:
    """A macro whose transition (into ``new``) came at ``t`` s after moving ``world`` m; ``step_n`` 0:
    no force signal."""
    params = {"min_force_n": 0.05, "step_n": step_n, "noise_n": 0.001}
    det = Detection("I", "force_enters_instable_vector", params)
    return SimpleNamespace(index=index, classes=classes, label=",".join(classes), t=t, final=final,
                           motion=SimpleNamespace(world=world), detection=(det,),
                           established=(ContactSpec(new, None),))


def test_went_on_is_the_furthest_motion_along_the_direction_within_the_window():
    pos = _track(0.023)  # the transition at 1 s (20 mm in), 3 mm more, then the gripper holds
    assert went_on(T, pos, 1.0, (0.0, -1.0, 0.0)) == pytest.approx(0.003)
    assert went_on(T, pos, 1.0, (0.0, 1.0, 0.0)) == 0.0  # back along it: none
    assert went_on(T, pos, 1.0, (0.0, -1.0, 0.0), window=0.05) == pytest.approx(0.001)
    assert went_on(T, pos, 5.0, (0.0, -1.0, 0.0)) == 0.0  # past the track's end


def test_a_drag_into_an_instability_without_force_signal_and_little_margin_is_listed():
    prog = SimpleNamespace(macros=[_macro()])
    assert blind(prog.macros[0])
    got = blind_margins(prog, T, _track(0.023))
    assert [k for k, _ in got] == [6] and got[0][1] == pytest.approx(0.003)
    text = margin_warning(got)
    assert text is not None and "macro 6 (3.0 mm)" in text and f"{PLACEMENT_M * 1000:g} mm" in text
    assert margin_warning([]) is None
    assert [k for k, _ in blind_margins(prog, T, _track(0.026), least=0.01)] == [6]


@pytest.mark.parametrize(
    ("why", "macro", "stop_at"),
    [
        ("margin enough", _macro(), 0.026),
        ("a force signal", _macro(step_n=0.2), 0.023),
        ("a stable transition", _macro(classes=("C",)), 0.023),
        ("not the tip", _macro(new="E/E^LI[convex185.F2,convex185.F3]"), 0.023),
        ("no drag", _macro(world=(0.0, -DRAG_MIN_M / 2, 0.0)), 0.023),
        ("the final motion", _macro(final=True), 0.023),
    ],
)
def test_not_listed(why, macro, stop_at):
    assert blind_margins(SimpleNamespace(macros=[macro]), T, _track(stop_at)) == [], why
