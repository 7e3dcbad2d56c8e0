"""dlovr: virtual-reality demonstrations of deformable linear object (DLO) manipulation.

The data flows one way: scene -> simulation -> contacts -> topology -> discrete -> transitions ->
program -> execution. The model package (:mod:`dlovr.model`) is pure Python + numpy; geometry
(:mod:`dlovr.geometry`), simulation (:mod:`dlovr.sim`), recordings (:mod:`dlovr.recording`) and the
browser UI (:mod:`dlovr.ui`) sit above it, the command line (:mod:`dlovr.cli`) on top.

Run as the command line (the ``dlovr`` script or ``python -m dlovr``), this is the first of dlovr's
code to run: it takes SIGINT and SIGTERM over at once (:func:`dlovr.signals.defer`), before any
heavy import, so that a signal from then on ends the command with one line and 130/143. Before it,
while the interpreter itself starts, a signal ends Python the default way (docs/recordings.md).
"""

import itertools as _itertools
import os as _os
import sys as _sys

__version__ = "0.1.0"


def _is_command_line() -> bool:
    """Whether this process is the ``dlovr`` script or ``python -m dlovr`` (not a library user)."""
    main = _sys.modules.get("__main__")
    if _os.path.basename(getattr(main, "__file__", None) or "") == "dlovr":
        return True
    argv = list(getattr(_sys, "orig_argv", ()))
    return "-mdlovr" in argv or any(pair == ("-m", "dlovr") for pair in _itertools.pairwise(argv))


if _is_command_line():
    from dlovr import signals as _signals

    _signals.defer()  # a signal while the command line is imported ends the command once it is ready
