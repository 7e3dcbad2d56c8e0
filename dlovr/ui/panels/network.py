"""The network panel: the current scene's transition network (:mod:`dlovr.ui.network_view`) with
the live situation highlighted while demonstrating or running a program."""

from __future__ import annotations

from typing import Any

import viser

from dlovr.model.network import Network
from dlovr.ui.app import App
from dlovr.ui.network_view import network_view_html, scene_network
from dlovr.ui.panels.run import SAMPLE_PROGRAMS


class NetworkPanel:
    """The "Transition network" folder: loaded (or built) for each scene, re-drawn when the live node
    changes; "Rebuild network" takes in recordings made since."""

    def __init__(self, app: App) -> None:
        self.app = app
        self.net: Network | None = None
        self.note = ""
        self.live: str | None = None
        self._scene = ""
        self._shown: tuple[Any, ...] = ()

    def build(self, gui: viser.GuiApi) -> None:
        with gui.add_folder("Transition network", expand_by_default=True):
            self.rebuild_btn = gui.add_button("Rebuild network", icon=viser.Icon.REFRESH)
            self.view = gui.add_html("")

        @self.rebuild_btn.on_click
        def _(_e: Any) -> None:
            self.load()

        self.load()

    def folders(self) -> list[Any]:
        """Where networks and recordings of the scene are looked for: the recordings directory, then
        the repository's ``recordings/``."""
        return [self.app.recordings_dir, SAMPLE_PROGRAMS.parent]

    def load(self) -> Network | None:
        """Load (or build) the current scene's network."""
        self._scene = self.app.session.scene.name
        self.net, self.note = scene_network(self._scene, self.folders())
        self._shown = ()
        self.update()
        return self.net

    def live_node(self) -> tuple[str | None, str]:
        """The node of the tracker's current kept situation (None outside the network) and its notation."""
        with self.app.lock:
            kept = self.app.session.tracker.kept
            sit = kept[-1].situation if kept else self.app.session.state.discrete
        text = sit.format()
        return (self.net.locate(text) if self.net is not None else None), text

    def update(self) -> None:
        """Follow the scene and the live situation (the server calls this at ``PANEL_HZ``)."""
        if self.app.session.scene.name != self._scene:
            self.load()
            return
        if self.net is None:
            state: tuple[Any, ...] = (None, self.note)
            if state != self._shown and self.app.server is not None:
                self.view.content = f"<div style='font-size:11px'>{self.note}</div>"
            self._shown = state
            return
        self.live, text = self.live_node()
        state = (id(self.net), self.live, text)
        if state == self._shown or self.app.server is None:
            return
        self._shown = state
        self.view.content = network_view_html(self.net, self.live, text, self.note)
