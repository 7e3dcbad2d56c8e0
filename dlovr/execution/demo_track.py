"""The demonstration's track: the gripper trajectory a recording commanded, as programs follow it.

- :class:`DemoTrack`: times, positions and orientations of the commanded gripper (world frame), with
  the forces the demonstration sensed where its recording has a wrench channel;
- :func:`load_track`: a recording's :class:`DemoTrack`.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, cast

import numpy as np

from dlovr.model.derivation import FREE_WINDOW_S, GOAL_SENSE_S


@dataclass(frozen=True)
class DemoTrack:
    """The demonstration's commanded gripper trajectory: times (k,) s, positions (k, 3) m and
    quaternions (k, 4) wxyz, world frame (``dlovr.recording.Recording.commands`` scaled to time)."""

    t: np.ndarray
    pos: np.ndarray
    quat: np.ndarray
    #: the force (N, world) the demonstration sensed at its end (mean over its last
    #: :data:`GOAL_SENSE_S`), where the recording has a wrench channel: what the goal feels like
    end_force: tuple[float, float, float] | None = None
    #: the force (N, world) the demonstration sensed while its cable hung free at its start (mean over
    #: :data:`FREE_WINDOW_S`): the demonstrated cable's weight, as its sensor read it
    free_force: tuple[float, float, float] | None = None
    #: the wrench the demonstration sensed (a :class:`dlovr.model.derivation.WrenchSeries`: times s,
    #: force N, torque N m, world), where its recording has one: how late the program's own detectors
    #: fire on the demonstration (:func:`demo_detection_lag`)
    wrench: Any = None
    #: the track is a trembling hand's, smoothed (``dlovr.execution.engine.smoothed``): beyond a
    #: stretch the gripper goes on with the stretch's net motion, not with the hand's last 0.1 s
    by_hand: bool = False
    #: what the program's detectors were measured to do on this track's wrench, kept for the next runs
    #: that ask the same (``dlovr.execution.executor.demo_detection_lag``; made empty per track, a
    #: copy by ``dataclasses.replace`` included)
    lags: dict[tuple[Any, ...], tuple[Any, float | None]] = field(
        init=False, repr=False, compare=False, default_factory=dict)


def load_track(path: str | Path) -> DemoTrack:
    """The gripper trajectory a recording commanded (raises ``dlovr.recording.RecordingError``)."""
    from dlovr.recording import Recording

    rec = Recording(path)
    steps, pos, quat = rec.commands()
    end_force = free_force = None
    wrench = rec.wrench()
    if wrench is not None and len(wrench.t):
        t1 = float(wrench.t[-1])
        end_force = _mean3(wrench.window(t1 - GOAL_SENSE_S, t1))
        free_force = _mean3(wrench.window(*FREE_WINDOW_S))
    return DemoTrack(steps * rec.dt, pos, quat, end_force, free_force, wrench)


def _mean3(rows: np.ndarray) -> tuple[float, float, float] | None:
    """The mean of (k, 3) rows as a tuple; None without rows."""
    if len(rows) == 0:
        return None
    return cast(tuple[float, float, float], tuple(float(x) for x in np.asarray(rows, float).mean(axis=0)))
