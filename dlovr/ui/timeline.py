"""The timeline (no viser): kept contact situations as coloured bands, and cable snapshots to scrub
through, either live (filled by :class:`dlovr.ui.session.Session`) or read from a recording file."""

from __future__ import annotations

import html
import threading
from collections import deque
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from dlovr.model.discrete import Stability
from dlovr.model.transitions import format_classes, kept_classes
from dlovr.recording import Recording, kept_states
from dlovr.scene import Scene
from dlovr.ui.drawing import point_colors, situation_faces
from dlovr.ui.forces import ForceTrace
from dlovr.ui.page_js import is_widget_id, with_input

BAND_COLORS = ("#4e79a7", "#a0cbe8", "#b07aa1", "#9c755f", "#76b7b2", "#d4a6c8", "#bab0ac", "#6b6ecf")
"""The situations' colours on the timeline: categorical, and none green, yellow or red (those are the
stability classes')."""


MIN_BAND_PX = 6
"""The narrowest a band is drawn (px), so that a short situation can still be hovered and clicked."""


def axis_end(t: float) -> float:
    """The end (s) of the live timeline's time axis at time ``t``: the next of 10, 20, 30, 60, 120, ...
    s with a quarter of the span left free. The axis changes scale only when time reaches it, so the
    bands under the mouse stay where they are while the timeline grows."""
    for step in (10.0, 20.0, 30.0, 60.0, 120.0, 180.0, 300.0, 600.0, 900.0, 1800.0, 3600.0):
        if t <= 0.75 * step:
            return step
    return 3600.0 * (int(t / 2700.0) + 1)


@dataclass
class Snapshot:
    """The cable at one moment (for the timeline): time, points, point colours, situation text."""

    t: float
    points: np.ndarray
    colors: np.ndarray
    gripper_pos: np.ndarray
    gripper_quat: np.ndarray
    text: str
    faces: dict[str, Stability] = field(default_factory=dict)  # faces touched, by stability class


@dataclass
class Band:
    """One kept contact situation on the timeline."""

    start: float
    end: float
    situation: str
    classes: tuple[str, ...]
    faces: dict[str, Stability] = field(default_factory=dict)  # faces touched, by stability class


@dataclass
class Timeline:
    """Kept situations as bands plus cable snapshots (one per kept situation and a few per second)."""

    bands: list[Band] = field(default_factory=list)
    snapshots: deque = field(default_factory=lambda: deque(maxlen=20000))
    source: str = "live"
    forces: ForceTrace = field(default_factory=ForceTrace)
    forces_note: str = ""  # where the forces come from, when not from the live simulation

    def transition_times(self) -> list[float]:
        """Start times (s) of the kept situations entered by a classified transition."""
        return [b.start for b in self.bands if b.classes]

    @property
    def end(self) -> float:
        t = [b.end for b in self.bands]
        if self.snapshots:
            t.append(self.snapshots[-1].t)
        return max(t, default=0.0)

    @property
    def start(self) -> float:
        t = [b.start for b in self.bands]
        if self.snapshots:
            t.append(self.snapshots[0].t)
        return min(t, default=0.0)

    def at(self, t: float) -> Snapshot | None:
        if not self.snapshots:
            return None
        ts = np.fromiter((s.t for s in self.snapshots), dtype=float, count=len(self.snapshots))
        i = int(np.searchsorted(ts, t, side="right")) - 1
        return self.snapshots[max(0, i)]

    def band_at(self, t: float) -> Band | None:
        for b in self.bands:
            if b.start <= t < b.end:
                return b
        return self.bands[-1] if self.bands and t >= self.bands[-1].start else None

    def html(
        self,
        pick_uuid: str | None = None,
        axis_end: float | None = None,
        window: tuple[float, float] | None = None,
    ) -> str:
        """Coloured bands, one per kept situation, transitions marked with their classes, and a list
        of the last situations.

        With ``pick_uuid`` (a text input of the page), hovering a band or a row sends ``h<i>:<n>`` to
        that input, leaving it sends ``:<n>`` (``<n>``: a count of reports, :data:`PICK_JS`), and
        clicking sends ``c<i>:<ms>`` (``i``: the index of the situation in :attr:`bands`); the server
        highlights its faces or scrubs to it. ``axis_end`` (s) ends the axis after the last band (the
        live timeline's room to grow); ``window`` (s, a zoomed view) draws only the bands within it,
        cut at its ends, each in its own colour still.
        """
        t0, t1 = self.start, self.end
        lo, hi = window if window is not None else (t0, t1 if axis_end is None else max(axis_end, t1))
        span = max(hi - lo, 1e-9)
        colors: dict[str, str] = {}
        cells = []
        drawn = lo  # the bar is drawn up to this time
        for i, b in enumerate(self.bands):
            c = colors.setdefault(b.situation, BAND_COLORS[len(colors) % len(BAND_COLORS)])
            start, end = b.start, b.end
            if window is not None:
                if b.end < lo or b.start > hi:
                    continue
                start, end = max(b.start, lo), min(b.end, hi)
                if start > drawn + 1e-9:  # a gap before it (the window starts before the first band)
                    cells.append(f'<div style="width:{100.0 * (start - drawn) / span:.2f}%"></div>')
            drawn = end
            w = 100.0 * (end - start) / span
            label = format_classes(b.classes) if b.classes else ""
            tip = html.escape(f"{b.start:.2f}-{b.end:.2f} s  {label}  {b.situation}")
            border = "border-left:2px solid #000;" if b.classes and start == b.start else ""
            cells.append(
                f'<div title="{tip}" data-situation="{i}" '
                f'style="width:{w:.2f}%;min-width:{MIN_BAND_PX}px;background:{c};{border}'
                'cursor:pointer"></div>'
            )
        bar = (
            '<div class="dlovr-timeline" style="display:flex;height:14px;width:100%;'
            f'background:#ddd;overflow:hidden;border-radius:3px">{"".join(cells)}</div>'
        )
        first = max(0, len(self.bands) - 8)
        rows = "".join(
            f'<li data-situation="{first + k}" style="cursor:pointer">'
            f"{b.start:.2f} s <b>{html.escape(format_classes(b.classes) if b.classes else '')}</b> "
            f"<code>{html.escape(b.situation)}</code></li>"
            for k, b in enumerate(self.bands[first:])
        )
        src = html.escape(self.source)
        shown = f", zoomed to {lo:.2f}-{hi:.2f} s" if window is not None else ""
        return (
            f'<div class="dlovr-pick"{_pick_handlers(pick_uuid)} style="font-size:11px">{bar}'
            f"<div>{src}: {len(self.bands)} situations, {t0:.2f}-{t1:.2f} s{shown}</div>"
            f"<ul style='margin:2px 0;padding-left:14px'>{rows}</ul></div>"
        )


ZOOM_MIN_S = 0.2
"""The narrowest zoomed window of the timeline (s)."""


def zoom_window(
    window: tuple[float, float] | None, full: tuple[float, float], at: float, factor: float
) -> tuple[float, float] | None:
    """The timeline's window (s) after zooming by ``factor`` (< 1: in) about the moment ``at`` (s),
    inside ``full`` (the whole timeline); None when it covers the whole timeline again. The moment
    keeps its place in the window (as a mouse-wheel zoom keeps the point under the mouse)."""
    lo, hi = window if window is not None else full
    span = max(hi - lo, 1e-9)
    at = min(max(at, lo), hi)
    width = max(span * factor, ZOOM_MIN_S)
    if width >= full[1] - full[0]:
        return None
    frac = (at - lo) / span
    return _inside(at - frac * width, width, full)


def pan_window(window: tuple[float, float] | None, full: tuple[float, float], by: float) -> tuple[
    float, float
] | None:
    """The window moved by ``by`` of its width (-0.5: half a window earlier), kept inside ``full``."""
    if window is None:
        return None
    width = window[1] - window[0]
    return _inside(window[0] + by * width, width, full)


def window_showing(window: tuple[float, float] | None, full: tuple[float, float], t: float) -> tuple[
    float, float
] | None:
    """The window, moved on (or back) to show the moment ``t`` (s) when it is outside (a playback
    reaching the window's end turns the page)."""
    if window is None or window[0] <= t <= window[1]:
        return window
    width = window[1] - window[0]
    return _inside(t if t > window[1] else t - width, width, full)


def _inside(lo: float, width: float, full: tuple[float, float]) -> tuple[float, float]:
    lo = min(max(lo, full[0]), full[1] - width)
    return (lo, lo + width)


def step_time(tl: Timeline, t: float, direction: int) -> float:
    """The time (s) of the next (``direction`` 1) or the previous (-1) cable snapshot of ``tl`` after
    or before ``t`` (a recording's frame); ``t`` itself when there is none."""
    ts = [s.t for s in tl.snapshots]
    if direction > 0:
        later = [x for x in ts if x > t + 1e-6]
        return min(later, default=t)
    earlier = [x for x in ts if x < t - 1e-6]
    return max(earlier, default=t)


PICK_JS = """(window.__dlovrPick||(window.__dlovrPick=(function(){var xy=null,hover='',timer=0,n=0;POST
function at(){var el=xy&&document.elementFromPoint(xy[0],xy[1]);
var t=el&&el.closest&&el.closest('.dlovr-pick [data-situation]');return t?'h'+t.dataset.situation:'';}
function send(s){hover=s;n+=1;post(s+':'+n);}
function decide(){timer=0;var s=at();if(s!==hover)send(s);}
var pick=function(e){if(e&&e.clientX!==undefined)xy=[e.clientX,e.clientY];
if(e&&e.type==='click'){var c=at();if(c)post('c'+c.slice(1)+':'+Date.now());return;}
var away=timer!==0;clearTimeout(timer);timer=0;var s=at();
if(s){if(s!==hover||away)send(s);}else timer=setTimeout(decide,LEAVE_MS);};
document.addEventListener('mousemove',pick,true);
document.documentElement.addEventListener('mouseleave',function(){xy=null;pick(null);});
return pick;})()))"""
"""The page's hover follower for the timeline (installed once, by the first ``mouseover``): the
situation under the mouse is looked up at the mouse's place (``document.elementFromPoint``), so a
band replaced under a still mouse (the live timeline is drawn again every second) is still the band
hovered. Entering a band is sent at once as ``h<i>:<n>`` to the text input ``UUID``; being over no
band is sent as ``:<n>`` only once it has lasted :data:`LEAVE_MS` (a redraw's moment without bands
is not a leave); a click sends ``c<i>:<ms>``. ``<n>`` counts the reports, so that each one is a new
value of the input (the server hears only changes): a band entered again after a moment off it is
reported again, and a report lost on the way (the page reconnecting) is mended by the next entry."""

LEAVE_MS = 150
"""How long the mouse must be over no band before the timeline counts as left (ms)."""


def _pick_handlers(uuid: str | None) -> str:
    """Inline mouse handlers of the timeline's outer element, which install :data:`PICK_JS` for the
    text input ``uuid`` (it reaches the server as a ``GuiUpdateMessage``, as an input edit does).
    One copy of the code for the whole timeline (event delegation)."""
    if uuid is None or not is_widget_id(uuid):
        return ""
    pick = with_input(PICK_JS.replace("LEAVE_MS", str(LEAVE_MS)), uuid)
    return f' onmouseover="{pick}(event)" onmouseleave="{pick}(event)" onclick="{pick}(event)"'


def recording_timeline(path: str | Path) -> tuple[Timeline, Scene, Any]:
    """Timeline of a recording file (bands from its debounced contact states, cable from its
    Foxglove frames), its embedded scene (loaded from a temporary directory, which the scene's meshes
    are read from later and which is removed when the process exits) and the Recording."""
    import atexit
    import shutil
    import tempfile

    from dlovr.recording import load_embedded_scene, situation_from_payload

    rec = Recording(path)
    tmp = tempfile.mkdtemp(prefix="dlovr-ui-")
    atexit.register(shutil.rmtree, tmp, ignore_errors=True)
    scene = load_embedded_scene(rec, tmp)
    kept = kept_states(rec)
    tl = Timeline(source=Path(path).name)
    for k, into in zip(kept, kept_classes(kept), strict=True):  # flights included
        tl.bands.append(
            Band(k.t, k.t + k.duration, k.situation.format(), tuple(into), situation_faces(k.situation))
        )
    states = rec.states()
    st_t = np.array([float(p["t"]) for p in states])
    tl.forces = ForceTrace(every=1)  # the gripper force where the contact state changed
    tl.forces_note = "samples at contact-state changes"
    for p, t in zip(states, st_t, strict=True):
        gf = p.get("gripper_force")
        if gf is not None and len(gf) == 3 and (not len(tl.forces) or t >= tl.forces.t[-1]):
            tl.forces.append(float(t), np.asarray(gf, dtype=float))
    for t, pts, gp, gq in rec.frames():
        j = max(0, int(np.searchsorted(st_t, t + 1e-9, side="right")) - 1)
        payload = states[j] if states else None
        classes: list[Stability | None] = [None] * len(pts)
        text = ""
        faces: dict[str, Stability] = {}
        if payload is not None:
            sit = situation_from_payload(payload)
            text = payload.get("discrete", "")
            faces = situation_faces(sit)
            for c, m_c in zip(sit.contacts, payload.get("contacts", []), strict=False):
                span, cls = m_c.get("span"), c.state.stability_class
                if span and cls is not None:
                    for i in range(max(0, span[0]), min(len(pts) - 1, span[1]) + 1):
                        classes[i] = cls
        tl.snapshots.append(Snapshot(t, pts, point_colors(classes), gp, gq, text, faces))
    return tl, scene, rec


def resimulated_forces(rec: Any, scene: Scene, stop: threading.Event | None = None) -> ForceTrace | None:
    """The gripper force of a recording at every step (mean of 10 steps, as live), by re-simulating it
    from its first checkpoint and its command stream, as ``dlovr replay`` does (bit for bit the
    recorded run with the same MuJoCo version); None when ``stop`` was set meanwhile.

    ``rec`` is the :class:`dlovr.recording.Recording`, ``scene`` its embedded scene.
    """
    from dlovr.sim import SimState, Simulator

    steps, pos, quat = rec.commands()
    first = rec.checkpoints()[0]
    sim = Simulator(scene, pieces=rec.pieces, track=False)  # the contacts are not needed here
    sim.set_state(SimState(first.state, first.step, first.target_pos, first.target_quat))
    trace = ForceTrace()
    r = sim.record()
    trace.append(r.time, r.gripper_force)
    for i in range(len(steps)):
        if stop is not None and i % 100 == 0 and stop.is_set():
            return None
        sim.target_pos, sim.target_quat = pos[i].copy(), quat[i].copy()
        r = sim.step()
        trace.add(r.time, r.gripper_force)
    return trace
