"""The GUI panels of ``dlovr serve``, top to bottom: the situation (:mod:`~dlovr.ui.panels.state`),
the gripper wrench plot (:mod:`~dlovr.ui.panels.forces`), recording controls
(:mod:`~dlovr.ui.panels.recording`), running a program (:mod:`~dlovr.ui.panels.run`), the scene's
transition network (:mod:`~dlovr.ui.panels.network`), the timeline
(:mod:`~dlovr.ui.panels.timeline`) and simulation controls (:mod:`~dlovr.ui.panels.simulation`).
Each panel builds its widgets in ``build(gui)`` and calls back into the :class:`dlovr.ui.app.App` it
was given (the server, as a panel may see it), never into the server's module."""

from dlovr.ui.panels.forces import ForcePanel
from dlovr.ui.panels.network import NetworkPanel
from dlovr.ui.panels.recording import RecordingPanel
from dlovr.ui.panels.run import RunPanel
from dlovr.ui.panels.simulation import JOG_ANGLE, JOG_STEP, SimulationPanel
from dlovr.ui.panels.state import StatePanel, status_markdown
from dlovr.ui.panels.timeline import TimelinePanel

__all__ = [
    "JOG_ANGLE",
    "JOG_STEP",
    "ForcePanel",
    "NetworkPanel",
    "RecordingPanel",
    "RunPanel",
    "SimulationPanel",
    "StatePanel",
    "TimelinePanel",
    "status_markdown",
]
