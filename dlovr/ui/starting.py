"""The page of ``dlovr serve`` up at once: a viser server that says what it waits for (compiling the
simulation kernels on a fresh install, loading the scene) while the rest starts, then handed to
:class:`dlovr.ui.server.DemoServer`, which builds the real page in it.

This module imports viser and nothing of the simulation (see :mod:`dlovr.ui`'s lazy names), so the
URL is printed within a second or two of the command, not after the 30-40 s of a first compilation.
"""

from __future__ import annotations

import ipaddress
import time

import viser


class StartingServer:
    """A started viser server showing one line of what it waits for (:meth:`say`); :attr:`server` is
    given to :meth:`dlovr.ui.server.DemoServer.start`, which takes the line away."""

    def __init__(self, host: str = "127.0.0.1", port: int = 8080, *, verbose: bool = False) -> None:
        self.t0 = time.perf_counter()
        self.server = viser.ViserServer(host=host, port=port, verbose=verbose)
        self.server.gui.configure_theme(show_share_button=False, control_width="large")
        self.server.gui.main_panel.dock_right()
        self.server.scene.configure_environment_map(None)
        self.line = self.server.gui.add_markdown("**Starting...**")

    def say(self, text: str) -> None:
        """Show what the server waits for now (and how long it has waited)."""
        waited = time.perf_counter() - self.t0
        self.line.content = f"**Starting** ({waited:.0f} s): {text}. The page becomes usable when it is done."

    def done(self) -> None:
        """The real page is about to be built: take the line away."""
        self.line.remove()

    def stop(self) -> None:
        self.server.stop()


def exposure_warning(host: str, port: int) -> str | None:
    """The warning printed when ``host`` is not a loopback address (None for a loopback one)."""
    h = host.strip().strip("[]")
    if h.lower() == "localhost":
        return None
    try:
        if ipaddress.ip_address(h).is_loopback:
            return None
    except ValueError:
        pass  # a host name, or "" (every interface): treat as reachable from outside
    where = h or "every interface"
    return (
        f"dlovr serve: WARNING: listening on {where}, not on loopback: anyone who can reach port {port} "
        "can drive the simulation and write recordings on this machine (there is no authentication); "
        "use --host 127.0.0.1 unless that is what you want"
    )
