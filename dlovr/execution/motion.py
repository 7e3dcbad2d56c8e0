"""The guarded motion of a macro: the demonstrated gripper displacement as a screw, repeated from
wherever the gripper is.

A macro's motion is the demonstrated change of gripper pose: a displacement and a rotation (the
program's ``relative`` displacement and ``rotation`` vector, gripper frame at the macro's start).
It is followed as the screw motion between the two poses (constant twist in the gripper frame), so a
demonstrated turn about the cable's tip or about an edge is repeated as that turn, not as a straight
line; a pure displacement is a straight line. Parameter ``s`` runs from 0 (start) to 1 (the
demonstrated end) and beyond (the allowance, 1.5 by default).

Frames: ``"world"`` repeats the demonstrated displacement and rotation in the world frame
(the turn's axis keeps its world direction); ``"relative"`` repeats them in the gripper frame at the
start (they turn with the gripper). Both start from the gripper's current pose.

Tool: a demonstrated turn about the cable's tip is a turn about a point the cable's demonstrated
length below the gripper. Where the executor has felt the tip elsewhere (a longer cable touches
sooner), ``tool`` (m, gripper frame) is how much further the tip is from the gripper than in the
demonstration, and every rotation is repeated about the point moved by it: the gripper's position
gets ``R(q_start) tool - R(q) tool`` added (nothing for a pure translation; nothing at ``tool = 0``).

Frames of objects: a macro's motion belongs to the object whose faces its principal contacts name
(the paper's macro operations act on contact faces). Where the executor is told where the objects
really are (``dlovr run --registered``: their shifts from the poses of the demonstration), a macro
whose object sits elsewhere than the previous macro's gets that difference added to its motion, in
proportion to its progress (:class:`ShiftedPath`), so that it moves where it should relative to its
object; blind (no shifts given), the motion is the demonstrated one in the world.

Everything here feeds the simulator, so it is computed in Python floats without BLAS (as
:mod:`dlovr.transforms`), and the same on every processor.
"""

from __future__ import annotations

import bisect
import math
from dataclasses import dataclass, field
from typing import Any, cast

import numpy as np

from dlovr.model.discrete import parse_discrete_contact
from dlovr.model.margins import DRAG_MIN_M, tip_drag, went_on
from dlovr.transforms import (
    dot,
    norm,
    quat_mul,
    quat_normalize,
    quat_rotate,
    quat_to_rotvec,
    rotvec_to_quat,
    slerp,
)

Vec = tuple[float, float, float]
Quat = tuple[float, float, float, float]


def _cross(a: Vec, b: Vec) -> Vec:
    return (a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0])


def _screw_coeffs(th: float) -> tuple[float, float]:
    """``a = (1 - cos th) / th^2`` and ``b = (th - sin th) / th^3`` (series near 0)."""
    if th < 1e-4:
        t2 = th * th
        return 0.5 - t2 / 24.0, 1.0 / 6.0 - t2 / 120.0
    return (1.0 - math.cos(th)) / (th * th), (th - math.sin(th)) / (th * th * th)


def _apply_v(phi: Vec, u: Vec) -> Vec:
    """``V(phi) u``: the displacement of a screw with rotation vector ``phi`` and linear twist ``u``."""
    th = math.sqrt(phi[0] ** 2 + phi[1] ** 2 + phi[2] ** 2)
    a, b = _screw_coeffs(th)
    c1 = _cross(phi, u)
    c2 = _cross(phi, c1)
    return (u[0] + a * c1[0] + b * c2[0], u[1] + a * c1[1] + b * c2[1], u[2] + a * c1[2] + b * c2[2])


def _apply_v_inv(phi: Vec, d: Vec) -> Vec:
    """``V(phi)^-1 d``: the linear twist of the screw that rotates by ``phi`` and moves by ``d``."""
    th = math.sqrt(phi[0] ** 2 + phi[1] ** 2 + phi[2] ** 2)
    if th < 1e-4:
        c = 1.0 / 12.0 + th * th / 720.0
    else:
        c = (1.0 - th * math.sin(th) / (2.0 * (1.0 - math.cos(th)))) / (th * th)
    c1 = _cross(phi, d)
    c2 = _cross(phi, c1)
    return (d[0] - 0.5 * c1[0] + c * c2[0], d[1] - 0.5 * c1[1] + c * c2[1], d[2] - 0.5 * c1[2] + c * c2[2])


@dataclass(frozen=True)
class ScrewPath:
    """Gripper poses along a demonstrated motion, from the pose ``start_pos``/``start_quat`` (world,
    wxyz) where it begins now.

    ``rotation``: rotation vector (rad) and ``displacement`` (m) of the demonstrated motion, both in
    the gripper frame at the demonstrated start; ``demo_quat``: the demonstrated start orientation
    (used by ``frame="world"``).
    """

    start_pos: Vec
    start_quat: tuple[float, float, float, float]
    rotation: Vec
    displacement: Vec
    demo_quat: tuple[float, float, float, float] = (1.0, 0.0, 0.0, 0.0)
    frame: str = "world"
    tool: Vec = (0.0, 0.0, 0.0)

    def __post_init__(self) -> None:
        if self.frame not in ("world", "relative"):
            raise ValueError(f"frame must be 'world' or 'relative', got {self.frame!r}")

    @property
    def twist(self) -> Vec:
        """Linear part of the constant gripper-frame twist (m per unit of ``s``)."""
        return _apply_v_inv(self.rotation, self.displacement)

    def at(self, s: float) -> tuple[np.ndarray, np.ndarray]:
        """Pose (world position m, quaternion wxyz) at path parameter ``s`` (0 start, 1 demonstrated end)."""
        phi = (s * self.rotation[0], s * self.rotation[1], s * self.rotation[2])
        v = self.twist
        local = _apply_v(phi, (s * v[0], s * v[1], s * v[2]))  # gripper frame at the start
        dq = rotvec_to_quat(phi)
        frame_q = np.asarray(self.start_quat if self.frame == "relative" else self.demo_quat, dtype=float)
        frame_q = quat_normalize(frame_q)
        offset = quat_rotate(frame_q, np.array(local))
        pos = np.array([self.start_pos[i] + float(offset[i]) for i in range(3)])
        q0 = quat_normalize(np.asarray(self.start_quat, dtype=float))
        if self.frame == "relative":
            quat = quat_mul(q0, dq)
        else:  # the rotation with its world axis: frame dq frame^-1, applied before q0
            inv = np.array([frame_q[0], -frame_q[1], -frame_q[2], -frame_q[3]])
            quat = quat_mul(quat_mul(quat_mul(frame_q, dq), inv), q0)
        quat = quat_normalize(quat)
        return tool_shift(pos, q0, quat, self.tool), quat


def tool_shift(pos: np.ndarray, q_ref: np.ndarray, q: np.ndarray, tool: Vec) -> np.ndarray:
    """``pos`` (m, world) plus ``R(q_ref) tool - R(q) tool``: the gripper position that turns about
    the point ``tool`` (gripper frame) further along than the demonstrated turn's pivot."""
    if tool[0] == 0.0 and tool[1] == 0.0 and tool[2] == 0.0:
        return pos
    a, b = quat_rotate(q_ref, tool).tolist(), quat_rotate(q, tool).tolist()
    p = pos.tolist() if type(pos) is np.ndarray else [float(x) for x in pos]
    return np.array([float(p[i]) + a[i] - b[i] for i in range(3)])


def local_twist(
    times: np.ndarray,
    pos: np.ndarray,
    quat: np.ndarray,
    t0: float,
    t1: float,
    span: float,
    window: float = 0.1,
) -> tuple[Vec, Vec] | None:
    """How the recorded gripper was moving when a stretch ``t0``-``t1`` (s) ended: the rotation
    vector (rad) and displacement (m) of ``span`` seconds of the constant twist (gripper frame) that
    takes the pose at ``t - window`` to the pose at ``t``, for the last ``t <= t1`` in the stretch
    where the gripper moved (more than 0.1 mm or 1 mrad in ``window``); None if it held still."""
    times = np.asarray(times, dtype=float)
    t = float(t1)
    while t - window >= float(t0) - 1e-12:
        a, b = np.searchsorted(times, t - window, side="right"), np.searchsorted(times, t, side="right")
        ia, ib = max(a - 1, 0), max(b - 1, 0)
        pa, qa, pb, qb = pos[ia], quat_normalize(quat[ia]), pos[ib], quat_normalize(quat[ib])
        inv = np.array([qa[0], -qa[1], -qa[2], -qa[3]])
        d = quat_rotate(inv, np.array([float(pb[i]) - float(pa[i]) for i in range(3)]))
        phi = quat_to_rotvec(quat_mul(inv, qb))
        dist = math.sqrt(sum(float(c) ** 2 for c in d))
        if dist > 1e-4 or math.sqrt(sum(c * c for c in phi)) > 1e-3:
            k = span / max(float(times[ib]) - float(times[ia]), 1e-9)
            rot = (phi[0] * k, phi[1] * k, phi[2] * k)
            v = _apply_v_inv(phi, (float(d[0]), float(d[1]), float(d[2])))
            return rot, _apply_v(rot, (v[0] * k, v[1] * k, v[2] * k))
        t -= window
    return None


def last_start(
    times: np.ndarray, pos: np.ndarray, quat: np.ndarray, t0: float, t1: float, still: float = 0.05
) -> float:
    """Demonstration time (s) at which the gripper last set off, within ``t0``-``t1``, after holding
    still (no sample-to-sample change above 1 mm/s or 1 mrad/s) for ``still`` s or more: the start of
    the motion phase in which the stretch's transition came. ``t0`` if it never held still."""
    times = np.asarray(times, dtype=float)
    a = max(int(np.searchsorted(times, t0, side="left")) - 1, 0)
    b = int(np.searchsorted(times, t1, side="right"))
    if b - a < 2:
        return float(t0)
    dt = np.maximum(np.diff(times[a:b]), 1e-12)
    dp = np.linalg.norm(np.diff(pos[a:b], axis=0), axis=1) / dt
    dq = np.linalg.norm(np.diff(quat[a:b], axis=0), axis=1) / dt
    moving = (dp > 1e-3) | (dq > 1e-3)
    for k in range(len(moving) - 1, 0, -1):
        if moving[k] and not moving[k - 1]:
            j = k - 1
            while j >= 0 and not moving[j]:
                j -= 1
            if float(times[a + k]) - float(times[a + j + 1]) >= still - 1e-12:
                return max(float(times[a + k]), float(t0))
    return float(t0)


def _between(t: float, times: list[float], pos: list[list[float]], quat: list[list[float]], j: int
             ) -> tuple[list[float], list[float] | np.ndarray]:
    """The pose at ``t`` (s) between samples ``j - 1`` and ``j`` (``times[j - 1] <= t < times[j]``,
    all in Python floats): the position linear, the quaternion slerped (sample ``j - 1``'s itself
    where ``t`` is its time or both are equal)."""
    a, b = times[j - 1], times[j]
    w = 0.0 if b <= a else (t - a) / (b - a)
    p0, p1 = pos[j - 1], pos[j]
    out = [p0[k] + w * (p1[k] - p0[k]) for k in range(3)]
    qa, qb = quat[j - 1], quat[j]
    if w == 0.0 or qa == qb:
        return out, qa
    return out, slerp(qa, qb, w)


#: Over how much demonstration time (s) before its end :class:`TrackPath` takes a stretch's last
#: velocity (where it eases into the motion beyond it).
END_VELOCITY_S = 0.02
#: How long (s) a hand's macro takes beyond its stretch to go from the stretch's last velocity to its
#: net motion's (:class:`TrackPath` ``ease``; the executor's ``_path``). A hand slows as it feels the
#: touch, and its net motion is faster: taken at once, the commanded velocity of one person-like
#: peg-in-hole approach jumped from 8 to 21 mm/s within a step, and the wrench's jolt was taken for the
#: tip's first touch in 13 of 20 trials (docs/people.md, "Easing into the motion beyond").
HAND_EASE_S = 0.2


@dataclass(frozen=True)
class TrackPath:
    """Gripper poses along the demonstration's own recorded trajectory between two of its times, from
    the pose where the macro begins now.

    ``times`` (k,) s, ``pos`` (k, 3) m, ``quat`` (k, 4) wxyz: the demonstration's commanded gripper
    poses (world). The macro's stretch runs from demonstration time ``t0`` (``s = 0``) to ``t1``
    (``s = 1``). Beyond it (the allowance), the motion goes on as the screw ``beyond`` (gripper frame,
    scaled by ``s - 1``; the executor gives :func:`local_twist`, the recorded motion at the end of
    the stretch over one stretch's time) from the pose reached at ``s = 1``: a guarded approach keeps
    approaching, a turn keeps turning. ``frame`` as :class:`ScrewPath`:
    ``world`` repeats the recorded displacement and rotation in the world frame, ``relative`` in the
    gripper frame at the start.

    ``ease`` (units of ``s``): beyond ``s = 1`` the velocity goes over from the stretch's last one
    (over its last :data:`END_VELOCITY_S` s) to the screw's along a linear ramp this long, instead of
    at once; 0: at once. A hand's stretch ends at its own pace and its net motion has another, and a
    jump of the commanded velocity shakes the wrench as a touch does (docs/programs.md).
    """

    times: np.ndarray
    pos: np.ndarray
    quat: np.ndarray
    t0: float
    t1: float
    start_pos: Vec
    start_quat: tuple[float, float, float, float]
    frame: str = "world"
    beyond: tuple[Vec, Vec] | None = None  # (rotation vector rad, displacement m), gripper frame
    tool: Vec = (0.0, 0.0, 0.0)  # the tip's offset from the demonstrated one (m, gripper frame)
    ease: float = 0.0
    # set once by __post_init__ (per path, not per step), and _end on the first step beyond s = 1
    _p0: list[float] = field(init=False, repr=False, compare=False)
    _inv0: list[float] = field(init=False, repr=False, compare=False)  # Python floats, as the steps use them
    _cur_q: list[float] = field(init=False, repr=False, compare=False)
    _end: ScrewPath | None = field(init=False, repr=False, compare=False)
    _v_end: list[float] = field(init=False, repr=False, compare=False)  # m per unit of s, with _end
    # the samples around the stretch t0-t1 as Python floats: times, positions, quaternions
    _window: tuple[list[float], list[list[float]], list[list[float]]] = field(
        init=False, repr=False, compare=False)
    # the tool (None when zero) as an array and turned by the start orientation (tool_shift's R(q_ref) tool)
    _tool: tuple[np.ndarray, list[float]] | None = field(init=False, repr=False, compare=False)

    def __post_init__(self) -> None:
        if self.frame not in ("world", "relative"):
            raise ValueError(f"frame must be 'world' or 'relative', got {self.frame!r}")
        times = np.asarray(self.times, dtype=float)
        lo = max(int(np.searchsorted(times, self.t0, side="right")) - 1, 0)
        hi = min(int(np.searchsorted(times, self.t1, side="right")), len(times) - 1) + 1
        window = (times[lo:hi].tolist(), np.asarray(self.pos[lo:hi], dtype=float).tolist(),
                  np.asarray(self.quat[lo:hi], dtype=float).tolist())
        object.__setattr__(self, "_window", window)
        p0, q0 = self._sample(self.t0)  # per path, not per step: this runs every simulation step
        object.__setattr__(self, "_p0", p0)
        object.__setattr__(self, "_inv0", [float(x) for x in (q0[0], -q0[1], -q0[2], -q0[3])])
        object.__setattr__(self, "_cur_q", quat_normalize(np.asarray(self.start_quat, dtype=float)).tolist())
        object.__setattr__(self, "_end", None)
        tool = self.tool
        turned = None
        if not (tool[0] == 0.0 and tool[1] == 0.0 and tool[2] == 0.0):
            arr = np.array(tool, dtype=float)
            turned = (arr, quat_rotate(self._cur_q, arr).tolist())
        object.__setattr__(self, "_tool", turned)

    def _at_time(self, t: float) -> tuple[np.ndarray, np.ndarray]:
        """The recorded pose at time ``t`` (s), interpolated between the samples around it (linear,
        slerp), held at the first and the last."""
        pos, quat = self._sample(t)
        return np.array(pos), np.array(quat, dtype=float)

    def _sample(self, t: float) -> tuple[list[float], Any]:
        """:meth:`_at_time` in Python floats (the same values; the quaternion a list or a row of
        ``quat``), from the stretch's samples (``_window``) where ``t`` lies between two of them."""
        times_w, pos_w, quat_w = self._window
        if times_w and times_w[0] <= t < times_w[-1]:  # searchsorted's index less the window's start
            return _between(t, times_w, pos_w, quat_w, bisect.bisect_right(times_w, t))
        times = self.times
        i = int(np.searchsorted(times, t, side="right"))
        if i <= 0:
            return np.asarray(self.pos[0], dtype=float).tolist(), self.quat[0]
        if i >= len(times):
            return np.asarray(self.pos[-1], dtype=float).tolist(), self.quat[-1]
        two = slice(i - 1, i + 1)
        ts, ps, qs = (np.asarray(x[two], dtype=float).tolist() for x in (times, self.pos, self.quat))
        return _between(t, ts, ps, qs, 1)

    def _beyond(self, on: ScrewPath, u: float) -> tuple[np.ndarray, np.ndarray]:
        """The pose ``u`` past ``s = 1``: the screw ``on`` at ``u``, or eased in (``ease``): the screw
        at ``w(u)``, which starts still and reaches its own pace at ``u = ease`` (``w' = u / ease``), plus
        the stretch's last velocity times ``u - w(u)`` (its share fading out), so that the velocity is
        continuous at ``s = 1``. The orientation is the screw's at ``w(u)``."""
        e = self.ease
        if e <= 0.0:
            return on.at(u)
        w = u * u / (2.0 * e) if u < e else u - 0.5 * e
        pos, quat = on.at(w)
        v = self._v_end
        return np.array([float(pos[i]) + v[i] * (u - w) for i in range(3)]), quat

    def at(self, s: float) -> tuple[np.ndarray, np.ndarray]:
        """Pose (world m, wxyz) at path parameter ``s`` (0 at ``t0``, 1 at ``t1``)."""
        if s > 1.0 and self.beyond is not None:
            on = self._end
            if on is None:
                pos, quat = self.at(1.0)
                here = cast(Quat, tuple(float(x) for x in quat))
                start = cast(Vec, tuple(float(x) for x in pos))
                on = ScrewPath(start, here, *self.beyond, here, "relative", self.tool)
                object.__setattr__(self, "_end", on)
                if self.ease > 0.0:
                    h = END_VELOCITY_S / max(self.t1 - self.t0, 1e-9)
                    before = self.at(1.0 - h)[0]
                    object.__setattr__(self, "_v_end", [(start[i] - float(before[i])) / h for i in range(3)])
            return self._beyond(on, s - 1.0)
        p0, inv0, cur_q = self._p0, self._inv0, self._cur_q
        p, q = self._sample(self.t0 + s * (self.t1 - self.t0))
        d = [p[i] - p0[i] for i in range(3)]  # Python floats throughout: numpy's roundings
        if self.frame == "relative":
            offset = quat_rotate(cur_q, quat_rotate(inv0, d)).tolist()
            quat = quat_mul(cur_q, quat_mul(inv0, q))
        else:
            offset = d
            quat = quat_mul(quat_mul(q, inv0), cur_q)
        start = self.start_pos
        quat = quat_normalize(quat)
        if self._tool is None:
            return np.array([start[i] + offset[i] for i in range(3)]), quat
        tool, a = self._tool  # tool_shift's sums, with R(q_start) tool made once
        b = quat_rotate(quat, tool).tolist()
        pos = [start[i] + offset[i] for i in range(3)]
        return np.array([pos[i] + a[i] - b[i] for i in range(3)]), quat


@dataclass(frozen=True)
class ShiftedPath:
    """A path (anything with ``at(s)``) with the displacement ``shift`` (m, world) added in proportion
    to its progress: ``min(s, 1) * shift`` (the whole shift from the demonstrated end on)."""

    path: Any
    shift: Vec

    def at(self, s: float) -> tuple[np.ndarray, np.ndarray]:
        pos, quat = self.path.at(s)
        k = min(max(s, 0.0), 1.0)
        return np.array([float(pos[i]) + k * self.shift[i] for i in range(3)]), quat


def slid_face_normal(m: Any) -> Vec | None:
    """The outward normal (unit, world) of the face that macro ``m``'s cable slides along into its
    new contact: an ``E`` transition whose from-situation has a principal contact on that face alone
    (``E/F`` or ``V/F``, whose contact vector is minus the normal) and whose established contact
    touches the same face (the tip sliding down a side face into the groove it makes with the block
    below); None for any other macro."""
    if tuple(m.classes) != ("E",):
        return None
    new_faces = {f for c in m.established for f in parse_discrete_contact(c.state).faces}
    for c in m.from_contacts:
        dc, v = parse_discrete_contact(c.state), c.vector
        if dc.state.env == "F" and len(dc.faces) == 1 and dc.faces[0] in new_faces and v is not None \
                and any(x != 0.0 for x in v):
            return (-float(v[0]), -float(v[1]), -float(v[2]))
    return None


#: The give-way (m) of a program that follows a hand's track (:func:`give_way_m`): a person's drift
#: toward a face the cable slides on presses it there. 5 mm took the person-like peg-in-hole programs
#: from 82 % to 90 % of the benchmark's standard-variation trials (79 -> 87 % and 86 -> 88 % on
#: held-out ones); 1 cm gained a point more, mostly by skipping the demonstrated groove contact
#: (docs/people.md, "The give-way by default for a hand's track").
HAND_GIVE_WAY_M = 0.005


def give_way_m(option: float | None, by_hand: bool) -> float:
    """The give-way (m) a run applies: ``option`` (``dlovr run --give-way``) where given, else
    :data:`HAND_GIVE_WAY_M` for a track a hand made (``by_hand``) and 0 for one a script played."""
    if option is not None:
        return option
    return HAND_GIVE_WAY_M if by_hand else 0.0


def given_way(path: Any, m: Any, distance: float) -> Any:
    """``path`` moved ``distance`` (m) away from the face that ``m`` slides along
    (:func:`slid_face_normal`), in proportion to its progress (:class:`ShiftedPath`); ``path`` itself
    for another macro or at ``distance`` 0. Held off the face, the cable often ends beside the new
    contact rather than in it (docs/people.md, "Giving way from the face the cable slides on")."""
    n = slid_face_normal(m) if distance > 0.0 else None
    if n is None:
        return path
    return ShiftedPath(path, (distance * n[0], distance * n[1], distance * n[2]))


#: How much further (m) a hand's ``I`` drag goes, per metre that the cable's tip was felt further
#: from the gripper than demonstrated, less what the hand itself dragged on after the transition
#: (:func:`dragged_on`): a longer cable's tip trails further behind a drag (along the groove to its
#: corner in peg-in-hole, 6 mm for a tip 18 mm further), and a hand that stopped its drag as the tip
#: reached the corner left no margin for it (docs/people.md, "A longer cable drags on").
DRAG_PER_EXCESS = 0.4
#: How far (m) past its demonstrated transition a hand's drag of the cable's tip into an instability
#: that no force shows (:func:`dlovr.model.margins.tip_drag`: peg-in-hole's tip dragged into the
#: groove's corner) goes at least, counting what the hand itself went on (:func:`dragged_on`).
#: Nothing ends such a drag where the transition comes later in a run than demonstrated (the objects
#: further along, a cable that trails more); the peg-in-hole script, computed with margins, drags
#: 10.2 mm past it. 15 mm, not the script's 10: on 15 person-like demonstrations, trials where the tip
#: reached the corner only as the drag ended and the fast lowering after it pressed it onto the hole
#: block's top instead (under force noise, the objects further along) reach the goal with it; 20 mm
#: loses trials again (docs/people.md, "A hand's drag goes on 15 mm past the corner").
DRAG_PAST_M = 0.015
#: The shortest such drag of the tip (m) that is drawn on (not only drags of :data:`DRAG_MIN_M`): a
#: hand that lifted the tip out of the groove on its way leaves a short last drag into the corner
#: (12.5 mm on one person-like demonstration: 85 % of its trials reached the goal without, 100 % with;
#: docs/people.md).
DRAG_TIP_MIN_M = 0.01


def dragged_on(path: Any, m: Any, tool: Vec, track: Any) -> tuple[Any, str]:
    """``path`` drawn on along its net displacement (unit ``u``), for an ``I`` macro that drags (net
    motion at least :data:`DRAG_MIN_M`, or :data:`DRAG_TIP_MIN_M` for a drag of the tip that no force
    shows: a drag that pulls the tip into an instability), by what it wants less the drag the
    demonstration's ``track`` went on with after ``m.t`` (within :data:`dlovr.model.margins.WINDOW_S`,
    :func:`dlovr.model.margins.went_on`), where that is positive; and why (the executor's event). It
    wants :data:`DRAG_PER_EXCESS` times the cable's excess, ``-tool[2]`` (m: how much further the tip
    is than demonstrated, the executor's ``tool``, gripper frame), and at least :data:`DRAG_PAST_M`
    where no force shows the tip's transition (:func:`dlovr.model.margins.tip_drag`). ``path`` itself
    otherwise. Added in proportion to progress (:class:`ShiftedPath`)."""
    if tuple(m.classes) != ("I",):
        return path, ""
    excess = -float(tool[2])
    want = DRAG_PER_EXCESS * max(excess, 0.0)
    past = tip_drag(m)
    if past:
        want = max(want, DRAG_PAST_M)
    if want <= 0.0:
        return path, ""
    a, b = path.at(0.0)[0], path.at(1.0)[0]
    d = [float(b[i]) - float(a[i]) for i in range(3)]
    n = norm(d)
    if n < (DRAG_TIP_MIN_M if past else DRAG_MIN_M):
        return path, ""
    u = (d[0] / n, d[1] / n, d[2] / n)
    left = went_on(track.t, track.pos, m.t, u)
    more = want - left
    if more <= 0.0:
        return path, ""
    if past and want == DRAG_PAST_M:
        why = (f"no force shows where the tip arrives, and the demonstration went on {left * 1000:.1f} mm "
               f"past it, not {DRAG_PAST_M * 1000:g}")
    else:
        why = f"the cable's tip is {excess * 1000:.1f} mm further than demonstrated"
    return ShiftedPath(path, (more * u[0], more * u[1], more * u[2])), why


def hand_path(path: Any, m: Any, give_way: float | None, track: Any, tool: Vec) -> tuple[Any, str]:
    """Macro ``m``'s ``path`` as the run adapts it: given way from the face it slides along
    (:func:`given_way`, :func:`give_way_m` of the option ``give_way`` and whether ``track`` is a
    hand's), and on a hand's track an ``I`` drawn on for a longer cable or past a transition no force
    shows (:func:`dragged_on`); and
    what the macro's event says of it (empty where ``path`` is unchanged)."""
    by_hand = track is not None and track.by_hand
    away = give_way_m(give_way, by_hand)
    out = given_way(path, m, away)
    said = "" if out is path else f" (giving way {away * 1000:g} mm from the face it slides along)"
    drawn, why = dragged_on(out, m, tool, track) if by_hand else (out, "")
    if drawn is not out:
        said += f" (dragging {norm(drawn.shift) * 1000:.1f} mm further: {why})"
    return drawn, said


@dataclass(frozen=True)
class TurnedPath:
    """A path (anything with ``at(s)``) that starts at ``pos``, ``quat`` (world), turned about that
    start by ``turn`` (wxyz, world): its displacements turned, ``pos + R (p(s) - pos)``, and its
    change of orientation turned with them, ``R (q(s) q0^-1) R^-1 q0`` (a registered run whose objects
    are turned repeats a world-frame motion in their frame)."""

    path: Any
    turn: Quat
    pos: Vec
    quat: Quat

    def at(self, s: float) -> tuple[np.ndarray, np.ndarray]:
        p, q = self.path.at(s)
        r = np.asarray(self.turn, float)
        r_inv = np.array([r[0], -r[1], -r[2], -r[3]])
        q0 = np.asarray(self.quat, float)
        q0_inv = np.array([q0[0], -q0[1], -q0[2], -q0[3]])
        d = quat_rotate(r, np.array([float(p[i]) - self.pos[i] for i in range(3)]))
        change = quat_mul(quat_mul(r, quat_mul(np.asarray(q, float), q0_inv)), r_inv)
        return (np.array([self.pos[i] + float(d[i]) for i in range(3)]),
                quat_normalize(quat_mul(change, q0)))


def eased(a: Vec, b: Vec, s: float) -> Vec:
    """The point ``s`` (0-1) of the way from ``a`` to ``b`` (m) with a smooth start and stop
    (``(1 - cos(pi s)) / 2``)."""
    k = 0.5 * (1.0 - math.cos(math.pi * min(max(s, 0.0), 1.0)))
    return (a[0] + k * (b[0] - a[0]), a[1] + k * (b[1] - a[1]), a[2] + k * (b[2] - a[2]))


def touches_tip(m: Any) -> bool:
    """Whether macro ``m`` is the cable's tip touching from free space, approached along the cable:
    an ``E`` that releases nothing and establishes only tip (``V/``) contacts, its demonstrated motion
    within 25 degrees of the gripper's -z axis (the cable leaves the gripper along -z)."""
    mo = m.motion
    d = norm(mo.relative)
    return (
        m.classes == ("E",) and not m.released and bool(m.established)
        and all(c.state.startswith("V/") for c in m.established)
        and d > 1e-6 and -float(mo.relative[2]) >= math.cos(math.radians(25.0)) * d
    )


def tip_offset(path: Any, s: float) -> Vec:
    """The tip's offset from the demonstrated one (m, gripper frame) when its first touch, which the
    demonstration felt at ``s = 1`` of ``path``, is felt at ``s``: the motion left (or overshot)
    along the cable's axis. A longer cable touches sooner, and its tip is that much further."""
    p1, _ = path.at(1.0)
    ps, qs = path.at(s)
    down = quat_rotate(np.asarray(qs, dtype=float), np.array([0.0, 0.0, -1.0]))
    along = dot([float(p1[i]) - float(ps[i]) for i in range(3)], down)
    return (0.0, 0.0, -along)
