"""Compiled per-step kernels of the contact tracker (:class:`dlovr.sim.tracker.ContactTracker`):
world frame, metres, newtons.

:func:`track_step` is the common step, one call: where each contact lies on the cable, the pairs to
label (merged with the touching ones), whether the last labels still hold (slack and budgets), the
touching hits with hysteresis grouped by cable point (which points changed), and the normal forces
per contact span. :func:`relabel_full` / :func:`relabel_partial` label the pairs or the moved points
again (through :func:`dlovr.geometry.kernels.pair_hits`); :func:`update_hits` and
:func:`span_forces` are also called alone after them.

The tracker's arrays are packed to keep the calls cheap (numba checks every argument's type):

- labels ``lab_i`` (int64): header (pairs K, queried points Q, hits H, query points N), the queried
  pairs (K,2: query point, piece id), the queried points (Q), the hit rows (H, 4 + W: query point,
  piece id, within enter, within leave, face ids); ``lab_f`` (float64): where each query point was
  labelled (N,3), the queried points' squared slacks (Q), the pairs' budgets (K,6);
- work ``work_i`` (int64): header (``W_*``: counts, capacities and section offsets), the touching
  keys (cable point << 20 | piece id, sorted), the kept hits' face rows grouped by cable point and
  where each point's group starts, the points whose group changed at the last step, the queried
  pairs, each query point's cable point (``owner``), each contact's cable point (``point_of``) and
  the points to label again; ``work_f`` (float64): the query points (cable points, then one per
  segment contact) and the forces per span.
"""

from __future__ import annotations

import numpy as np

from dlovr.geometry.kernels import dot3, keeps, np_sum, pair_hits
from dlovr.jit import njit
from dlovr.sim.kernels import T_FORCE, T_OBJ, T_PIECE, T_POINT, T_POS, T_SEGMENT

# track_step's outcome
REUSED, CHANGED, FULL, PARTIAL, BAD_PIECE = 0, 1, 2, 3, -1
_LOW = (1 << 20) - 1

# work_i header: counts, then section offsets (in work_i; qpts and forces in work_f)
W_TOUCH_N, W_KEPT_N, W_CHANGED_N, W_POINTS, W_WIDTH, W_CAP_H = 0, 1, 2, 3, 4, 5
W_TOUCH, W_GROUP, W_START, W_CHANGED, W_PAIRS, W_OWNER, W_POINT_OF, W_AGAIN = 6, 7, 8, 9, 10, 11, 12, 13
W_QPTS, W_FORCES, W_HEAD = 14, 15, 16
L_HEAD = 4


@njit
def _work(work_i: np.ndarray, work_f: np.ndarray):
    n1, w, cap_h = work_i[W_POINTS], work_i[W_WIDTH], work_i[W_CAP_H]
    return (
        work_i[work_i[W_TOUCH] : work_i[W_TOUCH] + cap_h],
        work_i[work_i[W_GROUP] : work_i[W_START]].reshape((cap_h, w)),
        work_i[work_i[W_START] : work_i[W_START] + n1 + 1],
        work_i[work_i[W_CHANGED] : work_i[W_CHANGED] + n1],
        work_i[work_i[W_PAIRS] : work_i[W_OWNER]].reshape((-1, 2)),
        work_i[work_i[W_OWNER] : work_i[W_POINT_OF]],
        work_i[work_i[W_POINT_OF] : work_i[W_AGAIN]],
        work_i[work_i[W_AGAIN] :],
        work_f[work_i[W_QPTS] : work_i[W_FORCES]].reshape((-1, 3)),
        work_f[work_i[W_FORCES] :],
    )


@njit
def _labels(lab_i: np.ndarray, lab_f: np.ndarray, width: int):
    k, q, h, n = lab_i[0], lab_i[1], lab_i[2], lab_i[3]
    a, b = L_HEAD + 2 * k, L_HEAD + 2 * k + q
    return (
        lab_i[L_HEAD:a].reshape((k, 2)),
        lab_i[a:b],
        lab_i[b : b + h * (4 + width)].reshape((h, 4 + width)),
        lab_f[: 3 * n].reshape((n, 3)),
        lab_f[3 * n : 3 * n + q],
        lab_f[3 * n + q : 3 * n + q + 6 * k].reshape((k, 6)),
    )


@njit
def track_step(
    pts: np.ndarray,
    table: np.ndarray,
    has_arrays: bool,
    piece_map: np.ndarray,
    n_pieces: int,
    spans: np.ndarray,
    reuse: bool,
    lab_i: np.ndarray,
    lab_f: np.ndarray,
    work_i: np.ndarray,
    work_f: np.ndarray,
):
    """One step of the tracker up to its touching hits and forces.

    From the cable ``pts`` and the contact ``table``: each contact's cable point (its vertex, or the
    nearer end of its segment; -1 for none), the queried pairs (query point, piece id; the reported
    pairs and the touching ones, unique and sorted, then one per segment contact at its centerline
    point) with their query points and owner cable points. Without ``has_arrays`` every point is
    queried against every piece.

    The last labels (``lab_*``; an empty ``lab_i`` for none) are kept when the same pairs are queried
    and every query point moved by less than its slack, or within its budgets; then the hits are
    made with hysteresis (:func:`update_hits`) and the forces summed over ``spans``
    (:func:`span_forces`). Returns (outcome, pairs, query points, points to label again, bad row):
    ``REUSED``/``CHANGED`` (the kept hits changed), ``FULL`` (label every pair again), ``PARTIAL``
    (label the points to label again), ``BAD_PIECE`` (row ``bad row`` names a piece that
    ``piece_map`` lacks).
    """
    touching, _, _, _, pairs, owner, point_of, again, qpts, forces = _work(work_i, work_f)
    n1 = pts.shape[0]
    k = 0
    nq = n1
    for i in range(n1):
        owner[i] = i
        qpts[i, 0], qpts[i, 1], qpts[i, 2] = pts[i, 0], pts[i, 1], pts[i, 2]
    nt = work_i[W_TOUCH_N]
    if not has_arrays:
        for i in range(n1):
            for c in range(n_pieces):
                pairs[k, 0], pairs[k, 1] = i, c
                k += 1
    else:
        nc = table.shape[0]
        width = piece_map.shape[1]
        keys = np.empty(nc + nt, np.int64)
        nk = 0
        for i in range(nc):
            obj, piece = int(table[i, T_OBJ]), int(table[i, T_PIECE])
            if not (0 <= obj < piece_map.shape[0] and 0 <= piece < width) or piece_map[obj, piece] < 0:
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
                keys[nk] = (point << 20) | piece_map[obj, piece]
                nk += 1
        keys[nk : nk + nt] = touching[:nt]
        keys = np.sort(keys[: nk + nt])
        for j in range(keys.shape[0]):
            if j == 0 or keys[j] != keys[j - 1]:
                pairs[k, 0], pairs[k, 1] = keys[j] >> 20, keys[j] & _LOW
                k += 1
        nb = 0
        for i in range(nc):  # the segment contacts' own pairs, after the others
            if int(table[i, T_POINT]) < 0 and int(table[i, T_SEGMENT]) >= 0:
                pairs[k, 0], pairs[k, 1] = n1 + nb, piece_map[int(table[i, T_OBJ]), int(table[i, T_PIECE])]
                k += 1
                nb += 1
    # the last labels, if the same pairs are queried and their points stayed within their slack
    if not (reuse and lab_i.shape[0] and k == lab_i[0] and nq == lab_i[3]):
        return FULL, k, nq, 0, -1
    lab_pairs, lab_q, lab_hits, lab_pts, lab_s2, lab_budgets = _labels(lab_i, lab_f, work_i[W_WIDTH])
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
    changed = update_hits(lab_hits, work_i, work_f)
    span_forces(spans, point_of, table, forces)
    return (CHANGED if changed else REUSED), k, nq, 0, -1


@njit
def update_hits(hits: np.ndarray, work_i: np.ndarray, work_f: np.ndarray) -> bool:
    """The labelled pairs that touch, with hysteresis: a hit within the enter distance touches, one
    within the leave distance keeps touching if it touched. Hit rows: query point, piece id, within
    enter, within leave, face ids. Updates the touching keys, the kept hits' face rows grouped by
    cable point (in hit order) and the list of points whose group changed; returns whether any did."""
    touching, group, start, changed, _, owner, _, _, _, _ = _work(work_i, work_f)
    n1 = start.shape[0] - 1
    h = hits.shape[0]
    nt = work_i[W_TOUCH_N]
    kept = np.zeros(h, np.bool_)
    count = np.zeros(n1 + 1, np.int64)
    keys = np.empty(h, np.int64)
    n_keep = 0
    for r in range(h):
        point = owner[hits[r, 0]]
        key = (point << 20) | hits[r, 1]
        keep = hits[r, 2] != 0
        if not keep and hits[r, 3] != 0:  # between the distances: touching if it touched
            j = np.searchsorted(touching[:nt], key)
            keep = j < nt and touching[j] == key
        if keep:
            kept[r] = True
            count[point + 1] += 1
            keys[n_keep] = key
            n_keep += 1
    for p in range(n1):
        count[p + 1] += count[p]
    new = np.empty((n_keep, group.shape[1]), np.int64)
    fill = count[:n1].copy()
    for r in range(h):
        if kept[r]:
            p = owner[hits[r, 0]]
            new[fill[p]] = hits[r, 4:]
            fill[p] += 1
    n_changed = 0
    for p in range(n1):
        same = count[p + 1] - count[p] == start[p + 1] - start[p]
        if same:
            for a in range(count[p + 1] - count[p]):
                for c in range(group.shape[1]):
                    if new[count[p] + a, c] != group[start[p] + a, c]:
                        same = False
        if not same:
            changed[n_changed] = p
            n_changed += 1
    group[:n_keep] = new
    start[:] = count
    work_i[W_CHANGED_N] = n_changed
    work_i[W_KEPT_N] = n_keep
    keys = np.sort(keys[:n_keep])
    nt = 0
    for j in range(n_keep):
        if j == 0 or keys[j] != keys[j - 1]:
            touching[nt] = keys[j]
            nt += 1
    work_i[W_TOUCH_N] = nt
    return n_changed > 0


# --------------------------------------------------------------------------------------------------
# labelling again


@njit
def relabel_full(
    gf: np.ndarray,
    gi: np.ndarray,
    width: int,
    radius: float,
    contact_tol: float,
    ttol: float,
    thresholds: np.ndarray,
    work_i: np.ndarray,
    work_f: np.ndarray,
    k: int,
    nq: int,
):
    """Label the step's ``k`` queried pairs at its ``nq`` query points: the new labels (``lab_i``,
    ``lab_f``; see the module docstring)."""
    _, _, _, _, pairs, _, _, _, qpts, _ = _work(work_i, work_f)
    pi, pc, qp = pairs[:k, 0].copy(), pairs[:k, 1].copy(), qpts[:nq]
    slack = np.empty(nq)
    budgets = np.empty((k, 6))
    hits = _label(gf, gi, width, radius, contact_tol, ttol, thresholds, qp, pi, pc, slack, budgets)
    q = np.unique(pi)
    lab_i = np.empty(L_HEAD + 2 * k + q.shape[0] + hits.size, np.int64)
    lab_i[0], lab_i[1], lab_i[2], lab_i[3] = k, q.shape[0], hits.shape[0], nq
    lab_i[L_HEAD : L_HEAD + 2 * k] = pairs[:k].ravel()
    lab_i[L_HEAD + 2 * k : L_HEAD + 2 * k + q.shape[0]] = q
    lab_i[L_HEAD + 2 * k + q.shape[0] :] = hits.ravel()
    lab_f = np.empty(3 * nq + q.shape[0] + 6 * k)
    lab_f[: 3 * nq] = qp.ravel()
    for m in range(q.shape[0]):
        lab_f[3 * nq + m] = slack[q[m]] * slack[q[m]]
    lab_f[3 * nq + q.shape[0] :] = budgets.ravel()
    return lab_i, lab_f


@njit
def relabel_partial(
    gf: np.ndarray,
    gi: np.ndarray,
    width: int,
    radius: float,
    contact_tol: float,
    ttol: float,
    thresholds: np.ndarray,
    work_i: np.ndarray,
    work_f: np.ndarray,
    k: int,
    nq: int,
    n_again: int,
    lab_i: np.ndarray,
    lab_f: np.ndarray,
) -> np.ndarray:
    """Label the points to label again (a point's labels depend on it alone) and splice them into
    the last labels: their points, slacks and budgets in ``lab_f`` in place; returns the new
    ``lab_i`` (its hit rows changed)."""
    _, _, _, _, pairs, _, _, again, qpts, _ = _work(work_i, work_f)
    _, lab_q, lab_hits, lab_pts, lab_s2, lab_budgets = _labels(lab_i, lab_f, width)
    redo = np.zeros(nq, np.bool_)
    for i in again[:n_again]:
        redo[i] = True
    rows = np.zeros(k, np.bool_)
    for j in range(k):
        rows[j] = redo[pairs[j, 0]]
    sub = np.nonzero(rows)[0]
    pi, pc = pairs[sub, 0].copy(), pairs[sub, 1].copy()
    slack = np.empty(nq)
    budgets = np.empty((sub.shape[0], 6))
    new = _label(gf, gi, width, radius, contact_tol, ttol, thresholds, qpts[:nq], pi, pc, slack, budgets)
    for s in range(sub.shape[0]):
        lab_budgets[sub[s]] = budgets[s]
    for i in again[:n_again]:
        lab_pts[i] = qpts[i]
    for m in range(lab_q.shape[0]):
        if redo[lab_q[m]]:
            lab_s2[m] = slack[lab_q[m]] * slack[lab_q[m]]
    n_old = 0
    for r in range(lab_hits.shape[0]):
        if not redo[lab_hits[r, 0]]:
            n_old += 1
    hits = np.empty((n_old + new.shape[0], lab_hits.shape[1]), np.int64)
    a = 0
    for r in range(lab_hits.shape[0]):
        if not redo[lab_hits[r, 0]]:
            hits[a] = lab_hits[r]
            a += 1
    hits[a:] = new
    hits = hits[np.argsort(hits[:, 0] * (1 << 20) + hits[:, 1], kind="mergesort")]
    head = L_HEAD + 2 * k + lab_q.shape[0]
    out = np.empty(head + hits.size, np.int64)
    out[:head] = lab_i[:head]
    out[2] = hits.shape[0]
    out[head:] = hits.ravel()
    return out


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


@njit
def after_relabel(
    lab_i: np.ndarray, lab_f: np.ndarray, work_i: np.ndarray, work_f: np.ndarray, spans: np.ndarray,
    table: np.ndarray,
) -> bool:  # fmt: skip
    """:func:`update_hits` and :func:`span_forces` on new labels (what :func:`track_step` does after
    keeping the last ones); returns whether the kept hits changed."""
    _, _, _, _, _, _, point_of, _, _, forces = _work(work_i, work_f)
    changed = update_hits(_labels(lab_i, lab_f, work_i[W_WIDTH])[2], work_i, work_f)
    span_forces(spans, point_of, table, forces)
    return changed
