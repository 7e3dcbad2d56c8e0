"""The demonstrated gripper track of a network edge, and tracks of several edges joined into one.

A network edge merges every occurrence of one transition; its mean displacement is a motion no
demonstration made (a turn about an edge averaged with a push is neither). So each edge also keeps
one occurrence's own commanded gripper track: the reference demonstration's where it took the edge
(:mod:`dlovr.model.network`), else the **representative** occurrence, the one whose world
displacement is nearest the median displacement of all of them (ties: the first). A network macro
follows the tracks of its edges one after the other, each repeated from where the previous ended
(:func:`join`), as a compiled program follows its demonstration's track.

Pure Python + numpy. Frames and units: world frame, metres, quaternions wxyz, seconds from the moment
the edge's source situation was entered.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from dlovr.model.program import PoseTrack
from dlovr.transforms import quat_mul, quat_normalize

#: Track samples are kept this far apart (s): the commanded track is smooth between waypoints.
SAMPLE_S = 0.01


@dataclass(frozen=True, eq=False)
class EdgeTrack:
    """One occurrence's commanded gripper poses from entering the edge's source (``t = 0``) to
    entering its target (``t[-1]``, s): positions (k, 3) m and quaternions (k, 4) wxyz, world frame;
    ``demonstration`` its index in the network's demonstrations and ``t0`` (s) where the stretch began
    in it."""

    demonstration: int
    t0: float
    t: np.ndarray
    pos: np.ndarray
    quat: np.ndarray

    def __eq__(self, other: object) -> bool:
        if not isinstance(other, EdgeTrack):
            return NotImplemented
        pairs = ((self.t, other.t), (self.pos, other.pos), (self.quat, other.quat))
        same = (self.demonstration, self.t0) == (other.demonstration, other.t0)
        return same and all(np.array_equal(a, b) for a, b in pairs)

    # unhashable: a class that defines __eq__ alone gets __hash__ = None (and eq=False keeps it)

    def to_json(self) -> dict[str, Any]:
        """Written as stored: :func:`stretch` rounds to what JSON keeps, so a round trip is exact."""
        return {
            "demonstration": self.demonstration,
            "t0": self.t0,
            "t": self.t.tolist(),
            "pos": self.pos.tolist(),
            "quat": self.quat.tolist(),
        }

    @staticmethod
    def from_json(d: Mapping[str, Any]) -> EdgeTrack:
        """Raises ``ValueError``/``KeyError``/``TypeError`` on a bad one (the network reader words it)."""
        t = np.array(d["t"], dtype=float)
        pos, quat = np.array(d["pos"], dtype=float), np.array(d["quat"], dtype=float)
        if t.ndim != 1 or len(t) == 0 or pos.shape != (len(t), 3) or quat.shape != (len(t), 4):
            raise ValueError("edge track needs t (k,), pos (k, 3), quat (k, 4) with k >= 1")
        if np.any(np.diff(t) < 0) or not (np.all(np.isfinite(pos)) and np.all(np.isfinite(quat))):
            raise ValueError("edge track times must not decrease and its poses must be finite")
        return EdgeTrack(int(d["demonstration"]), float(d["t0"]), t, pos, quat)


def stretch(commands: PoseTrack, demonstration: int, t0: float, t1: float) -> EdgeTrack:
    """The commanded poses of ``commands`` from ``t0`` to ``t1`` (s), one every :data:`SAMPLE_S`
    and the last at ``t1`` (each the last command at or before its time); rounded to 1 µs, 0.1 µm
    and 1e-8, as written to JSON."""
    n = max(int(np.floor((t1 - t0) / SAMPLE_S + 1e-9)), 0)
    times = [t0 + k * SAMPLE_S for k in range(n + 1)]
    if times[-1] < t1 - 1e-9:
        times.append(t1)
    pos, quat = zip(*(commands.at(t) for t in times), strict=True)
    rel = np.round(np.array(times) - t0, 6)
    return EdgeTrack(demonstration, round(float(t0), 6), rel, np.round(np.array(pos, float), 7),
                     np.round(np.array(quat, float), 8))


def representative(displacements: Sequence[Sequence[float]]) -> int:
    """Index of the displacement nearest (Euclidean) the per-axis median of them all (first on ties)."""
    d = np.asarray(displacements, dtype=float)
    med = np.median(d, axis=0)
    return int(np.argmin(np.sqrt(((d - med) ** 2).sum(axis=1))))


def join(tracks: Sequence[EdgeTrack]) -> PoseTrack:
    """The tracks one after the other as one track from ``t = 0``: each repeats its own displacement
    and rotation (world frame) from the pose where the one before it ended."""
    if not tracks:
        raise ValueError("no tracks to join")
    ts: list[float] = []
    ps: list[np.ndarray] = []
    qs: list[np.ndarray] = []
    t_end, p_end, q_end = 0.0, tracks[0].pos[0], tracks[0].quat[0]
    for k, tr in enumerate(tracks):
        inv0 = np.array([tr.quat[0][0], -tr.quat[0][1], -tr.quat[0][2], -tr.quat[0][3]])
        first = 0 if k == 0 else 1  # the joint's pose is the previous track's last
        for i in range(first, len(tr.t)):
            ts.append(t_end + float(tr.t[i]))
            ps.append(p_end + (tr.pos[i] - tr.pos[0]))
            qs.append(quat_normalize(quat_mul(quat_mul(tr.quat[i], inv0), q_end)))
        t_end, p_end, q_end = ts[-1], ps[-1], qs[-1]
    return PoseTrack(np.array(ts, dtype=float), np.array(ps), np.array(qs))
