"""Browser teleoperation UI (``dlovr serve``): a viser server around a real-time simulation.

The only package of dlovr that imports viser. :class:`DemoServer` (:mod:`dlovr.ui.server`) runs the
simulation :class:`Session` (:mod:`dlovr.ui.session`) in a real-time thread (:mod:`dlovr.ui.loop`),
draws it (:mod:`dlovr.ui.viewport`, with the pure helpers of :mod:`dlovr.ui.drawing`) and builds the
GUI panels (:mod:`dlovr.ui.panels`), which see it through :class:`dlovr.ui.app.App` only;
:mod:`dlovr.ui.timeline` holds the scrubbable timeline, live or read from a recording.
"""

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
