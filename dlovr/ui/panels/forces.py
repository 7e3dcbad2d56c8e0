"""The force panel: a uPlot chart of the gripper wrench over the last seconds (what the detection
algorithms of a program's macros watch), transitions marked, live or at a timeline moment; while a
program runs (:mod:`dlovr.ui.panels.run`), its current macro's detector signal and threshold."""

from __future__ import annotations

from typing import TYPE_CHECKING, Any

import numpy as np

from dlovr.model.transitions import format_classes
from dlovr.ui.app import App
from dlovr.ui.forces import (
    SERIES_COLORS,
    SERIES_LABELS,
    SIGNAL_COLORS,
    SIGNAL_LABELS,
    SIGNAL_RANGE,
    WINDOW_S,
    ForceTrace,
    plot_arrays,
    readout_js,
    signal_arrays,
)
from dlovr.ui.page_js import on_drawn
from dlovr.ui.panels.run import RunPanel
from dlovr.ui.timeline import Timeline

if TYPE_CHECKING:
    import viser
    from viser import uplot


READOUT_CSS = ".uplot .u-legend .u-value{display:inline-block;min-width:9ch;white-space:nowrap}"
"""The read-out's values keep their width as they change: the panel below the plot (the timeline)
does not move under the mouse."""


def _series(points: bool) -> tuple[uplot.Series, ...]:
    out: list[uplot.Series] = [{"label": SERIES_LABELS[0]}]
    for label, color in zip(SERIES_LABELS[1:], SERIES_COLORS[1:], strict=True):
        s: uplot.Series = {"label": label, "stroke": color, "width": 2.0 if label == "|F|" else 1.25}
        if label == "transition":
            s.update(scale="mark", width=1.0, dash=(4.0, 3.0), points={"show": False})
        elif points:  # a recording: samples only where the contact state changed
            s["points"] = {"show": True, "size": 4.0}
        else:
            s["points"] = {"show": False}
        out.append(s)
    for label, color in zip(SIGNAL_LABELS, SIGNAL_COLORS, strict=True):
        dash = (2.0, 2.0) if label == "threshold" else None
        sig: uplot.Series = {"label": label, "stroke": color, "scale": "signal", "width": 1.5}
        sig["points"] = {"show": False}
        if dash:
            sig["dash"] = dash
        out.append(sig)
    return tuple(out)


def _with_signal(data: tuple[np.ndarray, ...], trace: ForceTrace | None) -> tuple[np.ndarray, ...]:
    return (*data, *signal_arrays(data[0], trace))


class ForcePanel:
    """The "Gripper wrench" folder: the plot and a line naming the transitions it marks; ``run`` is
    the run panel, whose program's detector signal the plot shows."""

    def __init__(self, app: App, run: RunPanel) -> None:
        self.app = app
        self.run = run
        self._mode = "live"
        self._caption = ""
        self.updates = 0

    def build(self, gui: viser.GuiApi) -> None:
        s = self.app.session
        with gui.add_folder("Gripper wrench"):
            self.plot = gui.add_uplot(
                data=_with_signal(plot_arrays(s.forces, [], s.record.time), None),
                series=_series(points=False),
                title=f"force on the gripper [N], last {WINDOW_S:g} s",
                scales={
                    "x": {"time": False},
                    "y": {"auto": True},
                    "mark": {"auto": False, "range": (0.0, 1.0)},
                    "signal": {"auto": False, "range": SIGNAL_RANGE},
                },
                axes=({"label": "t [s]"}, {"scale": "y"}, {"scale": "signal", "side": 1, "size": 34}),
                legend={"show": True, "live": True},
                height=190,
            )
            self.caption = gui.add_markdown("")
            # the legend's read-out (forces.READOUT_JS)
            gui.add_html(f"<style>{READOUT_CSS}</style>{on_drawn(readout_js())}")

    def show_live(self) -> None:
        """The last seconds of the live simulation (the server calls this at ``PANEL_HZ``)."""
        app = self.app
        with app.lock:
            s = app.session
            tl = s.timeline
            data = plot_arrays(s.forces, tl.transition_times(), s.record.time)
            data = _with_signal(data, self.signal_trace())
            bands = [b for b in tl.bands[-12:] if b.classes]
        extra = self.run.signal_caption()
        self._show(data, bands, "live", f"force on the gripper [N], last {WINDOW_S:g} s", extra)

    def signal_trace(self) -> ForceTrace | None:
        """The detector signal of the program run in the current scene, if any."""
        return self.run.signals

    def show_at(self, tl: Timeline, t: float) -> None:
        """The seconds before moment ``t`` of a timeline being scrubbed (a recording, or the live one)."""
        data = _with_signal(plot_arrays(tl.forces, tl.transition_times(), t), None)
        bands = [b for b in tl.bands if b.classes and b.start <= t]
        live = tl is self.app.session.timeline
        # the moment goes under the plot: a new title would make the page draw the chart anew (and
        # lose the mouse's read-out) at every step of a scrub or a playback
        title = f"force on the gripper [N], {WINDOW_S:g} s up to the moment"
        if tl.forces_note:
            title += f" ({tl.forces_note})"
        dense = live or tl.forces.every > 1  # a step-rate trace, not samples at state changes
        self._show(data, bands, "live" if dense else "recording", title, f"up to {t:.2f} s")

    def _show(
        self, data: tuple[np.ndarray, ...], bands: list[Any], mode: str, title: str, extra: str = ""
    ) -> None:
        if not hasattr(self, "plot"):
            return
        t0 = float(data[0][-1]) - WINDOW_S
        marks = [f"{b.start:.2f} s **{format_classes(b.classes)}**" for b in bands if b.start >= t0]
        caption = "transitions (dashed): " + ", ".join(marks[-6:]) if marks else "no transition in the window"
        if extra:
            caption += "  \n" + extra
        assert self.app.server is not None, "the plot exists: the server is started"
        with self.app.server.atomic():
            if mode != self._mode:
                self.plot.series = _series(points=mode == "recording")
                self._mode = mode
            if self.plot.title != title:
                self.plot.title = title
            self.plot.data = data
            if caption != self._caption:
                self.caption.content = caption
                self._caption = caption
        self.updates += 1
