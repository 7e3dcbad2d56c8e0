"""Compiled per-step kernels of the simulator and the contact tracker (world frame, metres, newtons).

- :func:`step_record`: after ``mj_step``, the divergence checks and the step's record arrays (cable
  points, the raw rod-obstacle contacts with their normal forces, the gripper force) in one call,
  reading MuJoCo's contact structs in place (:func:`dlovr.sim.contacts.contact_layout`).
- :func:`track_step`: the tracker's common step: where each contact lies on the cable, the pairs to
  label (merged with the touching ones), whether the last labels still hold (slack and budgets) and
  the touching hits with hysteresis. :func:`relabel_full` / :func:`relabel_partial` label the pairs
  or the moved points again (through :func:`dlovr.geometry.kernels.pair_hits`), :func:`update_hits`
  applies the hysteresis, :func:`span_forces` sums the normal forces per contact span.

Contact rows (``table``, (n, 14) float64, ints held exactly): point, segment, geom, object, piece,
distance, normal (3, obstacle toward rod), position (3, MuJoCo's midway point), normal force, active
(0/1). See :class:`dlovr.sim.contacts.ContactArrays`.
"""

from __future__ import annotations

import numpy as np

from dlovr.geometry.kernels import dot3, keeps, np_sum, pair_hits
from dlovr.jit import njit

T_POINT, T_SEGMENT, T_GEOM, T_OBJ, T_PIECE, T_DIST = 0, 1, 2, 3, 4, 5
T_NORMAL, T_POS, T_FORCE, T_ACTIVE, T_WIDTH = 6, 9, 12, 13, 14

# layout of MuJoCo's contact structs (see dlovr.sim.contacts.contact_layout): float64 units, then int32
L_STRIDE_F, L_DIST, L_POS, L_FRAME, L_STRIDE_I, L_DIM, L_GEOM, L_FLEX, L_ELEM, L_VERT, L_EFC = range(11)

# track_step's outcome
REUSED, CHANGED, FULL, PARTIAL, BAD_PIECE = 0, 1, 2, 3, -1
_LOW = (1 << 20) - 1


# --------------------------------------------------------------------------------------------------
# simulator


@njit
def step_record(
    xpos: np.ndarray,
    qpos: np.ndarray,
    qvel: np.ndarray,
    warn: np.ndarray,
    fatal: np.ndarray,
    warn_base: int,
    bounds: np.ndarray,
    ncon: int,
    cf: np.ndarray,
    ci: np.ndarray,
    layout: np.ndarray,
    efc_force: np.ndarray,
    flex: int,
    piece_of_geom: np.ndarray,
    obj_of_geom: np.ndarray,
    pyramidal: bool,
    hold_rows: np.ndarray,
    pts: np.ndarray,
    table: np.ndarray,
    grip: np.ndarray,
):
    """The step's record arrays, and the divergence checks.

    Fills ``pts`` (the cable points from ``xpos``), the rows of ``table`` (one per rod-obstacle
    contact among MuJoCo's first ``ncon``, in MuJoCo's order) and ``grip`` (the force of the holding
    constraints' rows ``hold_rows`` of ``efc_force``, summed per axis). ``bounds``: squared segment
    length bounds (lo, hi), the segment length and the largest relative stretch.

    Returns (code, index, value, rows, self pairs): code 0, or the first failed check: 1 the count
    of the ``fatal`` warnings differs from ``warn_base``, 2 NaN/inf in qpos or qvel, 3 in the cable
    points, 4 segment ``index`` stretched by ``value`` (relative) beyond the largest stretch.
    """
    code, index, value = 0, -1, 0.0
    count = 0
    for w in fatal:
        count += warn[w]
    if count != warn_base:
        code = 1
    if code == 0:
        for x in qpos:
            if not np.isfinite(x):
                code = 2
        for x in qvel:
            if not np.isfinite(x):
                code = 2
    n1 = xpos.shape[0]
    for i in range(n1):
        for c in range(3):
            pts[i, c] = xpos[i, c]
            if code == 0 and not np.isfinite(pts[i, c]):
                code = 3
    if code == 0:
        lo, hi, seg, max_stretch = bounds[0], bounds[1], bounds[2], bounds[3]
        out = False
        for i in range(n1 - 1):
            dx, dy, dz = pts[i + 1, 0] - pts[i, 0], pts[i + 1, 1] - pts[i, 1], pts[i + 1, 2] - pts[i, 2]
            d2 = dot3(dx, dy, dz, dx, dy, dz)
            out = out or d2 < lo or d2 > hi
        if out:  # rare: the exact test, naming the segment
            for i in range(n1 - 1):
                dx, dy, dz = pts[i + 1, 0] - pts[i, 0], pts[i + 1, 1] - pts[i, 1], pts[i + 1, 2] - pts[i, 2]
                dev = abs(np.sqrt(dot3(dx, dy, dz, dx, dy, dz)) / seg - 1.0)
                if dev > value or index < 0:
                    index, value = i, dev
            if value > max_stretch:
                code = 4
    for c in range(3):
        s = 0.0
        for r in range(c, hold_rows.shape[0], 3):
            s += efc_force[hold_rows[r]]
        grip[c] = 0.0 + s
    rows, nself = 0, 0
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
                force = np_sum(efc_force[adr : adr + 2 * (dim - 1)])
            else:
                force = efc_force[adr]
        t[T_FORCE] = force
        t[T_ACTIVE] = 1.0 if adr >= 0 else 0.0
        rows += 1
    return code, index, value, rows, nself


@njit
def self_pairs(ncon: int, ci: np.ndarray, layout: np.ndarray, flex: int, out: np.ndarray) -> None:
    """The segment pairs (sorted) of the rod's self-contacts among MuJoCo's first ``ncon``."""
    k = 0
    si = layout[L_STRIDE_I]
    for i in range(ncon):
        bi = i * si
        if ci[bi + layout[L_FLEX]] == flex and ci[bi + layout[L_FLEX] + 1] == flex:
            a, b = ci[bi + layout[L_ELEM]], ci[bi + layout[L_ELEM] + 1]
            out[k, 0], out[k, 1] = min(a, b), max(a, b)
            k += 1


# --------------------------------------------------------------------------------------------------
# tracker: the common step


@njit
def track_step(
    pts: np.ndarray,
    table: np.ndarray,
    has_arrays: bool,
    piece_map: np.ndarray,
    n_pieces: int,
    reuse: bool,
    have_labels: bool,
    lab_pairs: np.ndarray,
    lab_pts: np.ndarray,
    lab_q: np.ndarray,
    lab_s2: np.ndarray,
    lab_budgets: np.ndarray,
    lab_hits: np.ndarray,
    state: np.ndarray,
    touching: np.ndarray,
    emitted: np.ndarray,
    pairs: np.ndarray,
    owner: np.ndarray,
    qpts: np.ndarray,
    point_of: np.ndarray,
    again: np.ndarray,
):
    """One step of the tracker up to its touching hits.

    From the cable ``pts`` and the contact ``table``: ``point_of`` (each contact's cable point: its
    vertex, or the nearer end of its segment; -1 for none), the queried ``pairs`` (query point, piece
    id; the reported pairs and the touching ones, unique and sorted, then one per segment contact at
    its centerline point) with their query points ``qpts`` and ``owner`` cable points. Without
    ``has_arrays`` every point is queried against every piece.

    The last labels (``lab_*``, ``have_labels``) are kept when the same pairs are queried and every
    query point moved by less than its slack, or within its budgets; then the hits are made with
    hysteresis (:func:`update_hits`). Returns (outcome, pairs, query points, points to label again,
    bad row): ``REUSED``/``CHANGED`` (the kept hits changed), ``FULL`` (label every pair again),
    ``PARTIAL`` (label the points in ``again`` again), ``BAD_PIECE`` (row ``bad row`` names a piece
    that ``piece_map`` lacks).
    """
    n1 = pts.shape[0]
    k = 0
    nq = n1
    for i in range(n1):
        owner[i] = i
        qpts[i, 0], qpts[i, 1], qpts[i, 2] = pts[i, 0], pts[i, 1], pts[i, 2]
    if not has_arrays:
        for i in range(n1):
            for c in range(n_pieces):
                pairs[k, 0], pairs[k, 1] = i, c
                k += 1
    else:
        nc = table.shape[0]
        width = piece_map.shape[1]
        keys = np.empty(nc + state[0], np.int64)
        nk = 0
        for i in range(nc):
            obj, piece = int(table[i, T_OBJ]), int(table[i, T_PIECE])
            if obj < 0 or obj >= piece_map.shape[0] or piece < 0 or piece >= width:
                return BAD_PIECE, 0, 0, 0, i
            pid = piece_map[obj, piece]
            if pid < 0:
                return BAD_PIECE, 0, 0, 0, i
            point, seg = int(table[i, T_POINT]), int(table[i, T_SEGMENT])
            if point < 0 and seg >= 0:  # on a segment: the contact projected onto it
                a, b = pts[seg], pts[seg + 1]
                abx, aby, abz = b[0] - a[0], b[1] - a[1], b[2] - a[2]
                p = table[i, T_POS : T_POS + 3]
                t = dot3(p[0] - a[0], p[1] - a[1], p[2] - a[2], abx, aby, abz) / max(
                    dot3(abx, aby, abz, abx, aby, abz), 1e-18
                )
                t = min(max(t, 0.0), 1.0)
                point = seg if t < 0.5 else seg + 1
                qpts[nq, 0], qpts[nq, 1], qpts[nq, 2] = a[0] + t * abx, a[1] + t * aby, a[2] + t * abz
                owner[nq] = point
                nq += 1
            point_of[i] = point
            if point >= 0:
                keys[nk] = (point << 20) | pid
                nk += 1
        for j in range(state[0]):
            keys[nk + j] = touching[j]
        keys = np.sort(keys[: nk + state[0]])
        for j in range(keys.shape[0]):
            if j == 0 or keys[j] != keys[j - 1]:
                pairs[k, 0], pairs[k, 1] = keys[j] >> 20, keys[j] & _LOW
                k += 1
        nb = 0
        for i in range(nc):  # the segment contacts' own pairs, after the others
            if int(table[i, T_POINT]) < 0 and int(table[i, T_SEGMENT]) >= 0:
                obj, piece = int(table[i, T_OBJ]), int(table[i, T_PIECE])
                pairs[k, 0], pairs[k, 1] = n1 + nb, piece_map[obj, piece]
                k += 1
                nb += 1
    # the last labels, if the same pairs are queried and their points stayed within their slack
    if not (have_labels and reuse and k == lab_pairs.shape[0] and nq == lab_pts.shape[0]):
        return FULL, k, nq, 0, -1
    for j in range(k):
        if pairs[j, 0] != lab_pairs[j, 0] or pairs[j, 1] != lab_pairs[j, 1]:
            return FULL, k, nq, 0, -1
    n_again = 0
    moved = np.zeros(nq, np.bool_)
    any_moved = False
    for m in range(lab_q.shape[0]):
        i = lab_q[m]
        dx, dy, dz = qpts[i, 0] - lab_pts[i, 0], qpts[i, 1] - lab_pts[i, 1], qpts[i, 2] - lab_pts[i, 2]
        if dot3(dx, dy, dz, dx, dy, dz) >= lab_s2[m]:
            moved[i] = True
            any_moved = True
    if any_moved:  # beyond its slack in some direction: within its budgets along and across its faces?
        redo = np.zeros(nq, np.bool_)
        for j in range(k):
            i = pairs[j, 0]
            if moved[i]:
                m, o = qpts[i], lab_pts[i]
                if not keeps(lab_budgets[j], m[0] - o[0], m[1] - o[1], m[2] - o[2]):
                    redo[i] = True
        for i in range(nq):
            if redo[i]:
                again[n_again] = i
                n_again += 1
        if n_again:
            return PARTIAL, k, nq, n_again, -1
    changed = update_hits(lab_hits, owner, state, touching, emitted)
    return (CHANGED if changed else REUSED), k, nq, 0, -1


@njit
def update_hits(
    hits: np.ndarray, owner: np.ndarray, state: np.ndarray, touching: np.ndarray, emitted: np.ndarray
) -> bool:
    """The labelled pairs that touch, with hysteresis: a hit within the enter distance touches, one
    within the leave distance keeps touching if it touched. Hit rows: query point, piece id, within
    enter, within leave, face ids. Writes the touching keys (cable point << 20 | piece id, sorted;
    ``state[0]`` of them) and the kept hits (cable point, face ids; ``state[1]`` of them) into
    ``emitted``; returns whether those changed."""
    h = hits.shape[0]
    nt = state[0]
    keep_keys = np.empty(h, np.int64)
    n_keep = 0
    changed = False
    for r in range(h):
        point = owner[hits[r, 0]]
        key = (point << 20) | hits[r, 1]
        keep = hits[r, 2] != 0
        if not keep and hits[r, 3] != 0:  # between the distances: touching if it touched
            j = np.searchsorted(touching[:nt], key)
            keep = j < nt and touching[j] == key
        if keep:
            if n_keep >= state[1] or emitted[n_keep, 0] != point:
                changed = True
            else:
                for c in range(4, hits.shape[1]):
                    if emitted[n_keep, c - 3] != hits[r, c]:
                        changed = True
            emitted[n_keep, 0] = point
            emitted[n_keep, 1:] = hits[r, 4:]
            keep_keys[n_keep] = key
            n_keep += 1
    changed = changed or n_keep != state[1]
    state[1] = n_keep
    keep_keys = np.sort(keep_keys[:n_keep])
    nt = 0
    for j in range(n_keep):
        if j == 0 or keep_keys[j] != keep_keys[j - 1]:
            touching[nt] = keep_keys[j]
            nt += 1
    state[0] = nt
    return changed


# --------------------------------------------------------------------------------------------------
# tracker: labelling again


@njit
def relabel_full(
    gf: np.ndarray,
    gi: np.ndarray,
    width: int,
    radius: float,
    contact_tol: float,
    ttol: float,
    thresholds: np.ndarray,
    qpts: np.ndarray,
    pairs: np.ndarray,
):
    """Label every queried pair: (pairs, query points then, queried points, their squared slacks,
    budgets per pair, hit rows) for :func:`track_step` (hit rows as in :func:`update_hits`)."""
    pi, pc = pairs[:, 0].copy(), pairs[:, 1].copy()
    nq = qpts.shape[0]
    slack = np.empty(nq)
    budgets = np.empty((pi.shape[0], 6))
    hits = _label(gf, gi, width, radius, contact_tol, ttol, thresholds, qpts, pi, pc, slack, budgets)
    q = np.unique(pi)
    s2 = np.empty(q.shape[0])
    for m in range(q.shape[0]):
        s2[m] = slack[q[m]] * slack[q[m]]
    return pairs.copy(), qpts.copy(), q, s2, budgets, hits


@njit
def relabel_partial(
    gf: np.ndarray,
    gi: np.ndarray,
    width: int,
    radius: float,
    contact_tol: float,
    ttol: float,
    thresholds: np.ndarray,
    qpts: np.ndarray,
    pairs: np.ndarray,
    again: np.ndarray,
    lab_pts: np.ndarray,
    lab_q: np.ndarray,
    lab_s2: np.ndarray,
    lab_budgets: np.ndarray,
    lab_hits: np.ndarray,
) -> np.ndarray:
    """Label the query points ``again`` again (a point's labels depend on it alone) and splice
    them into the last labels: their points, slacks and budgets in place; returns the new hit rows."""
    nq = qpts.shape[0]
    redo = np.zeros(nq, np.bool_)
    for i in again:
        redo[i] = True
    rows = np.zeros(pairs.shape[0], np.bool_)
    for j in range(pairs.shape[0]):
        rows[j] = redo[pairs[j, 0]]
    sub = np.nonzero(rows)[0]
    pi, pc = pairs[sub, 0].copy(), pairs[sub, 1].copy()
    slack = np.empty(nq)
    budgets = np.empty((sub.shape[0], 6))
    new = _label(gf, gi, width, radius, contact_tol, ttol, thresholds, qpts, pi, pc, slack, budgets)
    for s in range(sub.shape[0]):
        lab_budgets[sub[s]] = budgets[s]
    for i in again:
        lab_pts[i] = qpts[i]
    for m in range(lab_q.shape[0]):
        if redo[lab_q[m]]:
            lab_s2[m] = slack[lab_q[m]] * slack[lab_q[m]]
    n_old = 0
    for r in range(lab_hits.shape[0]):
        if not redo[lab_hits[r, 0]]:
            n_old += 1
    out = np.empty((n_old + new.shape[0], lab_hits.shape[1]), np.int64)
    a = 0
    for r in range(lab_hits.shape[0]):
        if not redo[lab_hits[r, 0]]:
            out[a] = lab_hits[r]
            a += 1
    out[a:] = new
    keys = out[:, 0] * (1 << 20) + out[:, 1]
    return out[np.argsort(keys, kind="mergesort")]


@njit
def _label(
    gf: np.ndarray,
    gi: np.ndarray,
    width: int,
    radius: float,
    contact_tol: float,
    ttol: float,
    thresholds: np.ndarray,
    qpts: np.ndarray,
    pi: np.ndarray,
    pc: np.ndarray,
    slack: np.ndarray,
    budgets: np.ndarray,
) -> np.ndarray:
    """Hit rows (query point, piece id, within enter, within leave, face ids) of pairs ``pi``/``pc``."""
    n_pieces = gi[0]
    cap = pi.shape[0] + min(qpts.shape[0], pi.shape[0]) * n_pieces
    hit_i = np.empty((cap, 2 + width), np.int64)
    hit_f = np.empty((cap, 4))
    h = pair_hits(
        gf, gi, qpts, pi, pc, radius, contact_tol, ttol, thresholds, True, hit_i, hit_f, slack, budgets
    )
    out = np.empty((h, 4 + width), np.int64)
    for r in range(h):
        out[r, 0], out[r, 1] = hit_i[r, 0], hit_i[r, 1]
        out[r, 2] = 1 if hit_f[r, 0] <= thresholds[0] else 0
        out[r, 3] = 1 if hit_f[r, 0] <= thresholds[1] else 0
        out[r, 4:] = hit_i[r, 2:]
    return out


# --------------------------------------------------------------------------------------------------
# forces


@njit
def span_forces(spans: np.ndarray, point_of: np.ndarray, table: np.ndarray, out: np.ndarray) -> None:
    """Per contact span (first, last cable point; -1 for none), the summed normal force of the contacts
    whose cable point lies in it (summed as numpy sums: the same bits as before the kernels)."""
    n = table.shape[0]
    buf = np.empty(n)
    for c in range(spans.shape[0]):
        a, b = spans[c, 0], spans[c, 1]
        if a < 0 or n == 0:
            out[c] = 0.0
            continue
        m = 0
        for i in range(n):
            if a <= point_of[i] <= b:
                buf[m] = table[i, T_FORCE]
                m += 1
        out[c] = np_sum(buf[:m])
