"""The status line at the top of the panel: what a demonstrator must see at a glance: a recording in
progress (red dot and elapsed time, also in the page's title), a recording being viewed instead of the
live simulation, a program running (manual control locked), a force that may break the cable, and
what the server is still waiting for at start."""

from __future__ import annotations

import time
from dataclasses import dataclass
from html import escape
from typing import TYPE_CHECKING

import numpy as np

from dlovr.ui.page_js import on_drawn

if TYPE_CHECKING:
    import viser

    from dlovr.ui.app import App
    from dlovr.ui.panels.run import RunPanel

FORCE_WARN_WEIGHTS = 10.0
"""The gripper wrench (in cable weights) above which the status warns: pushing the tip into an obstacle
built up 30 weights (7 N) before the table cable snapped through, with no warning."""

REC_COLOR = "#d62728"

KEYS_LINE = (
    "Keys: <b>J/L</b> x, <b>I/K</b> y, <b>U/O</b> z, <b>T/G Y/H N/M</b> turn, <b>R</b> record, "
    "<b>P</b> pause (hold to move; step, speed and pivot: the folder Gripper, keys and view)"
)


@dataclass(frozen=True)
class Status:
    """What the status line says; every field optional (empty: nothing to say)."""

    recording: str = ""  # the file being written
    elapsed: float = 0.0  # s since the recording started
    viewing: str = ""  # the recording (or "live timeline") being viewed
    running: str = ""  # the program running
    force: float = 0.0  # |gripper wrench| (N)
    weight: float = 0.0  # the cable's weight (N)
    waiting: str = ""  # what the server still waits for


def status_html(s: Status) -> str:
    """The status line (HTML); ``data-*`` attributes name what it shows, for tests."""
    parts = []
    if s.waiting:
        parts.append(f'<div data-waiting="1" style="color:#555">&#8987; {escape(s.waiting)}</div>')
    if s.recording:
        m, sec = divmod(int(s.elapsed), 60)
        parts.append(
            f'<div data-recording="1"><span style="display:inline-block;width:10px;height:10px;'
            f'border-radius:50%;background:{REC_COLOR}"></span> <b style="color:{REC_COLOR}">REC '
            f"{m}:{sec:02d}</b> <code>{escape(s.recording)}</code></div>"
        )
    if s.viewing:
        parts.append(
            f'<div data-viewing="1" style="background:#e8f0fe;padding:2px 4px"><b>Viewing recording</b> '
            f"{escape(s.viewing)}: the live simulation runs unseen (<i>Back to live</i> in Timeline)</div>"
        )
    if s.running:
        parts.append(
            f'<div data-running="1" style="background:#fff4d6;padding:2px 4px"><b>Program running</b> '
            f"{escape(s.running)}: manual control locked (gizmo and keys); <i>Stop run</i> to take over</div>"
        )
    if s.weight > 0 and s.force > FORCE_WARN_WEIGHTS * s.weight:
        parts.append(
            f'<div data-force-warning="1" style="color:{REC_COLOR}"><b>&#9888; High force</b>: '
            f"{s.force:.1f} N, {s.force / s.weight:.0f}x the cable's weight: the cable may snap "
            "through the obstacle; back off</div>"
        )
    if not parts:
        parts.append('<div style="color:#555">not recording</div>')
    parts.append(f'<div class="dlovr-keys-line" style="color:#555;font-size:11px">{KEYS_LINE}</div>')
    return f'<div class="dlovr-status" style="font-size:12px">{"".join(parts)}</div>'


def current_status(app: App, run: RunPanel, rec_started: float) -> Status:
    """What the status line says now: ``run`` is the run panel, ``rec_started`` when the recording in
    progress started (``time.monotonic()``)."""
    with app.lock:
        s = app.session
        rec = s.recorder.path.name if s.recorder is not None else ""
        force = float(np.linalg.norm(s.state.gripper_force)) if s.state is not None else 0.0
        weight = float(s.scene.dlo.mass) * 9.81
        prog = run.program
        running = prog.name if run.runner is not None and prog is not None else ""
        tl = app.view.timeline
        viewing = tl.source if tl is not None and app.view.scene is not None else ""
    elapsed = time.monotonic() - rec_started if rec else 0.0
    return Status(rec, elapsed, viewing, running, force, weight)


def page_title(s: Status) -> str:
    """The browser tab's title: a red dot and the elapsed time while recording."""
    if s.recording:
        m, sec = divmod(int(s.elapsed), 60)
        return f"\N{LARGE RED CIRCLE} REC {m}:{sec:02d} - dlovr"
    return "dlovr"


class StatusPanel:
    """The status line; :meth:`show` skips a status already shown."""

    def __init__(self) -> None:
        self.status = Status(waiting="starting")
        self._shown: tuple[str, str] = ("", "")
        self.script = ""  # more code the page runs as the line is drawn (the key follower)
        self.camera_speed = 0.3  # the camera keys' speed for the scene shown (m/s, framing.CAMERA_KEYS_JS)

    def build(self, gui: viser.GuiApi) -> None:
        self.html = gui.add_html(status_html(self.status))

    def build_legend(self, gui: viser.GuiApi) -> None:
        """The folded *Legend* (:func:`legend_html`)."""
        with gui.add_folder("Legend", expand_by_default=False):
            gui.add_html(legend_html())

    def show(self, status: Status) -> None:
        self.status = status
        text, title = status_html(status), page_title(status)
        speed = f"window.__dlovrCamSpeed={self.camera_speed:.4g};"
        if (text, title + speed) == self._shown:
            return
        self._shown = (text, title + speed)
        # the title is set, and the key followers installed, by the page itself as the line is drawn
        # (page_js.on_drawn)
        self.html.content = text + on_drawn(f"document.title={title!r};{speed}{self.script}")


def _swatch(rgb: tuple[int, int, int] | str, shape: str = "border-radius:2px") -> str:
    color = rgb if isinstance(rgb, str) else "rgb({},{},{})".format(*rgb)
    return (f'<span style="display:inline-block;width:11px;height:11px;{shape};background:{color};'
            'vertical-align:middle;border:1px solid #0003"></span>')


def legend_html() -> str:
    """What the notation, the class letters and every colour of the page mean."""
    from dlovr.model.discrete import Stability
    from dlovr.model.transitions import CLASS_NAMES
    from dlovr.ui.drawing import COLOR_BY_CLASS, COLOR_FREE, FACE_COLOR_BY_CLASS
    from dlovr.ui.program_view import RISK_COLORS, RISK_SYMBOLS

    words = {Stability.STABLE: "stable", Stability.SEMI: "semi-stable", Stability.INSTABLE: "instable"}
    cable = " ".join(f"{_swatch(COLOR_BY_CLASS[c])} {w}" for c, w in words.items())
    faces = " ".join(f"{_swatch(FACE_COLOR_BY_CLASS[c])} {w}" for c, w in words.items())
    classes = "".join(f"<li><b>{k}</b> {v}</li>" for k, v in CLASS_NAMES.items())
    risks = " ".join(
        f'<span style="color:{RISK_COLORS[r]}">{RISK_SYMBOLS[r]}</span> {r}' for r in RISK_COLORS
    )
    return (
        '<div class="dlovr-legend" style="font-size:11px;line-height:1.5">'
        "<b>Situation</b> <code>V/G &amp; E/N &amp; V/F[table.F1]</code>: the cable's contacts from the "
        "gripper to the tip, joined by <code>&amp;</code> (<code>+</code>: one stretch touching two "
        "things). Each is <i>cable part</i>/<i>what it touches</i>: <b>V</b> a tip (vertex), <b>E</b> a "
        "stretch (edge) of the cable; <b>G</b> the gripper, <b>N</b> nothing (free), <b>F</b> a face, "
        "<b>E^P</b> across an edge at a point, <b>E^L</b> along an edge, <b>V</b> a corner; the last "
        "letter <b>S</b> / <b>T</b> / <b>I</b> is stable / semi-stable / instable; the faces touched "
        "in brackets. <i>Discrete</i> is this per contact kind; <i>topological</i> names the cable "
        "points (<code>E9</code>) as well.<br>"
        f"<b>Transition classes</b><ul style='margin:0;padding-left:14px'>{classes}</ul>"
        f"<b>Cable</b>: {_swatch(COLOR_FREE)} free {cable}; blue arrows: contact vectors.<br>"
        f"<b>Faces touched</b> (lighter): {faces}.<br>"
        f"<b>Program risk</b>: {risks} (caution: a T, risky: an I or S transition).<br>"
        "<b>Timeline</b>: each contact situation has its own colour (no meaning beyond telling them "
        "apart); a black edge: a transition, with its class.<br>"
        "<b>Force plot</b>: x, y, z and |F| of the gripper wrench; dashed: transitions; orange: a "
        "running program's detector (fires at 1).</div>"
    )
