"""Pure helpers (no viser) for drawing the cable: a unit cylinder on each segment, each point's colour
by the stability class of the contact it belongs to, the contact vectors as arrows, and the faces
the contacts touch."""

from __future__ import annotations

from typing import Any

import numpy as np

from dlovr.model.discrete import Stability
from dlovr.sim.tracker import ContactState

# cable colours: free, then by stability class of the contact a point belongs to. Free is a dark
# neutral grey, like a real cable, which no class colour resembles (a pale orange read as yellow).
COLOR_FREE = (55, 60, 75)
COLOR_BY_CLASS = {
    Stability.STABLE: (20, 150, 45),
    Stability.SEMI: (235, 195, 0),
    Stability.INSTABLE: (215, 30, 30),
}
# the faces touched, in lighter tints of the same hues, so that a cable lying on one stays visible
FACE_COLOR_BY_CLASS = {
    Stability.STABLE: (100, 210, 120),
    Stability.SEMI: (245, 225, 100),
    Stability.INSTABLE: (245, 125, 125),
}


def segment_transforms(points: np.ndarray, radius: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Per-segment (positions, wxyz, xyz scales) placing a unit cylinder (z axis, height 1) on each
    segment of the polyline ``points``."""
    p = np.asarray(points, dtype=float)
    d = np.diff(p, axis=0)
    length = np.linalg.norm(d, axis=1)
    u = d / np.maximum(length, 1e-12)[:, None]
    # rotation taking +z to u: q = (1 + u_z, -u_y, u_x, 0), normalised; u = -z -> 180° about x
    q = np.stack([1.0 + u[:, 2], -u[:, 1], u[:, 0], np.zeros(len(u))], axis=1)
    n = np.linalg.norm(q, axis=1)
    flip = n < 1e-9
    q[flip] = (0.0, 1.0, 0.0, 0.0)
    n[flip] = 1.0
    q /= n[:, None]
    scales = np.stack([np.full(len(u), radius), np.full(len(u), radius), length], axis=1)
    return (p[:-1] + p[1:]) / 2.0, q, scales


def point_classes(state: ContactState | None, npoints: int) -> list[Stability | None]:
    """Stability class of the contact each cable point belongs to (None: free point)."""
    out: list[Stability | None] = [None] * npoints
    if state is None:
        return out
    for tc, dc in zip(state.topological.contacts, state.discrete.contacts, strict=True):
        span = tc.dlo.span
        cls = dc.state.stability_class
        if span is None or cls is None:
            continue
        a, b = span
        for i in range(max(0, a), min(npoints - 1, b) + 1):
            prev = out[i]
            # keep the least stable class where two contacts share a point
            if prev is None or _rank(cls) > _rank(prev):
                out[i] = cls
    return out


def situation_faces(situation: Any) -> dict[str, Stability]:
    """The obstacle faces a discrete situation's contacts touch, each with the stability class of its
    least stable contact (free and gripper contacts touch none)."""
    out: dict[str, Stability] = {}
    if situation is None:
        return out
    for c in situation.contacts:
        cls = c.state.stability_class
        if cls is None:
            continue
        for f in c.faces:
            prev = out.get(f)
            if prev is None or _rank(cls) > _rank(prev):
                out[f] = cls
    return out


STABILITY_WORDS = {Stability.STABLE: "stable", Stability.SEMI: "semi-stable", Stability.INSTABLE: "instable"}


def _rank(c: Stability) -> int:
    return {Stability.STABLE: 0, Stability.SEMI: 1, Stability.INSTABLE: 2}[c]


def point_colors(classes: list[Stability | None]) -> np.ndarray:
    return np.array([COLOR_BY_CLASS[c] if c is not None else COLOR_FREE for c in classes], dtype=np.uint8)


def contact_arrows(state: ContactState | None, points: np.ndarray, length: float = 0.06) -> np.ndarray:
    """(k, 2, 3) arrows: from each non-free contact's point(s) along its contact vector."""
    if state is None:
        return np.zeros((0, 2, 3))
    out = []
    for tc, dc in zip(state.topological.contacts, state.discrete.contacts, strict=True):
        if dc.vector is None or tc.dlo.span is None or dc.state.stability_class is None:
            continue
        a, b = tc.dlo.span
        base = np.asarray(points[a : b + 1], dtype=float).mean(axis=0)
        v = np.asarray(dc.vector, dtype=float)
        out.append([base, base + length * v / max(float(np.linalg.norm(v)), 1e-12)])
    return np.asarray(out, dtype=float).reshape(-1, 2, 3)
