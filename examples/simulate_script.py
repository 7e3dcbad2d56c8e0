"""Simulate a scripted demonstration headless and print its contact situations.

Run from the repository root::

    python examples/simulate_script.py                      # the table demonstration
    python examples/simulate_script.py scenes/edges.script.toml

Each line is a kept (debounced) situation: its start time in seconds, the transition class that led
to it (``-`` when none) and the discrete situation with face names.
"""

from __future__ import annotations

import sys
from pathlib import Path

from dlovr.scene import load_scene
from dlovr.script import load_script
from dlovr.sim import Simulator

ROOT = Path(__file__).resolve().parent.parent


def main(script_path: str) -> None:
    script = load_script(script_path)
    sim = Simulator(load_scene(script.scene or "table"), track=True)
    for _ in sim.run(script):  # one record per 2 ms step: time, cable points, contacts, situations
        pass
    for kept, classes in sim.tracker.transitions():
        print(f"{kept.start:7.3f} s  {','.join(classes) or '-':4}  {kept.situation}")


if __name__ == "__main__":
    main(sys.argv[1] if len(sys.argv) > 1 else str(ROOT / "scenes" / "table.script.toml"))
