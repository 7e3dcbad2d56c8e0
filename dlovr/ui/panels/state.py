"""The state panel: the markdown at the top of the GUI with the live contact situation (discrete and
topological), the last transition class, the forces and the simulation clock, or the timeline moment
being scrubbed."""

from __future__ import annotations

import math
from typing import TYPE_CHECKING

from dlovr.sim.tracker import ContactState

if TYPE_CHECKING:
    import viser


def status_markdown(
    state: ContactState | None,
    last_class: str,
    *,
    t: float,
    rtf: float,
    paused: bool,
    note: str = "",
    contact_force: float | None = None,
) -> str:
    """The situation panel's markdown. *Gripper wrench* is the force (N, world frame) the holding
    constraints exert on the gripper, as a wrist force sensor reads it (the simulator records no
    torque); *Contact normal force (sum)* is the sum over the cable's contacts of their normal
    forces (N), a different quantity (a cable lying still on a table carries its weight there while
    the gripper feels only the hanging part), given as ``contact_force`` averaged over the last 0.1 s
    (one step's value can flicker with the stiff contacts)."""
    if state is None:
        return "Situation: (starting)"
    fx, fy, fz = state.gripper_force
    run = "paused" if paused else f"running, {rtf:.2f}x real time"
    lines = [
        f"**Discrete:** `{state.discrete.format()}`",
        f"**Topological:** `{state.topological.format()}`",
        f"**Last transition:** `{last_class or '-'}`",
        f"**Gripper wrench:** |F| {math.hypot(fx, fy, fz):.2f} N ({fx:+.2f}, {fy:+.2f}, {fz:+.2f})",
        f"**Contact normal force (sum):** {_contact(state, contact_force)}",
        f"t = {t:.2f} s, {run}",
    ]
    if note:
        lines.append(f"**{note}**")
    return "\n\n".join(lines)


def _contact(state: ContactState, mean: float | None) -> str:
    """The contact normal force: the mean over the last 0.1 s where given (a step's own value can
    flicker with the stiff contacts), else the step's."""
    if mean is None:
        return f"{sum(state.forces):.2f} N"
    if all(c.state.stability_class is None for c in state.discrete.contacts):  # free and gripper only
        return f"{mean:.2f} N (no contact)"
    return f"{mean:.2f} N (mean of 0.1 s)"


class StatePanel:
    """The situation markdown; :meth:`show_live` skips a text already shown live."""

    def __init__(self) -> None:
        self._last_text = ""

    def build(self, gui: viser.GuiApi) -> None:
        self.markdown = gui.add_markdown("Situation: (starting)")

    def show_live(self, text: str) -> None:
        """Show the live status (a :func:`status_markdown` text) unless it is the last one shown live."""
        if text != self._last_text:
            self.markdown.content = text
            self._last_text = text

    def show(self, text: str) -> None:
        """Show another text (a timeline moment)."""
        self.markdown.content = text
