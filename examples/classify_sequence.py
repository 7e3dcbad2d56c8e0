"""Classify a logged sequence of discrete contact situations (no simulator needed).

Run::

    python examples/classify_sequence.py

The sequence is the first steps of the paper's peg-in-hole example (Fig. 11): the cable's tip
touches the block's top face, the cable is laid down on it, pushed over its edge, and turned about
the edge. Each step prints its transition class (``-``: no principal contact changed).
"""

from __future__ import annotations

from dlovr.model.discrete import parse_discrete_situation
from dlovr.model.transitions import classify_sequence

LOG = """
V/G & E/N & V/N
V/G & E/N & V/F[block.F1]
V/G & E/N & E/F[block.F1] & V/N
V/G & E/N & E/F[block.F1] & E/E^P[block.F1,block.F2] & V/N
V/G & E/N & E/E^P[block.F1,block.F2] & V/N
V/G & E/N & V/F[block.F2]
"""


def main() -> None:
    situations = [parse_discrete_situation(line) for line in LOG.strip().splitlines()]
    for step in classify_sequence(situations):
        print(f"{step.index:2}  {step.label:4}  {step.situation.format()}")


if __name__ == "__main__":
    main()
