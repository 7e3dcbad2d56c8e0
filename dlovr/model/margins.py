"""How far a demonstration went on past a transition that no force shows: the margin a program has there.

A macro whose demonstrated transition shows no force signal (every detection of it
:func:`dlovr.model.detection.no_force_signal`) ends by its motion: the program moves as the
demonstration did until its transition came, then goes on with the next macro's motion. Where the
transition comes later in a run than in the demonstration (the objects lie further along that
motion, a longer or softer cable trails further behind the gripper), nothing tells the program to
go on: only the motion that followed the transition in the demonstration can still carry the cable
over. That motion along the macro's own direction is the margin the demonstration left
(:func:`went_on`). A hand that stopped its drag as the transition came leaves almost none, and its
program fails wherever the objects lie a millimetre further along (docs/people.md).

:func:`blind_margins` lists a program's drags of the cable's tip into an instability (an ``I``
macro that moves the gripper :data:`DRAG_MIN_M` or more and establishes a vertex contact, ``V/...``:
the tip caught at a corner or an edge) without force signal whose margin is less than
:data:`PLACEMENT_M`, the objects' placement tolerance of the standard variation (``--vary
objects.pos=0.005``): ``dlovr compile`` warns of them, so that a demonstrator can drag on past such
a transition the next time. Other macros without force signal are left out, as the trials show no
such failure for them. On ten person-like peg-in-hole demonstrations, the stable transitions
(``C``, ``E``) had margins of 0-4 mm in programs that reach the goal in 75-100 % of the standard
variation's trials, and so did the edges sample's drag of the cable onto a ridge (``E/E^LI``: its
trials with the objects moved get past it). The drag of the tip into the groove's corner had 2.3-4.0
mm in the three that reached it in 45-75 %, and more in the seven with 75-100 % (docs/people.md).
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import numpy as np

from dlovr.model.detection import MIN_SNR, no_force_signal
from dlovr.transforms import norm

#: How long after a transition (s) the demonstration's motion on is looked for.
WINDOW_S = 1.0
#: The objects' placement tolerance (m) a margin is compared with: what the standard variation moves
#: each object by, at most, along each axis.
PLACEMENT_M = 0.005
#: The least net motion (m) of an ``I`` macro that counts as a drag.
DRAG_MIN_M = 0.02


def went_on(
    times: np.ndarray, pos: np.ndarray, t: float, u: Sequence[float], window: float = WINDOW_S,
) -> float:
    """How far (m) the gripper (``times`` s, ``pos`` (k, 3) m, world frame) went on along the unit
    direction ``u`` after time ``t``, at most, within ``window`` s (0 when it went back or stayed)."""
    a = int(np.searchsorted(times, t))
    b = int(np.searchsorted(times, t + window, side="right"))
    if a >= len(times) or b <= a:
        return 0.0
    along = (np.asarray(pos[a:b], dtype=float) - np.asarray(pos[a], dtype=float)) @ np.asarray(u, dtype=float)
    return max(float(along.max()), 0.0)


def blind(m: Any, min_snr: float = MIN_SNR) -> bool:
    """Does macro ``m`` end by its motion for want of a force signal (every detection of it: no signal
    or weak signal, :func:`dlovr.model.detection.no_force_signal`)?"""
    return not m.final and bool(m.detection) and all(
        no_force_signal(d.cls, d.params, min_snr) for d in m.detection
    )


def tip_drag(m: Any, min_snr: float = MIN_SNR) -> bool:
    """Is ``m`` a drag of the cable's tip into an instability that no force shows: an ``I`` macro that
    establishes a vertex contact (``V/...``) and ends by its motion (:func:`blind`)? (Its net motion is
    the caller's to check against :data:`DRAG_MIN_M`.)"""
    return tuple(m.classes) == ("I",) and any(c.state.startswith("V/") for c in m.established) and blind(
        m, min_snr
    )


def blind_margins(
    program: Any, times: np.ndarray, pos: np.ndarray, min_snr: float = MIN_SNR, least: float | None = None,
) -> list[tuple[int, float]]:
    """``(index, margin m)`` of each drag of the tip into an instability of ``program`` that no force
    shows (:func:`tip_drag`, net motion :data:`DRAG_MIN_M` or more) and whose demonstration went on
    less than ``least`` (default
    :data:`PLACEMENT_M`) along that motion after its transition (:func:`went_on` of the track the
    program follows: ``times`` s, ``pos`` m world)."""
    least = PLACEMENT_M if least is None else least
    out = []
    for m in program.macros:
        d = m.motion.world
        n = norm(d)
        if n < DRAG_MIN_M or not tip_drag(m, min_snr):
            continue
        margin = went_on(times, pos, m.t, (d[0] / n, d[1] / n, d[2] / n))
        if margin < least:
            out.append((m.index, margin))
    return out


def margin_warning(margins: Sequence[tuple[int, float]]) -> str | None:
    """What ``dlovr compile`` says of :func:`blind_margins` (None for none)."""
    if not margins:
        return None
    parts = ", ".join(f"macro {k} ({margin * 1000:.1f} mm)" for k, margin in margins)
    return (
        f"no force shows where the drag of the cable's tip into an instability ends in {parts}, and the "
        "demonstration "
        f"went on only that far past it: where the objects lie further along (up to "
        f"{PLACEMENT_M * 1000:g} mm under the standard variation) the program stops short; "
        "demonstrating, drag on a few millimetres past such a transition"
    )
