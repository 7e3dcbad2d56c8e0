"""Browser teleoperation UI (``dlovr serve``): a viser server around a real-time simulation.

The only package of dlovr that imports viser. :class:`DemoServer` (:mod:`dlovr.ui.server`) runs the
simulation :class:`Session` (:mod:`dlovr.ui.session`) in a real-time thread (:mod:`dlovr.ui.loop`),
draws it (:mod:`dlovr.ui.viewport`, with the pure helpers of :mod:`dlovr.ui.drawing`) and builds the
GUI panels (:mod:`dlovr.ui.panels`), which see it through :class:`dlovr.ui.app.App` only;
:mod:`dlovr.ui.timeline` holds the scrubbable timeline, live or read from a recording.

The names below are imported on first use (PEP 562), so that :mod:`dlovr.ui.starting` (viser alone)
can put the page up at once, before the simulation and its kernels are imported.
"""

from __future__ import annotations

import importlib
from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:
    from dlovr.model.discrete import Stability
    from dlovr.ui.drawing import (
        COLOR_BY_CLASS,
        COLOR_FREE,
        contact_arrows,
        point_classes,
        point_colors,
        segment_transforms,
    )
    from dlovr.ui.panels import JOG_ANGLE, JOG_STEP, status_markdown
    from dlovr.ui.server import HEADLESS_CHROMIUM_ARGS, PUBLISH_HZ, DemoServer, free_port, serve
    from dlovr.ui.session import Session
    from dlovr.ui.timeline import BAND_COLORS, Band, Snapshot, Timeline, recording_timeline

_WHERE = {
    "Stability": "dlovr.model.discrete",
    "COLOR_BY_CLASS": "dlovr.ui.drawing",
    "COLOR_FREE": "dlovr.ui.drawing",
    "contact_arrows": "dlovr.ui.drawing",
    "point_classes": "dlovr.ui.drawing",
    "point_colors": "dlovr.ui.drawing",
    "segment_transforms": "dlovr.ui.drawing",
    "JOG_ANGLE": "dlovr.ui.panels",
    "JOG_STEP": "dlovr.ui.panels",
    "status_markdown": "dlovr.ui.panels",
    "HEADLESS_CHROMIUM_ARGS": "dlovr.ui.server",
    "PUBLISH_HZ": "dlovr.ui.server",
    "DemoServer": "dlovr.ui.server",
    "free_port": "dlovr.ui.server",
    "serve": "dlovr.ui.server",
    "Session": "dlovr.ui.session",
    "BAND_COLORS": "dlovr.ui.timeline",
    "Band": "dlovr.ui.timeline",
    "Snapshot": "dlovr.ui.timeline",
    "Timeline": "dlovr.ui.timeline",
    "recording_timeline": "dlovr.ui.timeline",
}


def __getattr__(name: str) -> Any:
    where = _WHERE.get(name)
    if where is None:
        raise AttributeError(f"module 'dlovr.ui' has no attribute {name!r}")
    value = getattr(importlib.import_module(where), name)
    globals()[name] = value
    return value


__all__ = [
    "BAND_COLORS",
    "COLOR_BY_CLASS",
    "COLOR_FREE",
    "HEADLESS_CHROMIUM_ARGS",
    "JOG_ANGLE",
    "JOG_STEP",
    "PUBLISH_HZ",
    "Band",
    "DemoServer",
    "Session",
    "Snapshot",
    "Stability",
    "Timeline",
    "contact_arrows",
    "free_port",
    "point_classes",
    "point_colors",
    "recording_timeline",
    "segment_transforms",
    "serve",
    "status_markdown",
]
