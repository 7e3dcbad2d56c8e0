"""The gripper wrench over time (no viser): a growing trace of samples and the arrays of the force plot.

The simulator records the force (N, world frame) that the holding constraints exert on the gripper,
as a wrist force sensor reads it (``StepRecord.gripper_force``); it records no torque, so the plot
shows the force only: its x, y, z components and its magnitude. Live, :class:`ForceTrace` keeps the
mean of every 10 steps (20 ms at the 2 ms step: 250 points over the 5 s the plot shows, about its
width in pixels, which keeps each update small). A recording stores the force in its contact-state
messages only, the moments the contact state changed; the UI re-simulates it for the rest
(:func:`dlovr.ui.timeline.resimulated_forces`).
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

WINDOW_S = 5.0
"""Seconds of history the plot shows."""

SERIES_LABELS = ("t [s]", "Fx", "Fy", "Fz", "|F|", "transition")
SERIES_COLORS = ("", "#d62728", "#2ca02c", "#1f77b4", "#222222", "#9467bd")
MARK_LOW, MARK_HIGH = -1.0, 2.0
"""Values of the transition series: off the bottom of its 0-1 scale between transitions, a vertical
line through the whole plot (off the top) at each transition."""


class ForceTrace:
    """Gripper force samples in time order: ``t`` (s) and ``f`` (N, world frame, (k, 3)).

    :meth:`add` takes one simulation step and stores the mean of every ``every`` steps; :meth:`append`
    stores a sample as it is. At ``capacity`` samples the older half is dropped.
    """

    def __init__(self, every: int = 10, capacity: int = 100_000) -> None:
        self.every = max(1, int(every))
        self.capacity = max(16, int(capacity))
        self._t = np.empty(self.capacity)
        self._f = np.empty((self.capacity, 3))
        self._n = 0
        self._acc = np.zeros(3)
        self._acc_n = 0

    def __len__(self) -> int:
        return self._n

    @property
    def t(self) -> np.ndarray:
        return self._t[: self._n]

    @property
    def f(self) -> np.ndarray:
        return self._f[: self._n]

    def add(self, t: float, force: Sequence[float] | np.ndarray) -> None:
        """One step's force; every ``every`` steps their mean is stored at the last step's time."""
        self._acc += force
        self._acc_n += 1
        if self._acc_n >= self.every:
            self.append(t, self._acc / self._acc_n)
            self._acc[:] = 0.0
            self._acc_n = 0

    def append(self, t: float, force: Sequence[float] | np.ndarray) -> None:
        if self._n and t < self._t[self._n - 1]:
            raise ValueError("force samples must come in time order")
        if self._n == self.capacity:
            keep = self.capacity // 2
            self._t[:keep] = self._t[self._n - keep : self._n]
            self._f[:keep] = self._f[self._n - keep : self._n]
            self._n = keep
        self._t[self._n] = t
        self._f[self._n] = force
        self._n += 1

    def window(self, t0: float, t1: float) -> tuple[np.ndarray, np.ndarray]:
        """Samples with ``t0 <= t <= t1`` (copies), plus the last one before ``t0`` when there is one
        (so that a sparse trace still draws a line into the window)."""
        t = self.t
        i = max(0, int(np.searchsorted(t, t0, side="left")) - 1)
        j = int(np.searchsorted(t, t1, side="right"))
        return t[i:j].copy(), self.f[i:j].copy()


def plot_arrays(
    trace: ForceTrace, marks: Sequence[float], t_end: float, window: float = WINDOW_S
) -> tuple[np.ndarray, ...]:
    """The force plot's data: x (s), Fx, Fy, Fz, |F| (N) over ``[t_end - window, t_end]``, and the
    transition series with a vertical line at each time of ``marks`` in the window.

    A sample before the window is moved to the window's edge with the value the drawn line has there
    (interpolated). Each mark adds three x samples at its time, with the forces interpolated there,
    on which the transition series goes up and down; elsewhere it stays off the plot. (uPlot draws
    nothing sensible through NaN values, so every x sample carries a force.)
    """
    t0 = t_end - window
    t, f = trace.window(t0, t_end)
    if len(t) and t[0] < t0:
        if len(t) >= 2:  # cut the line from the sample before the window at the window's edge
            w = (t0 - t[0]) / (t[1] - t[0]) if t[1] > t[0] else 1.0
            f[0] = f[0] + w * (f[1] - f[0])
            t[0] = t0
        else:
            t, f = t[1:], f[1:]
    ms = np.array(sorted(m for m in marks if t0 <= m <= t_end), dtype=float)
    if not len(t):
        if not len(ms):
            z = np.zeros(1)
            return (np.array([t_end]), z, z, z, z, np.full(1, MARK_LOW))
        t, f = ms[:1].copy(), np.zeros((1, 3))  # no force known: a flat zero line under the marks
    mark = np.full(len(t), MARK_LOW)
    if len(ms):
        fm = np.stack([np.interp(ms, t, f[:, k]) for k in range(3)], axis=1)
        x = np.concatenate([t, np.repeat(ms, 3)])
        f = np.concatenate([f, np.repeat(fm, 3, axis=0)])
        mark = np.concatenate([mark, np.tile([MARK_LOW, MARK_HIGH, MARK_LOW], len(ms))])
        order = np.argsort(x, kind="stable")  # a mark's three samples stay in their order
        t, f, mark = x[order], f[order], mark[order]
    mag = np.linalg.norm(f, axis=1)
    return (t, f[:, 0].copy(), f[:, 1].copy(), f[:, 2].copy(), mag, mark)


SIGNAL_LABELS = ("detector", "threshold")
SIGNAL_COLORS = ("#ff7f0e", "#ff7f0e")
SIGNAL_RANGE = (0.0, 1.25)
"""The detector signal's own scale: 0 to a little above 1, the threshold at which a detector fires."""


def signal_arrays(x: np.ndarray, trace: ForceTrace | None) -> tuple[np.ndarray, np.ndarray]:
    """The detector signal of a program run (the first component of ``trace``, dimensionless: 1 =
    fires) and its threshold line, at the plot's times ``x`` (s); off the plot where no run is."""
    off = np.full(len(x), MARK_LOW)
    if trace is None or not len(trace):
        return off, off.copy()
    t, s = trace.t, trace.f[:, 0]
    inside = (x >= t[0]) & (x <= t[-1])
    sig = np.where(inside, np.interp(x, t, s), MARK_LOW)
    return sig, np.where(inside, 1.0, MARK_LOW)


READOUT_JS = """(function(){if(window.__dlovrReadout)return;window.__dlovrReadout=1;
function last(u){return Math.max(0,u.data[0].length-1);}
function fmt(u,si,v,idx){if(idx==null){idx=last(u);v=u.data[si][idx];}if(v==null||!isFinite(v))return '-';
var l=u.series[si].label;if(si==0)return v.toFixed(2)+' s';
if(l==='transition')return v>=MARK?'here':'-';
if(l==='detector')return v<0?'off':v.toFixed(2);if(l==='threshold')return v<0?'-':v.toFixed(0);
return v.toFixed(3)+' N';}
function patch(u){if(u.__dlovr)return;u.__dlovr=1;u.series.forEach(function(s,i){
s.value=function(uu,v,si,idx){return fmt(uu,si,v,idx);};});
u.hooks.setData=(u.hooks.setData||[]).concat([function(uu){var t=performance.now();
if(uu.cursor.idx==null&&t-(uu.__dlovrAt||0)>=LEGEND_MS){uu.__dlovrAt=t;uu.setLegend({idx:null});}}]);
u.setLegend({idx:u.cursor.idx==null?null:u.cursor.idx});}
setInterval(function(){var tp=(window.__viserTestpoints||{}).uplots||{};
Object.keys(tp).forEach(function(k){try{patch(tp[k].chart);}catch(e){}});},300);})()"""
"""The force plot's read-out on the page: the legend under the plot shows the values at the hovered
time (``12.34 s``, forces in N to the mN, ``here`` on a transition's mark, the detector signal or
``off``) and, with the mouse off the plot, the latest sample's (redrawn every :data:`LEGEND_MS`),
instead of uPlot's ``--``. uPlot's
options cross to the page as JSON, which carries no formatting functions: the page installs them on
every chart (viser registers each uPlot chart in ``window.__viserTestpoints.uplots``), looking again
every 0.3 s for a chart drawn anew."""


LEGEND_MS = 500
"""How often the read-out of the latest values is redrawn with the mouse off the plot (ms): the page
has other work (a hovered read-out follows every update)."""


def readout_js() -> str:
    """:data:`READOUT_JS` with the transition mark's value and :data:`LEGEND_MS`."""
    return READOUT_JS.replace("MARK", repr(MARK_HIGH)).replace("LEGEND_MS", str(LEGEND_MS)).replace("\n", "")
