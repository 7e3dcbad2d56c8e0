"""What the panels of ``dlovr serve`` see of the server: :class:`App`, a narrow interface (what a panel
may read and do), and :class:`View`, the timeline being viewed instead of the live simulation.

:class:`dlovr.ui.server.DemoServer` implements :class:`App`; the panels (:mod:`dlovr.ui.panels`) and
the viewport (:mod:`dlovr.ui.viewport`) are given it (and, where they need one, another panel or the
viewport itself) and never import the server. This module imports no other UI module but the session
and the timeline, so the UI's modules import each other without a circle.
"""

from __future__ import annotations

import threading
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any, Protocol

from dlovr.scene import Scene
from dlovr.ui.session import Session
from dlovr.ui.timeline import Snapshot, Timeline

if TYPE_CHECKING:
    import viser


@dataclass
class View:
    """The timeline shown instead of the live simulation: a recording, or the live timeline being
    scrubbed; ``timeline`` None is the live view. ``scene`` is the recording's scene (None: the live
    scene). Read and written under the server's session lock (:attr:`App.lock`)."""

    timeline: Timeline | None = None
    scene: Scene | None = None

    def clear(self) -> None:
        """Back to the live view."""
        self.timeline = None
        self.scene = None


class App(Protocol):
    """The server as a panel sees it: the session and its locks, the viser server (None until
    started: the commands work without the GUI), the viewed timeline, and the commands of the GUI.

    ``lock`` guards the session (the real-time thread steps under it); ``draw_lock`` guards drawing
    into the 3D scene (the live cable and a scrubbed moment must not interleave).
    """

    lock: threading.RLock
    draw_lock: threading.RLock
    recordings_dir: Path
    view: View
    last_recording: Path | None  # the last recording finished
    last_program: Any  # the last recording's compiled program (None: none, or compiling failed)
    program_text: str  # its listing

    @property
    def session(self) -> Session:
        """The current scene's simulation session (replaced by :meth:`load`)."""
        ...

    @property
    def server(self) -> viser.ViserServer | None:
        """The viser server (None: not started, or stopped)."""
        ...

    @property
    def paused(self) -> bool:
        """Whether the simulation is paused."""
        ...

    def set_target(self, pos: Any, quat: Any | None = None, *, move_gizmo: bool = True) -> None:
        """Command the gripper pose (m, world; quaternion wxyz; None: keep the orientation)."""
        ...

    def target(self) -> tuple[Any, Any]:
        """The gripper target last commanded (m, world; wxyz), else the simulator's."""
        ...

    def move_gizmo(self, pos: Any, quat: Any) -> None:
        """Put the gizmo at a pose (m, world; wxyz) without commanding it (a program's target)."""
        ...

    def jog(self, dx: float = 0.0, dy: float = 0.0, dz: float = 0.0, yaw: float = 0.0) -> None:
        """Move the gripper target by (dx, dy, dz) (m, world) and turn it by ``yaw`` (rad, about z)."""
        ...

    def hold(self) -> None:
        """Stop the gripper where it is now."""
        ...

    def pause(self, paused: bool = True) -> None: ...

    def reset(self) -> None:
        """Restart the current scene."""
        ...

    def load(self, scene: str | Path) -> None:
        """Switch to another scene (built-in name or path)."""
        ...

    def start_recording(self, path: str | Path | None = None) -> Path: ...

    def stop_recording(self, *, wait: bool = True) -> Path | None: ...

    def open_recording(self, path: str | Path) -> Timeline: ...

    def scrub(self, t: float) -> Snapshot | None: ...

    def live(self) -> None: ...
