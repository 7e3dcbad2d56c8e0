"""dlovr: virtual-reality demonstrations of deformable linear object (DLO) manipulation.

The data flows one way: scene -> simulation -> contacts -> topology -> discrete -> transitions ->
program -> execution. The model package (:mod:`dlovr.model`) is pure Python + numpy; geometry
(:mod:`dlovr.geometry`), simulation (:mod:`dlovr.sim`), recordings (:mod:`dlovr.recording`) and the
browser UI (:mod:`dlovr.ui`) sit above it, the command line (:mod:`dlovr.cli`) on top.
"""

__version__ = "0.1.0"
