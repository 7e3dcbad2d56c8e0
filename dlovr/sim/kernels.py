"""Compiled per-step kernel of the simulator (world frame, metres, newtons): :func:`step_record`,
after ``mj_step``, the divergence checks and the step's record arrays (cable points, the raw
rod-obstacle contacts with their normal forces, the gripper force) in one call, reading MuJoCo's
arrays in place (:class:`dlovr.sim.contacts.MjViews`). The tracker's kernels are in
:mod:`dlovr.sim.track_kernels`.

Contact rows (``table``, (n, 14) float64, ints held exactly): point, segment, geom, object, piece,
distance, normal (3, obstacle toward rod), position (3, MuJoCo's midway point), normal force, active
(0/1). See :class:`dlovr.sim.contacts.ContactArrays`.
"""

from __future__ import annotations

import math
from typing import NamedTuple

import numpy as np

from dlovr.geometry.kernels import block_sum, dot3
from dlovr.jit import check_cache, njit

T_POINT, T_SEGMENT, T_GEOM, T_OBJ, T_PIECE, T_DIST = 0, 1, 2, 3, 4, 5
T_NORMAL, T_POS, T_FORCE, T_ACTIVE, T_WIDTH = 6, 9, 12, 13, 14

# layout of MuJoCo's contact structs (see dlovr.sim.contacts.MjViews.contacts): float64 units, then int32
L_STRIDE_F, L_DIST, L_POS, L_FRAME, L_STRIDE_I, L_DIM, L_GEOM, L_FLEX, L_ELEM, L_VERT, L_EFC = range(11)
L_COUNT = 11

# the simulator's configuration (cfg, int64): header (the contact structs' layout at its end), then
# the sections of Config (:func:`pack_config`)
C_WARN_BASE, C_FLEX, C_PYRAMIDAL, C_NFATAL, C_NGEOM, C_NHOLD = 0, 1, 2, 3, 4, 5
C_XPOS, C_QPOS, C_NQ, C_QVEL, C_NV, C_NVERT, C_MOCAP_POS, C_MOCAP_QUAT = 6, 7, 8, 9, 10, 11, 12, 13
# where mjData's fields lie in its struct (``mem``): ncon, ne, nefc (int32 units), time (float64), the
# arena and efc_force pointers (int64)
C_S_NCON, C_S_NE, C_S_NEFC, C_S_TIME, C_S_ARENA, C_S_EFC, C_S_END = 14, 15, 16, 17, 18, 19, 20
C_LAYOUT = C_S_END
C_HEAD = C_LAYOUT + L_COUNT
# the record's small arrays in one (``out``): gripper force, torque, position, quaternion
O_FORCE, O_TORQUE, O_POS, O_QUAT, O_WIDTH = 0, 3, 6, 9, 13


class Config(NamedTuple):
    """The sections of the simulator's configuration after its header (views)."""

    fatal: np.ndarray  # the fatal warnings' counts (in int32 units of the mjData struct)
    piece_of_geom: np.ndarray  # the obstacle piece of each geom (-1 for none)
    obj_of_geom: np.ndarray  # the object of each geom
    hold_rows: np.ndarray  # the holding constraints' rows (3 per constraint)
    layout: np.ndarray  # (L_COUNT,) the contact structs' layout (``L_*``)


def pack_config(
    head: np.ndarray,
    fatal: np.ndarray,
    piece_of_geom: np.ndarray,
    obj_of_geom: np.ndarray,
    hold_rows: np.ndarray,
) -> np.ndarray:
    """The configuration array: ``head`` (``C_HEAD`` entries; ``C_NHOLD`` is set here), then the
    sections of :class:`Config`."""
    head[C_NHOLD] = len(hold_rows)
    return np.concatenate([head, fatal, piece_of_geom, obj_of_geom, hold_rows.astype(np.int64)])


@njit(inner=True)
def _config(cfg: np.ndarray) -> Config:
    n_fatal, n_geom, n_hold = cfg[C_NFATAL], cfg[C_NGEOM], cfg[C_NHOLD]
    a = C_HEAD + n_fatal
    b = a + 2 * n_geom
    layout = cfg[C_LAYOUT:C_HEAD]
    return Config(cfg[C_HEAD:a], cfg[a : a + n_geom], cfg[a + n_geom : b], cfg[b : b + n_hold], layout)


# --------------------------------------------------------------------------------------------------
# simulator


@njit
def step_record(
    mj: np.ndarray,
    mem: np.ndarray,
    arena: np.ndarray,
    cfg: np.ndarray,
    bounds: np.ndarray,
    ncon: int,
    pts: np.ndarray,
    table: np.ndarray,
    out: np.ndarray,
):
    """The step's record arrays, and the divergence checks.

    ``mj``: MuJoCo's float arrays in place (qpos, qvel, the cable points and the gripper's mocap pose
    at the offsets in ``cfg``); ``mem``: the ``mjData`` struct (int64; its warning structs, counts,
    time and pointers at the offsets in ``cfg``); ``arena``: MuJoCo's arena, its contact structs
    (the first ``ncon``) and this step's ``efc_force``; ``cfg``: the configuration (``C_*``; see
    :class:`dlovr.sim.contacts.MjViews`); ``bounds``: squared segment length bounds (lo, hi), the
    segment length and the largest relative stretch. Fills ``pts`` (the cable points), the rows of
    ``table`` (one per rod-obstacle contact, in MuJoCo's order) and ``out`` (``O_*``): the gripper
    force (the holding constraints' rows of ``efc_force``, summed per axis), its torque
    (:func:`hold_torque`), the gripper's position and quaternion (wxyz).

    Returns (code, index, value, rows, self pairs, ne, time, (gripper position, quaternion,
    force)): code 0, or the first failed check: 1 the count of the fatal warnings differs from the
    baseline, 2 NaN/inf in qpos or qvel, 3 in the cable points, 4 segment ``index`` stretched by
    ``value`` (relative) beyond the largest stretch; MuJoCo's ``ne`` (the holding constraints'
    rows in ``cfg`` are those of this count: call again with the rows of another) and ``time``; the
    gripper's pose and force as tuples of floats (what the tracker's states hold).
    """
    conf = _config(cfg)
    fatal, piece_of_geom, obj_of_geom = conf.fatal, conf.piece_of_geom, conf.obj_of_geom
    hold_rows, layout, n_hold = conf.hold_rows, conf.layout, cfg[C_NHOLD]
    warn = mem.view(np.int32)
    ne, nefc, time = warn[cfg[C_S_NE]], warn[cfg[C_S_NEFC]], mem.view(np.float64)[cfg[C_S_TIME]]
    e0 = (mem[cfg[C_S_EFC]] - mem[cfg[C_S_ARENA]]) // 8
    if e0 < 0 or e0 + nefc > arena.shape[0]:
        raise RuntimeError("efc_force outside MuJoCo's arena")
    efc_force = arena[e0 : e0 + nefc]
    mp, mq = cfg[C_MOCAP_POS], cfg[C_MOCAP_QUAT]
    code, index, value = 0, -1, 0.0
    count = 0
    for w in fatal:
        count += warn[w]
    if count != cfg[C_WARN_BASE]:
        code = 1
    if code == 0:
        for i in range(cfg[C_QPOS], cfg[C_QPOS] + cfg[C_NQ]):
            if not np.isfinite(mj[i]):
                code = 2
        for i in range(cfg[C_QVEL], cfg[C_QVEL] + cfg[C_NV]):
            if not np.isfinite(mj[i]):
                code = 2
    n1 = cfg[C_NVERT]
    x0 = cfg[C_XPOS]
    for i in range(n1):
        for c in range(3):
            pts[i, c] = mj[x0 + 3 * i + c]
            if code == 0 and not np.isfinite(pts[i, c]):
                code = 3
    if code == 0:
        lo, hi, seg, max_stretch = bounds[0], bounds[1], bounds[2], bounds[3]
        beyond = False
        for i in range(n1 - 1):
            dx, dy, dz = pts[i + 1, 0] - pts[i, 0], pts[i + 1, 1] - pts[i, 1], pts[i + 1, 2] - pts[i, 2]
            d2 = dot3(dx, dy, dz, dx, dy, dz)
            beyond = beyond or d2 < lo or d2 > hi
        if beyond:  # rare: the exact test, naming the segment
            for i in range(n1 - 1):
                dx, dy, dz = pts[i + 1, 0] - pts[i, 0], pts[i + 1, 1] - pts[i, 1], pts[i + 1, 2] - pts[i, 2]
                dev = abs(np.sqrt(dot3(dx, dy, dz, dx, dy, dz)) / seg - 1.0)
                if dev > value or index < 0:
                    index, value = i, dev
            if value > max_stretch:
                code = 4
    for c in range(3):
        s = 0.0
        for r in range(c, n_hold, 3):
            s += efc_force[hold_rows[r]]
        out[O_FORCE + c] = 0.0 + s
        out[O_POS + c] = mj[mp + c]
    for c in range(4):
        out[O_QUAT + c] = mj[mq + c]
    hold_torque(efc_force, hold_rows, out[O_QUAT : O_QUAT + 4], bounds[2], out[O_TORQUE : O_TORQUE + 3])
    rows, nself = 0, 0
    flex, pyramidal = cfg[C_FLEX], cfg[C_PYRAMIDAL] != 0
    cf, ci = arena, arena.view(np.int32)
    sf, si = layout[L_STRIDE_F], layout[L_STRIDE_I]
    for i in range(ncon):
        bi = i * si
        f0, f1 = ci[bi + layout[L_FLEX]], ci[bi + layout[L_FLEX] + 1]
        g0, g1 = ci[bi + layout[L_GEOM]], ci[bi + layout[L_GEOM] + 1]
        if f0 == flex and f1 == flex:
            nself += 1
            continue
        if f1 == flex and g0 >= 0:
            side, gid, sign = 1, g0, 1.0
        elif f0 == flex and g1 >= 0:
            side, gid, sign = 0, g1, -1.0
        else:
            continue
        if piece_of_geom[gid] < 0:
            continue
        bf = i * sf
        t = table[rows]
        t[T_POINT] = ci[bi + layout[L_VERT] + side]
        t[T_SEGMENT] = ci[bi + layout[L_ELEM] + side]
        t[T_GEOM] = gid
        t[T_OBJ] = obj_of_geom[gid]
        t[T_PIECE] = piece_of_geom[gid]
        t[T_DIST] = cf[bf + layout[L_DIST]]
        for c in range(3):
            fr = cf[bf + layout[L_FRAME] + c]
            t[T_NORMAL + c] = fr if sign > 0 else -fr
            t[T_POS + c] = cf[bf + layout[L_POS] + c]
        adr = ci[bi + layout[L_EFC]]
        force = 0.0
        if adr >= 0:
            dim = ci[bi + layout[L_DIM]]
            if pyramidal and dim > 1:  # mj_contactForce: the sum of the cone's 2 (dim - 1) edge forces
                force = 0.0 + block_sum(efc_force, np.int64(adr), 2 * (dim - 1))  # np_sum's (lo int64)
            else:
                force = efc_force[adr]
        t[T_FORCE] = force
        t[T_ACTIVE] = 1.0 if adr >= 0 else 0.0
        rows += 1
    pos, quat, grip = (out[O_POS], out[O_POS + 1], out[O_POS + 2]), (out[O_QUAT], out[O_QUAT + 1],
                       out[O_QUAT + 2], out[O_QUAT + 3]), (out[O_FORCE], out[O_FORCE + 1], out[O_FORCE + 2])
    return code, index, value, rows, nself, ne, time, (pos, quat, grip)


@njit
def move_gripper(
    pos: np.ndarray, quat: np.ndarray, target_pos: np.ndarray, target_quat: np.ndarray, vmax: float,
    wmax: float,
) -> None:
    """Moves the gripper's pose (``pos``, m, and ``quat``, wxyz: MuJoCo's mocap arrays, in place) one
    step toward the target at most ``vmax`` (m) and ``wmax`` (rad) per step: the target itself when
    it lies within them, else the position along the straight line and the orientation along the
    shortest arc (:func:`dlovr.transforms.slerp`). The same IEEE operations in the same order as the
    Python floats of :func:`dlovr.transforms.norm`, ``dot`` and ``slerp`` (sums from 0.0, left to
    right; ``math.acos`` and ``sin`` from the C library both ways), so the same bits: this feeds
    MuJoCo and recordings replay bit for bit."""
    p0, p1, p2 = pos[0], pos[1], pos[2]
    t0, t1, t2 = target_pos[0], target_pos[1], target_pos[2]
    if p0 != t0 or p1 != t1 or p2 != t2:  # a gripper already at its target stays put
        d0, d1, d2 = t0 - p0, t1 - p1, t2 - p2
        dist = np.sqrt(0.0 + d0 * d0 + d1 * d1 + d2 * d2)
        if dist <= vmax:
            pos[0], pos[1], pos[2] = t0, t1, t2
        else:
            f = vmax / dist
            pos[0], pos[1], pos[2] = p0 + d0 * f, p1 + d1 * f, p2 + d2 * f
    q0, q1, q2, q3 = quat[0], quat[1], quat[2], quat[3]
    r0, r1, r2, r3 = target_quat[0], target_quat[1], target_quat[2], target_quat[3]
    if q0 == r0 and q1 == r1 and q2 == r2 and q3 == r3:
        return
    c = 0.0 + q0 * r0 + q1 * r1 + q2 * r2 + q3 * r3
    angle = 2.0 * math.acos(min(1.0, abs(c)))
    if angle <= wmax:
        quat[0], quat[1], quat[2], quat[3] = r0, r1, r2, r3
        return
    s = wmax / angle
    # slerp(q, target, s): both made unit first
    n = np.sqrt(0.0 + q0 * q0 + q1 * q1 + q2 * q2 + q3 * q3)
    a0, a1, a2, a3 = q0 / n, q1 / n, q2 / n, q3 / n
    n = np.sqrt(0.0 + r0 * r0 + r1 * r1 + r2 * r2 + r3 * r3)
    b0, b1, b2, b3 = r0 / n, r1 / n, r2 / n, r3 / n
    c = 0.0 + a0 * b0 + a1 * b1 + a2 * b2 + a3 * b3
    if c < 0.0:
        b0, b1, b2, b3, c = -b0, -b1, -b2, -b3, -c
    if c > 0.9995:  # close: along the chord, made unit
        v0, v1, v2, v3 = a0 + s * (b0 - a0), a1 + s * (b1 - a1), a2 + s * (b2 - a2), a3 + s * (b3 - a3)
        n = np.sqrt(0.0 + v0 * v0 + v1 * v1 + v2 * v2 + v3 * v3)
        quat[0], quat[1], quat[2], quat[3] = v0 / n, v1 / n, v2 / n, v3 / n
        return
    th = math.acos(min(1.0, c))
    sin = math.sin(th)
    wa, wb = math.sin((1.0 - s) * th) / sin, math.sin(s * th) / sin
    quat[0], quat[1] = wa * a0 + wb * b0, wa * a1 + wb * b1
    quat[2], quat[3] = wa * a2 + wb * b2, wa * a3 + wb * b3


@njit
def hold_torque(efc_force: np.ndarray, hold_rows: np.ndarray, quat: np.ndarray, seg: float, out: np.ndarray):
    """Torque (N m, world, about the gripper's origin) of the holding constraints' forces (rows
    ``hold_rows`` of ``efc_force``, 3 per constraint): ``hold_0`` acts at the origin, ``hold_1`` one
    segment (``seg``, m) down ``-G_z`` (``G_z`` from the gripper's ``quat``, wxyz), so the torque is
    ``(-seg G_z) x F_1``; zero without ``hold_1``. The torsion taken by the twist lock
    (``hold_twist``) is not included."""
    if len(hold_rows) < 6:
        out[0], out[1], out[2] = 0.0, 0.0, 0.0
        return
    w, x, y, z = quat[0], quat[1], quat[2], quat[3]
    s = -seg  # lever = s * G_z, G_z the third column of R(q)
    rx, ry, rz = s * 2.0 * (x * z + w * y), s * 2.0 * (y * z - w * x), s * (1.0 - 2.0 * (x * x + y * y))
    fx, fy, fz = efc_force[hold_rows[3]], efc_force[hold_rows[4]], efc_force[hold_rows[5]]
    out[0], out[1], out[2] = ry * fz - rz * fy, rz * fx - rx * fz, rx * fy - ry * fx


@njit
def self_pairs(ncon: int, arena: np.ndarray, cfg: np.ndarray, out: np.ndarray) -> None:
    """The segment pairs (sorted) of the rod's self-contacts among MuJoCo's first ``ncon``."""
    k = 0
    ci, layout, flex = arena.view(np.int32), _config(cfg).layout, cfg[C_FLEX]
    si = layout[L_STRIDE_I]
    for i in range(ncon):
        bi = i * si
        if ci[bi + layout[L_FLEX]] == flex and ci[bi + layout[L_FLEX] + 1] == flex:
            a, b = ci[bi + layout[L_ELEM]], ci[bi + layout[L_ELEM] + 1]
            out[k, 0], out[k, 1] = min(a, b), max(a, b)
            k += 1


check_cache(__name__)
