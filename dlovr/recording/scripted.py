"""Playing a demonstration script on a simulator, step by step, optionally recording each step: the
one loop behind ``dlovr demo``, ``dlovr record`` and ``dlovr record --trials``."""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

from dlovr.recording.writer import DemoRecorder, StopSignals
from dlovr.sim import SimulationDiverged

#: Steps between two calls of ``progress``.
PROGRESS_EVERY = 100


def play_script(
    sim: Any,
    script: Any,
    recorder: DemoRecorder | None = None,
    *,
    progress: Callable[[int], None] | None = None,
    stop: StopSignals | None = None,
) -> str | None:
    """Run ``script`` (a :class:`dlovr.script.Script`) on ``sim`` (a :class:`dlovr.sim.Simulator`)
    to its end, passing each step to ``recorder`` when given.

    ``progress(n)`` is called with ``n`` = :data:`PROGRESS_EVERY` after every that many steps;
    with ``stop``, the loop ends between two steps once it caught a signal (``stop.signum``).
    Returns None, or why the simulation ended early (it diverged), which is then also the
    recorder's ``end_reason`` (written in its end marker).
    """
    try:
        for k, record in enumerate(sim.run(script), 1):
            if recorder is not None:
                recorder.step(record)
            if progress is not None and k % PROGRESS_EVERY == 0:
                progress(PROGRESS_EVERY)
            if stop is not None and stop.signum is not None:
                break
    except SimulationDiverged as e:
        if recorder is not None:
            recorder.end_reason = str(e)
        return str(e)
    return None
