"""Moving the gripper target with the keyboard (no viser): which key moves along or turns about which
world axis, a press as one step and a held key as smooth motion at a set speed, and turns about a pivot
(the gripper, the cable's tip or the current contact: "turn about the tip", "turn about the edge").

The page reports the jog keys held down (:data:`JOG_KEYS`, as a string such as ``"JU"``) whenever that
set changes; :class:`HeldKeys` turns the reports into motion: a key just pressed moves one step at
once, and a key held longer than :data:`HOLD_DELAY` moves on at the set speed, every tick of the
server's publishing loop, until it is released.
"""

from __future__ import annotations

import math
from collections.abc import Iterable
from dataclasses import dataclass

import numpy as np

from dlovr.transforms import quat_mul, quat_rotate, quat_to_rotvec, rotvec_to_quat
from dlovr.ui.page_js import with_input

JOG_KEYS: dict[str, tuple[int, float]] = {
    "J": (0, -1.0), "L": (0, 1.0),  # x
    "I": (1, 1.0), "K": (1, -1.0),  # y
    "U": (2, 1.0), "O": (2, -1.0),  # z
    "T": (3, 1.0), "G": (3, -1.0),  # turn about x
    "Y": (4, 1.0), "H": (4, -1.0),  # turn about y
    "N": (5, 1.0), "M": (5, -1.0),  # turn about z (yaw)
}
"""Key -> (component, sign): components 0-2 move along world x, y, z; 3-5 turn about world x, y, z
through the pivot."""

KEY_HELP = (
    ("J / L", "x"), ("I / K", "y"), ("U / O", "z"), ("T / G", "turn about x"), ("Y / H", "turn about y"),
    ("N / M", "turn about z (yaw)"), ("R", "start / stop recording"), ("P", "pause / resume"),
    ("W/S, A/D, Q/E", "fly the camera (scaled to the scene)"), ("arrows", "turn the camera"),
)
"""The keys, as the page's help lists them."""

HOLD_DELAY = 0.3
"""Seconds a key is held before it moves on smoothly (a shorter press moves one step)."""

REPORT_TIMEOUT = 0.6
"""The page repeats its report every 0.2 s while keys are held; keys not reported for this long (s) are
let go (a lost release, a page that went away)."""

PIVOTS = ("gripper", "cable tip", "contact")
"""What a turn is about: the gripper itself, the cable's free end, or the middle of the current contacts
with the obstacles (the tip when there is none)."""


@dataclass(frozen=True)
class JogSettings:
    """A press moves ``step`` (m) or turns ``angle`` (rad); a held key moves at ``speed`` (m/s) or turns
    at ``turn`` (rad/s)."""

    step: float = 0.005
    angle: float = math.radians(5.0)
    speed: float = 0.05
    turn: float = math.radians(30.0)


def key_motion(keys: Iterable[str], linear: float, angular: float) -> tuple[np.ndarray, np.ndarray]:
    """The motion of ``keys`` together: (translation (m, world), rotation vector (rad, world)), each
    key moving ``linear`` or turning ``angular`` along its axis; unknown keys are ignored."""
    v = np.zeros(6)
    for k in set(keys):
        if k in JOG_KEYS:
            i, sign = JOG_KEYS[k]
            v[i] += sign * (linear if i < 3 else angular)
    return v[:3], v[3:]


def turn_about(pos: np.ndarray, quat: np.ndarray, rotvec: np.ndarray, pivot: np.ndarray | None) -> tuple[
    np.ndarray, np.ndarray
]:
    """The gripper pose (m, world; wxyz) turned by ``rotvec`` (rad, world axes) about ``pivot`` (m,
    world; None: the gripper's own position)."""
    if not np.any(rotvec):
        return np.asarray(pos, dtype=float), np.asarray(quat, dtype=float)
    r = rotvec_to_quat(rotvec)
    q = quat_mul(r, np.asarray(quat, dtype=float))
    p = np.asarray(pos, dtype=float)
    if pivot is not None:
        c = np.asarray(pivot, dtype=float)
        p = c + quat_rotate(r, p - c)
    return p, q / np.linalg.norm(q)


def gizmo_target(
    start_pos: np.ndarray, start_quat: np.ndarray, pos: np.ndarray, quat: np.ndarray, pivot: np.ndarray | None
) -> tuple[np.ndarray, np.ndarray]:
    """The gripper target (m, world; wxyz) for a gizmo dragged from ``start_pos``, ``start_quat`` to
    ``pos``, ``quat`` with turns about ``pivot`` (m, world, fixed at the drag's start; None: about the
    gripper, i.e. the gizmo's pose itself): the gizmo's turn since the drag's start is made about the
    pivot, its move added."""
    if pivot is None:
        return np.asarray(pos, dtype=float), np.asarray(quat, dtype=float)
    q0 = np.asarray(start_quat, dtype=float)
    conj = q0 * np.array([1.0, -1.0, -1.0, -1.0]) / float(q0 @ q0)
    rel = quat_mul(np.asarray(quat, dtype=float), conj)  # the turn since the start (world axes)
    p, q = turn_about(start_pos, q0, np.asarray(quat_to_rotvec(rel)), pivot)
    return p + (np.asarray(pos, dtype=float) - np.asarray(start_pos, dtype=float)), q


class HeldKeys:
    """The jog keys held down on the page. :meth:`report` takes what the page says is held (and the
    page's clock) and returns the keys just pressed (a step each) and, for the keys released, how many
    seconds of smooth motion to add (or take back, when negative); :meth:`tick` returns the keys held
    long enough to move on and the seconds since the last tick.

    The smooth motion follows the server's clock, tick by tick; a release corrects it to what the
    page's clock says the key was held (its press and release may reach a busy server late, or
    together), so that a tap moves exactly one step and a hold exactly ``speed * (held - HOLD_DELAY)``.
    """

    def __init__(self) -> None:
        self.down: dict[str, float] = {}  # key -> when it was pressed (time.perf_counter())
        self._page_down: dict[str, float] = {}  # key -> when it was pressed (s, the page's clock)
        self.applied: dict[str, float] = {}  # key -> seconds of smooth motion applied so far
        self._tick = 0.0
        self._seen = 0.0

    def report(self, held: str, now: float) -> tuple[list[str], dict[str, float]]:
        """``held``: ``"<keys>#<count>@<page ms>"`` (count and time optional)."""
        self._seen = now
        head, _, stamp = held.partition("@")
        keys = {k for k in head.partition("#")[0].upper() if k in JOG_KEYS}
        try:
            page_t = float(stamp) / 1000.0 if stamp else None
        except ValueError:
            page_t = None
        if page_t is not None and not math.isfinite(page_t):
            page_t = None  # a client's message is untrusted: no NaN or infinite time reaches the motion
        # a key let go for want of reports (a busy server or page) but still held is not pressed anew:
        # no second step, and its release is still measured from the page's first press
        pressed = sorted(keys - set(self.down) - set(self._page_down))
        fix: dict[str, float] = {}
        for k in (set(self.down) | set(self._page_down)) - keys:
            t0 = self._page_down.pop(k, None)
            if page_t is not None and t0 is not None:
                fix[k] = max(0.0, page_t - t0 - HOLD_DELAY) - self.applied.get(k, 0.0)
            self.applied.pop(k, None)
        for k in pressed:
            if page_t is not None:
                self._page_down[k] = page_t
        self.down = {k: self.down.get(k, now) for k in keys}
        return pressed, fix

    def clear(self) -> None:
        self.down, self._page_down, self.applied = {}, {}, {}

    @property
    def idle(self) -> bool:
        """No key held, none whose release is still to come."""
        return not self.down and not self._page_down

    def tick(self, now: float) -> tuple[list[str], float]:
        dt = min(max(now - self._tick, 0.0), 0.1) if self._tick else 0.0
        self._tick = now
        if self.down and now - self._seen > REPORT_TIMEOUT:
            self.down = {}  # stop; a late release still corrects the motion by the page's clock
        keys = [k for k, t in self.down.items() if now - t >= HOLD_DELAY]
        for k in keys:
            self.applied[k] = self.applied.get(k, 0.0) + dt
        return keys, dt


KEYS_JS = """(function(){if(window.__dlovrKeys)return;window.__dlovrKeys=1;var held={},n=0;POST
function send(t){post(Object.keys(held).sort().join('')+'#'+(n++)+'@'+(t||performance.now()).toFixed(1));}
function typing(e){var t=e.target;
return t&&(t.tagName==='INPUT'||t.tagName==='TEXTAREA'||t.isContentEditable);}
document.addEventListener('keydown',function(e){var k=(e.key||'').toUpperCase();
if(e.repeat||e.ctrlKey||e.metaKey||e.altKey||typing(e)||KEYS.indexOf(k)<0)return;held[k]=1;send(e.timeStamp);},
true);document.addEventListener('keyup',function(e){var k=(e.key||'').toUpperCase();
if(held[k]){delete held[k];send(e.timeStamp);}},true);
window.addEventListener('blur',function(){if(Object.keys(held).length){held={};send();}});
setInterval(function(){if(Object.keys(held).length)send();},200);})()"""
"""The page's key follower: sends the jog keys held (sorted, then ``#`` and a count that makes every
report a new value, then ``@`` and the page's clock in ms, e.g. ``"JU#7@5123.4"``: a key event's own
time stamp, when the key went down or up, not when a busy page got round to handling it) to the text
input ``UUID`` whenever they change and every 0.2 s while any is held; keys typed into an input and
key repeats are ignored; leaving the window lets go."""


def keys_js(uuid: str) -> str:
    """:data:`KEYS_JS` for the text input ``uuid`` (:func:`dlovr.ui.page_js.with_input`)."""
    return with_input(KEYS_JS.replace("KEYS", repr("".join(JOG_KEYS))), uuid)
