"""Compiled per-step kernel of the contact tracker (:class:`dlovr.sim.tracker.ContactTracker`):
world frame, metres, newtons.

:func:`track_step` is one call per step: where each contact lies on the cable, the pairs to label
(merged with the touching ones), whether the last labels still hold (slack and budgets), labelling
the pairs or the moved points again when not (:func:`dlovr.geometry.kernels.pair_hits`), the touching
hits with hysteresis grouped by cable point (which points changed), and the normal forces per
contact span (:func:`span_forces`, also called alone when the situation changed).

The tracker's arrays are packed, with room to grow, to keep the call cheap (numba checks every
argument's type, and returning arrays costs more than passing them):

- labels ``lab_i`` (int64): header (``L_*``: pairs K, queried points Q, hits H, query points N), the
  queried pairs (K,2: query point, piece id), the queried points (Q), the hit rows (H, 4 + W: query
  point, piece id, within enter, within leave, face ids); ``lab_f`` (float64): where each query point
  was labelled (N,3), the queried points' squared slacks (Q), the pairs' budgets (K,6);
- work ``work_i`` (int64): header (``W_*``: counts, capacities and section offsets), the touching
  keys (cable point << 20 | piece id, sorted), the kept hits (cable point, face ids; in hit order),
  their face rows grouped by cable point and where each point's group starts, the points whose
  group changed when the kept hits last changed, the queried
  pairs, each query point's cable point (``owner``), each contact's cable point (``point_of``) and
  the points to label again; ``work_f`` (float64): the query points (cable points, then one per
  segment contact) and the forces per span.

Their layout lives here alone: :func:`new_work` and :func:`no_labels` make the arrays, :class:`Work`
(:func:`work_views`) and :class:`Labels` name their sections.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np

from dlovr.geometry.kernels import dot3, keeps, np_sum, pair_hits
from dlovr.jit import check_cache, njit
from dlovr.sim.kernels import T_FORCE, T_OBJ, T_PIECE, T_POINT, T_POS, T_SEGMENT

# track_step's outcome
KEPT, PARTIAL, FULL, GROW, BAD_PIECE = 0, 1, 2, 3, -1
_LOW = (1 << 20) - 1

# work_i header: counts, capacities, then section offsets (in work_i; the query points and forces in
# work_f), and the room asked for by GROW
W_TOUCH_N, W_CHANGED_N, W_POINTS, W_WIDTH, W_CAP_H, W_KEPT_N = 0, 1, 2, 3, 4, 5
W_TOUCH, W_KEPT, W_GROUP, W_START, W_CHANGED, W_PAIRS, W_OWNER, W_POINT_OF, W_AGAIN = range(6, 15)
W_QPTS, W_FORCES, W_NEED_H, W_NEED_I, W_NEED_F, W_AGAIN_N, W_HEAD = range(15, 22)
# lab_i header
L_K, L_Q, L_H, L_N, L_HEAD = 0, 1, 2, 3, 4
# parameters (float64): radius, contact tolerance of the labels (leave), tangential tolerance, enter
# and leave distances
# and the least squared cosine of the angle by which an edge contact's DLO vector may turn (:func:`turned`)
P_RADIUS, P_TOL, P_TTOL, P_ENTER, P_LEAVE, P_COS2_TURN = 0, 1, 2, 3, 4, 5


class Work(NamedTuple):
    """The sections of the work arrays (views; see the module docstring): W the most faces of a hit,
    H the kept hits' room, N1 the cable points."""

    touching: np.ndarray  # (H,) the touching keys, cable point << 20 | piece id, sorted
    kept: np.ndarray  # (H, 1 + W) the kept hits: cable point, face ids
    group: np.ndarray  # (H, W) their face rows grouped by cable point
    start: np.ndarray  # (N1 + 1,) where each point's group starts
    changed: np.ndarray  # (N1,) the points whose group changed
    pairs: np.ndarray  # (K, 2) the queried pairs: query point, piece id
    owner: np.ndarray  # each query point's cable point
    point_of: np.ndarray  # each contact's cable point (-1 for none)
    again: np.ndarray  # the query points to label again
    qpts: np.ndarray  # (Q, 3) float: the query points
    forces: np.ndarray  # float: the forces per span


def work_views(work_i: np.ndarray, work_f: np.ndarray) -> Work:
    """The sections of the work arrays (called from kernels and from Python alike)."""
    n1, w, cap_h = work_i[W_POINTS], work_i[W_WIDTH], work_i[W_CAP_H]
    return Work(
        work_i[work_i[W_TOUCH] : work_i[W_TOUCH] + cap_h],
        work_i[work_i[W_KEPT] : work_i[W_GROUP]].reshape((cap_h, w + 1)),
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


_work = njit(work_views, inner=True)

# the work_i sections that last from step to step (copied over when the arrays grow)
_LASTING_COUNTS = (W_TOUCH_N, W_CHANGED_N, W_KEPT_N)


def new_work(
    n1: int, width: int, n_pieces: int, cap_c: int, cap_h: int, old: np.ndarray | None = None
) -> tuple[np.ndarray, np.ndarray]:
    """Work arrays (``work_i``, ``work_f``) for ``n1`` cable points, pieces of at most ``width``
    faces, ``n_pieces`` pieces, room for ``cap_c`` contacts and ``cap_h`` kept hits; from ``old``
    (the last ``work_i`` for the same points) the counts, touching keys and groups that last."""
    cap_q = n1 + cap_c
    cap_k = n1 * n_pieces + 2 * cap_c + cap_h
    sections = (W_TOUCH, W_KEPT, W_GROUP, W_START, W_CHANGED, W_PAIRS, W_OWNER, W_POINT_OF, W_AGAIN)
    sizes = (cap_h, cap_h * (width + 1), cap_h * width, n1 + 1, n1, 2 * cap_k, cap_q, cap_c, cap_q)
    offsets = np.cumsum((W_HEAD, *sizes))
    wi = np.zeros(int(offsets[-1]), np.int64)
    wi[[W_POINTS, W_WIDTH, W_CAP_H]] = n1, width, cap_h
    wi[list(sections)] = offsets[:-1]
    wi[W_QPTS], wi[W_FORCES] = 0, 3 * cap_q
    if old is not None:
        for slot in _LASTING_COUNTS:
            wi[slot] = old[slot]
        old_h = old[W_CAP_H]
        for sec, n in ((W_TOUCH, old_h), (W_KEPT, old_h * (width + 1)), (W_GROUP, old_h * width),
                       (W_START, n1 + 1)):
            wi[wi[sec] : wi[sec] + n] = old[old[sec] : old[sec] + n]
    return wi, np.zeros(3 * cap_q + 2 * n1 + 8)


class Labels(NamedTuple):
    """The sections of the label arrays (views; see the module docstring): K pairs, Q queried points,
    H hit rows, N query points, W the most faces of a hit."""

    pairs: np.ndarray  # (K, 2) the labelled pairs: query point, piece id
    queried: np.ndarray  # (Q,) the queried points
    hits: np.ndarray  # (H, 4 + W) query point, piece id, within enter, within leave, face ids
    points: np.ndarray  # (N, 3) float: where each query point was labelled
    slack2: np.ndarray  # (Q,) float: the queried points' squared slacks
    budgets: np.ndarray  # (K, 6) float: the pairs' budgets


def no_labels() -> tuple[np.ndarray, np.ndarray]:
    """Label arrays (``lab_i``, ``lab_f``) that hold no labels (an empty header)."""
    return np.full(64, -1, np.int64), np.zeros(64)


@njit(inner=True)
def _labels(lab_i: np.ndarray, lab_f: np.ndarray, width: int) -> Labels:
    k, q, h, n = lab_i[L_K], lab_i[L_Q], lab_i[L_H], lab_i[L_N]
    a, b = L_HEAD + 2 * k, L_HEAD + 2 * k + q
    return Labels(
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
    spans: np.ndarray,
    edges: np.ndarray,
    edge_ref: np.ndarray,
    reuse: bool,
    gf: np.ndarray,
    gi: np.ndarray,
    params: np.ndarray,
    lab_i: np.ndarray,
    lab_f: np.ndarray,
    work_i: np.ndarray,
    work_f: np.ndarray,
):
    """One step of the tracker: its touching hits and the forces on ``spans``.

    From the cable ``pts`` and the contact ``table``: each contact's cable point (its vertex, or the
    nearer end of its segment; -1 for none), the queried pairs (query point, piece id; the reported
    pairs and the touching ones, unique and sorted, then one per segment contact at its centerline
    point) with their query points and owner cable points. Without ``has_arrays`` every point is
    queried against every piece (``gi`` holds their number).

    The last labels (``lab_*``; an empty header for none) are kept when the same pairs are queried
    and every query point moved by less than its slack, or within its budgets; else every pair
    (``FULL``), or the pairs of the points that moved beyond (``PARTIAL``), are labelled again and
    spliced in. Then the hits are made with hysteresis (:func:`update_hits`) and the forces summed,
    and ``edges`` are checked against ``edge_ref`` (:func:`turned`).

    Returns (outcome, whether the kept hits changed, bad row, whether an edge turned, quiet):
    ``KEPT``/``PARTIAL``/``FULL``,
    ``GROW`` (the labels or the work arrays need the room in the work header's ``W_NEED_*``: grow
    them, keeping their contents, and call again; nothing was changed) or ``BAD_PIECE`` (row
    ``bad row`` of the table names a piece that ``piece_map`` lacks). ``quiet``: nothing touches,
    nothing is kept and the labels hold no pair, for these points: a next step with contact arrays
    but no contact, with ``reuse`` and no ``edges``, would keep it all (``KEPT``, nothing changed,
    no edge turned, only its unread forces set to 0), so the tracker skips the call then.
    """
    w = _work(work_i, work_f)
    touching, pairs, owner, point_of, again, qpts = w.touching, w.pairs, w.owner, w.point_of, w.again, w.qpts
    width, n_pieces = work_i[W_WIDTH], gi[0]
    n1 = pts.shape[0]
    k = np.int64(0)  # not a literal: a literal would compile the callees twice
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
        width_map = piece_map.shape[1]
        keys = np.empty(nc + nt, np.int64)
        nk = 0
        for i in range(nc):
            obj, piece = int(table[i, T_OBJ]), int(table[i, T_PIECE])
            if not (0 <= obj < piece_map.shape[0] and 0 <= piece < width_map) or piece_map[obj, piece] < 0:
                return BAD_PIECE, False, i, False, False
            point, seg = int(table[i, T_POINT]), int(table[i, T_SEGMENT])
            if point < 0 and seg >= 0:  # on a segment: the contact projected onto it
                ax, ay, az = pts[seg, 0], pts[seg, 1], pts[seg, 2]
                abx, aby, abz = pts[seg + 1, 0] - ax, pts[seg + 1, 1] - ay, pts[seg + 1, 2] - az
                px, py, pz = table[i, T_POS], table[i, T_POS + 1], table[i, T_POS + 2]
                den = max(dot3(abx, aby, abz, abx, aby, abz), 1e-18)
                t = dot3(px - ax, py - ay, pz - az, abx, aby, abz) / den
                t = min(max(t, 0.0), 1.0)
                point = seg if t < 0.5 else seg + 1
                qpts[nq, 0], qpts[nq, 1], qpts[nq, 2] = ax + t * abx, ay + t * aby, az + t * abz
                owner[nq] = point
                nq += 1
            point_of[i] = point
            if point >= 0:
                keys[nk] = (point << 20) | piece_map[obj, piece]
                nk += 1
        for j in range(nt):
            keys[nk + j] = touching[j]
        _sort_keys(keys, nk + nt, n1)
        for j in range(nk + nt):
            if j == 0 or keys[j] != keys[j - 1]:
                pairs[k, 0], pairs[k, 1] = keys[j] >> 20, keys[j] & _LOW
                k += 1
        nb = 0
        for i in range(nc):  # the segment contacts' own pairs, after the others
            if int(table[i, T_POINT]) < 0 and int(table[i, T_SEGMENT]) >= 0:
                pairs[k, 0], pairs[k, 1] = n1 + nb, piece_map[int(table[i, T_OBJ]), int(table[i, T_PIECE])]
                k += 1
                nb += 1
    outcome = _outcome(reuse, k, nq, lab_i, lab_f, work_i, pairs, qpts, again)
    if outcome == FULL or outcome == PARTIAL:
        if not _relabel(outcome == FULL, k, nq, n_pieces, gf, gi, params, lab_i, lab_f, work_i, work_f):
            return GROW, False, -1, False, False
    changed = update_hits(_labels(lab_i, lab_f, width).hits, work_i, work_f)
    span_forces(spans, point_of, table, w.forces)
    quiet = work_i[W_TOUCH_N] == 0 and work_i[W_KEPT_N] == 0 and lab_i[L_K] == 0 and lab_i[L_N] == n1
    return outcome, changed, -1, turned(pts, edges, edge_ref, params[P_COS2_TURN]), quiet


@njit(inner=True)
def turned(pts: np.ndarray, edges: np.ndarray, ref: np.ndarray, cos2: float) -> bool:
    """Has the DLO vector of an edge contact turned by more than the angle whose squared cosine is
    ``cos2`` since its situation was made? ``edges`` rows: the two cable points whose difference is
    the vector; ``ref``: the cable's points when the situation was made (its vectors ``v`` are
    theirs). The sums of ``dlovr.transforms.dot`` written out, in its order (as the tracker's Python
    did before)."""
    for e in range(edges.shape[0]):
        ia, ib = edges[e, 0], edges[e, 1]
        d0, d1, d2 = pts[ib, 0] - pts[ia, 0], pts[ib, 1] - pts[ia, 1], pts[ib, 2] - pts[ia, 2]
        v0, v1, v2 = ref[ib, 0] - ref[ia, 0], ref[ib, 1] - ref[ia, 1], ref[ib, 2] - ref[ia, 2]
        vv = v0 * v0 + v1 * v1 + v2 * v2
        dv = d0 * v0 + d1 * v1 + d2 * v2
        nn = (d0 * d0 + d1 * d1 + d2 * d2) * vv
        if nn <= 0.0 or dv < 0.0 or dv * dv < cos2 * nn:  # a zero's sign changes none of these
            return True
    return False


@njit(inner=True)
def _outcome(
    reuse: bool, k: int, nq: int, lab_i: np.ndarray, lab_f: np.ndarray, work_i: np.ndarray,
    pairs: np.ndarray, qpts: np.ndarray, again: np.ndarray,
) -> int:
    """KEPT when the last labels hold for the step's ``k`` pairs at its ``nq`` query points (the same
    pairs, every point within its slack or its budgets), PARTIAL with the points to label again in
    ``again`` (their number in the work header), or FULL."""
    if not (reuse and lab_i[L_K] >= 0 and k == lab_i[L_K] and nq == lab_i[L_N]):
        return FULL
    lab = _labels(lab_i, lab_f, work_i[W_WIDTH])
    lab_pairs, lab_q, lab_pts, lab_s2 = lab.pairs, lab.queried, lab.points, lab.slack2
    for j in range(k):
        if pairs[j, 0] != lab_pairs[j, 0] or pairs[j, 1] != lab_pairs[j, 1]:
            return FULL
    moved = np.zeros(nq, np.bool_)
    any_moved = False
    for m in range(lab_q.shape[0]):
        i = lab_q[m]
        dx, dy, dz = qpts[i, 0] - lab_pts[i, 0], qpts[i, 1] - lab_pts[i, 1], qpts[i, 2] - lab_pts[i, 2]
        if dot3(dx, dy, dz, dx, dy, dz) >= lab_s2[m]:
            moved[i] = True
            any_moved = True
    if not any_moved:
        return KEPT
    # beyond its slack in some direction: within its budgets along and across its faces?
    redo = np.zeros(nq, np.bool_)
    for j in range(k):
        i = pairs[j, 0]
        if moved[i]:
            mx, my, mz = qpts[i, 0] - lab_pts[i, 0], qpts[i, 1] - lab_pts[i, 1], qpts[i, 2] - lab_pts[i, 2]
            if not keeps(lab.budgets, j, mx, my, mz):
                redo[i] = True
    n_again = 0
    for i in range(nq):
        if redo[i]:
            again[n_again] = i
            n_again += 1
    work_i[W_AGAIN_N] = n_again
    return PARTIAL if n_again else KEPT


@njit(inner=True, inline=True)  # one caller; its own module would compile pair_hits once more
def _relabel(
    full: bool, k: int, nq: int, n_pieces: int, gf: np.ndarray, gi: np.ndarray,
    params: np.ndarray, lab_i: np.ndarray, lab_f: np.ndarray, work_i: np.ndarray, work_f: np.ndarray,
) -> bool:
    """Label every queried pair (``full``) or the pairs of the points to label again (a point's
    labels depend on it alone) and splice them into the labels, in place; False (nothing changed)
    when the labels or the work arrays lack room (the room needed goes into the work header)."""
    w = _work(work_i, work_f)
    pairs, again, qpts = w.pairs, w.again, w.qpts
    width = work_i[W_WIDTH]
    redo = np.zeros(nq, np.bool_)
    if full:
        for i in range(nq):
            redo[i] = True
    else:
        for i in again[: work_i[W_AGAIN_N]]:
            redo[i] = True
    n_sub = 0
    for j in range(k):
        if redo[pairs[j, 0]]:
            n_sub += 1
    pi, pc = np.empty(n_sub, np.int64), np.empty(n_sub, np.int64)
    sub = np.empty(n_sub, np.int64)
    s = 0
    for j in range(k):
        if redo[pairs[j, 0]]:
            pi[s], pc[s], sub[s] = pairs[j, 0], pairs[j, 1], j
            s += 1
    # room: the new hits at most one per pair plus one per piece for each point labelled again
    n_redo = 0
    for i in range(nq):
        if redo[i]:
            n_redo += 1
    cap = n_sub + min(n_redo, n_sub) * n_pieces
    h_old = 0 if full else lab_i[L_H]
    q_n = k if full else lab_i[L_Q]
    need_i = L_HEAD + 3 * k + (h_old + cap) * (4 + width)
    need_f = 3 * nq + q_n + 6 * k
    if need_i > lab_i.shape[0] or need_f > lab_f.shape[0] or h_old + cap > work_i[W_CAP_H]:
        work_i[W_NEED_I], work_i[W_NEED_F], work_i[W_NEED_H] = need_i, need_f, h_old + cap
        return False
    hit_i = np.empty((cap, 2 + width), np.int64)
    hit_f = np.empty((cap, 4))
    slack = np.empty(nq)
    budgets = np.empty((n_sub, 6))
    qp = qpts[:nq].copy()  # arguments of the types the geometry passes (one compiled pair_hits)
    enter, leave = params[P_ENTER], params[P_LEAVE]
    thresholds = np.empty(2)
    thresholds[0], thresholds[1] = enter, leave
    yes = k >= 0  # True, as a value: literal flags would compile another pair_hits than Python calls
    h = pair_hits(
        gf, gi, qp, pi, pc, params[P_RADIUS], params[P_RADIUS], params[P_TOL], params[P_TTOL], thresholds,
        yes, not yes, hit_i, hit_f, slack, budgets,
    )
    if full:
        _store_labels(k, nq, pairs, pi, qp, hit_i, hit_f, h, slack, budgets, lab_i, lab_f, width, thresholds)
    else:
        _splice_labels(redo, sub, qpts, hit_i, hit_f, h, slack, budgets, lab_i, lab_f, width, thresholds)
    return True


@njit(inner=True)
def _store_labels(
    k: int, nq: int, pairs: np.ndarray, pi: np.ndarray, qp: np.ndarray, hit_i: np.ndarray,
    hit_f: np.ndarray, h: int, slack: np.ndarray, budgets: np.ndarray, lab_i: np.ndarray,
    lab_f: np.ndarray, width: int, thresholds: np.ndarray,
) -> None:
    """The labels of every queried pair: the ``k`` pairs at the ``nq`` query points ``qp``, the
    ``h`` hits of :func:`pair_hits` (``hit_*``), the query points' slacks and the pairs' budgets
    (``thresholds``: the enter and the leave distance)."""
    enter, leave = thresholds[0], thresholds[1]
    q = _unique(pi)
    lab_i[L_K], lab_i[L_Q], lab_i[L_H], lab_i[L_N] = k, q.shape[0], h, nq
    lab = _labels(lab_i, lab_f, width)
    for j in range(k):
        lab.pairs[j, 0], lab.pairs[j, 1] = pairs[j, 0], pairs[j, 1]
        for c in range(6):
            lab.budgets[j, c] = budgets[j, c]
    for i in range(nq):
        lab.points[i, 0], lab.points[i, 1], lab.points[i, 2] = qp[i, 0], qp[i, 1], qp[i, 2]
    for m in range(q.shape[0]):
        lab.queried[m] = q[m]
        lab.slack2[m] = slack[q[m]] * slack[q[m]]
    for r in range(h):
        _hit_row(lab.hits, r, hit_i, r, hit_f[r, 0], enter, leave)


@njit(inner=True)
def _splice_labels(
    redo: np.ndarray, sub: np.ndarray, qpts: np.ndarray, hit_i: np.ndarray, hit_f: np.ndarray, h: int,
    slack: np.ndarray, budgets: np.ndarray, lab_i: np.ndarray, lab_f: np.ndarray, width: int,
    thresholds: np.ndarray,
) -> None:
    """The labels of the query points in ``redo`` (labelled again: the pairs ``sub`` of the labels,
    at ``qpts``) spliced into the last labels: their budgets, points and slacks, and their ``h`` new
    hits merged with the others' kept ones (``thresholds``: the enter and the leave distance)."""
    enter, leave = thresholds[0], thresholds[1]
    lab = _labels(lab_i, lab_f, width)
    for s in range(sub.shape[0]):
        for c in range(6):
            lab.budgets[sub[s], c] = budgets[s, c]
    for i in range(redo.shape[0]):
        if redo[i]:
            lab.points[i, 0], lab.points[i, 1], lab.points[i, 2] = qpts[i, 0], qpts[i, 1], qpts[i, 2]
    for m in range(lab.queried.shape[0]):
        if redo[lab.queried[m]]:
            lab.slack2[m] = slack[lab.queried[m]] * slack[lab.queried[m]]
    merged = np.empty((lab.hits.shape[0] + h, lab.hits.shape[1]), np.int64)
    r = _merge_hits(lab.hits, redo, hit_i, hit_f, h, enter, leave, merged)
    lab_i[L_H] = r  # the hit rows start where they did: the new ones over the old
    hits = _labels(lab_i, lab_f, width).hits
    for i in range(r):
        for c in range(merged.shape[1]):
            hits[i, c] = merged[i, c]


@njit(inner=True)
def _merge_hits(
    old: np.ndarray, redo: np.ndarray, hit_i: np.ndarray, hit_f: np.ndarray, n_new: int, enter: float,
    leave: float, out: np.ndarray,
) -> int:
    """The label hit rows ``old`` of the points not in ``redo`` and the ``n_new`` new hits of
    :func:`pair_hits` (``hit_*``), merged into ``out`` by (query point, piece); returns their count.
    The old ones come first among equals (there are none: a point's hits are all old or all new)."""
    a, b, r = np.int64(0), np.int64(0), np.int64(0)  # not literals (see track_step)
    while a < old.shape[0] or b < n_new:
        if a < old.shape[0] and redo[old[a, 0]]:
            a += 1
            continue
        take_old = b >= n_new or (
            a < old.shape[0] and old[a, 0] * (1 << 20) + old[a, 1] <= hit_i[b, 0] * (1 << 20) + hit_i[b, 1]
        )
        if take_old:
            for c in range(old.shape[1]):
                out[r, c] = old[a, c]
            a += 1
        else:
            _hit_row(out, r, hit_i, b, hit_f[b, 0], enter, leave)
            b += 1
        r += 1
    return int(r)


@njit(inner=True)
def _hit_row(
    rows: np.ndarray, r: int, hits: np.ndarray, b: int, dist: float, enter: float, leave: float
) -> None:
    """Label hit row ``r`` from :func:`pair_hits` row ``b``: query point, piece id, within the enter
    and the leave distance, face ids."""
    rows[r, 0], rows[r, 1] = hits[b, 0], hits[b, 1]
    rows[r, 2] = 1 if dist <= enter else 0
    rows[r, 3] = 1 if dist <= leave else 0
    for c in range(2, hits.shape[1]):
        rows[r, c + 2] = hits[b, c]


@njit(inner=True)
def update_hits(hits: np.ndarray, work_i: np.ndarray, work_f: np.ndarray) -> bool:
    """The labelled pairs that touch, with hysteresis: a hit within the enter distance touches, one
    within the leave distance keeps touching if it touched. Hit rows: query point, piece id, within
    enter, within leave, face ids. Updates the touching keys and the kept hits (cable point, face
    ids; in hit order) and returns whether those changed; then also their face rows grouped by cable
    point and the list of points whose group changed."""
    w = _work(work_i, work_f)
    touching, kept, group, start, changed, owner = w.touching, w.kept, w.group, w.start, w.changed, w.owner
    n1 = start.shape[0] - 1
    h, w = hits.shape[0], group.shape[1]
    nt, n_old = work_i[W_TOUCH_N], work_i[W_KEPT_N]
    new = np.empty((h, w + 1), np.int64)
    keys = np.empty(h, np.int64)
    n_keep = np.int64(0)
    for r in range(h):
        point = owner[hits[r, 0]]
        key = (point << 20) | hits[r, 1]
        keep = hits[r, 2] != 0
        if not keep and hits[r, 3] != 0:  # between the distances: touching if it touched
            keep = _contains(touching, nt, key)
        if keep:
            new[n_keep, 0] = point
            for c in range(w):
                new[n_keep, c + 1] = hits[r, c + 4]
            keys[n_keep] = key
            n_keep += 1
    _sort(keys, n_keep)
    nt = 0
    for j in range(n_keep):
        if j == 0 or keys[j] != keys[j - 1]:
            touching[nt] = keys[j]
            nt += 1
    work_i[W_TOUCH_N] = nt
    same = n_keep == n_old
    for r in range(n_keep if same else 0):
        for c in range(w + 1):
            if new[r, c] != kept[r, c]:
                same = False
    if same:
        return False
    # grouped by cable point, in hit order: the points whose group differs from the last one
    count = np.zeros(n1 + 1, np.int64)
    for r in range(n_keep):
        count[new[r, 0] + 1] += 1
    for p in range(n1):
        count[p + 1] += count[p]
    fill = count[:n1].copy()
    grouped = np.empty((n_keep, w), np.int64)
    for r in range(n_keep):
        p = new[r, 0]
        for c in range(w):
            grouped[fill[p], c] = new[r, c + 1]
        fill[p] += 1
    n_changed = 0
    for p in range(n1):
        differs = count[p + 1] - count[p] != start[p + 1] - start[p]
        for a in range(0 if differs else count[p + 1] - count[p]):
            for c in range(w):
                if grouped[count[p] + a, c] != group[start[p] + a, c]:
                    differs = True
        if differs:
            changed[n_changed] = p
            n_changed += 1
    for r in range(n_keep):
        for c in range(w):
            group[r, c] = grouped[r, c]
        for c in range(w + 1):
            kept[r, c] = new[r, c]
    for p in range(n1 + 1):
        start[p] = count[p]
    work_i[W_KEPT_N] = n_keep
    work_i[W_CHANGED_N] = n_changed
    return True


@njit(inner=True)
def _sort(a: np.ndarray, n: int) -> None:
    """Sort ``a[:n]`` in place (an insertion sort: the keys here come nearly sorted and few)."""
    for i in range(1, n):
        v = a[i]
        j = i
        while j > 0 and a[j - 1] > v:
            a[j] = a[j - 1]
            j -= 1
        a[j] = v


@njit(inner=True)
def _sort_keys(keys: np.ndarray, n: int, n_points: int) -> None:
    """Sort ``keys[:n]`` (cable point << 20 | piece id, points below ``n_points``) in place: a
    counting sort by point, then by piece within each point."""
    count = np.zeros(n_points + 1, np.int64)
    for j in range(n):
        count[(keys[j] >> 20) + 1] += 1
    for p in range(n_points):
        count[p + 1] += count[p]
    out = np.empty(n, np.int64)
    for j in range(n):
        p = keys[j] >> 20
        out[count[p]] = keys[j]
        count[p] += 1
    for j in range(n):
        keys[j] = out[j]
    _sort(keys, n)  # now only pieces of one point out of order: an insertion sort finishes it


@njit(inner=True)
def _contains(sorted_a: np.ndarray, n: int, v: int) -> bool:
    """Whether ``v`` is among ``sorted_a[:n]`` (a binary search)."""
    lo, hi = 0, n
    while lo < hi:
        mid = (lo + hi) // 2
        if sorted_a[mid] < v:
            lo = mid + 1
        else:
            hi = mid
    return lo < n and sorted_a[lo] == v


@njit(inner=True)
def _unique(a: np.ndarray) -> np.ndarray:
    """The sorted distinct values of ``a``."""
    b = a.copy()
    _sort(b, b.shape[0])
    n = 0
    for i in range(b.shape[0]):
        if i == 0 or b[i] != b[n - 1]:
            b[n] = b[i]
            n += 1
    return b[:n]


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


check_cache(__name__)
