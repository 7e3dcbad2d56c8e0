"""Vectors, quaternions, rotations and poses: the one place for them (pure Python + numpy).

Quaternions are ``[w, x, y, z]`` (MuJoCo's order; Foxglove's is xyzw). Rotation vectors are
axis * angle in radians. The helpers that feed the simulation (:func:`dot`, :func:`norm`,
:func:`quat_normalize`, :func:`quat_mul`, :func:`quat_rotate`, :func:`slerp`) round the same on every
processor: they avoid BLAS, so a recording replays bit for bit on another machine.

The vector helpers (:func:`dot`, :func:`norm`, :func:`unit`, :func:`units`, :func:`angle_deg`) share
one zero-vector rule: a vector of zero length, or shorter than the caller's tolerance, has no
direction. :func:`unit` returns None for it, :func:`units` (row by row) a zero row, and
:func:`angle_deg` 180 degrees (no direction agrees with it).
"""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np


def dot(a: Sequence[float] | np.ndarray, b: Sequence[float] | np.ndarray) -> float:
    """Dot product of two short vectors, summed left to right in Python floats.

    The gripper's motion feeds MuJoCo, so it must round the same on every machine: ``np.dot`` and
    ``np.linalg.norm`` go through BLAS, whose kernel (and so its rounding, with or without fused
    multiply-adds) depends on the processor, and a recording made on one machine then replays a
    last bit differently on another.
    """
    total = 0.0
    xs = a if type(a) is list else np.asarray(a, dtype=float).tolist()  # a list: Python floats already
    ys = b if type(b) is list else np.asarray(b, dtype=float).tolist()
    for x, y in zip(xs, ys, strict=True):
        total += x * y
    return total


def norm(v: Sequence[float] | np.ndarray) -> float:
    """Euclidean length of a short vector, the same on every machine (see :func:`dot`)."""
    return math.sqrt(dot(v, v))


def unit(v: Sequence[float] | np.ndarray, tol: float = 0.0) -> np.ndarray | None:
    """``v / |v|`` (float64), or None when ``v`` has no direction: its length is zero or below
    ``tol`` (the zero-vector rule, see the module docstring). The length is :func:`norm`'s: it rounds
    as numpy's ``sqrt((v * v).sum())`` for vectors of fewer than 8 entries."""
    a = np.asarray(v, dtype=float)
    n = norm(a)
    return None if n < tol or n == 0.0 else a / n


def units(v: np.ndarray) -> np.ndarray:
    """Unit vectors of the rows of ``v`` (along its last axis; a single vector too), lengths as
    ``np.linalg.norm(v, axis=-1)``; a row of zero length stays zero (the zero-vector rule, see the
    module docstring: no direction)."""
    v = np.asarray(v, dtype=float)
    n = np.linalg.norm(v, axis=-1, keepdims=True)
    return v / np.where(n == 0.0, 1.0, n)


def angle_deg(a: Sequence[float] | np.ndarray, b: Sequence[float] | np.ndarray, tol: float = 1e-12) -> float:
    """Angle between ``a`` and ``b`` in degrees (0..180); 180 when either is shorter than ``tol``
    (the zero-vector rule: no direction agrees with it). Lengths and the dot product as :func:`norm`
    and :func:`dot` round them."""
    na, nb = norm(a), norm(b)
    if na < tol or nb < tol:
        return 180.0
    c = dot(a, b) / (na * nb)
    return math.degrees(math.acos(max(-1.0, min(1.0, c))))


def _f64(v: object) -> list[float] | None:
    """A 1-d float64 array's entries as Python floats (the same IEEE doubles, which round as numpy's
    scalars do, without their overhead); None for anything else."""
    return v.tolist() if type(v) is np.ndarray and v.dtype == np.float64 and v.ndim == 1 else None


def _floats(v: Sequence[float] | np.ndarray) -> Sequence[float] | np.ndarray:
    """``v``'s entries for arithmetic: a float64 array's as Python floats (:func:`_f64`), anything
    else as it is."""
    got = _f64(v)
    return v if got is None else got


def quat_normalize(q: Sequence[float] | np.ndarray) -> np.ndarray:
    """``q / |q|`` (float64; :func:`norm`'s length): element by element in Python floats, the same
    roundings as numpy's ``q / norm(q)``."""
    v = _f64(q)
    if v is None:
        a = np.asarray(q, dtype=float)
        return a / norm(a)
    n = norm(v)
    if n == 0.0 or not math.isfinite(n):  # numpy's nan/inf and warning
        a = np.asarray(q, dtype=float)
        return a / n
    return np.array([x / n for x in v])


def quat_mul(a: Sequence[float] | np.ndarray, b: Sequence[float] | np.ndarray) -> np.ndarray:
    """The Hamilton product ``a b`` (wxyz), in Python floats for float64 input (the same roundings)."""
    aw, ax, ay, az = _floats(a)
    bw, bx, by, bz = _floats(b)
    return np.array(
        [
            aw * bw - ax * bx - ay * by - az * bz,
            aw * bx + ax * bw + ay * bz - az * by,
            aw * by - ax * bz + ay * bw + az * bx,
            aw * bz + ax * by - ay * bx + az * bw,
        ]
    )


def quat_rotate(q: Sequence[float] | np.ndarray, v: Sequence[float] | np.ndarray) -> np.ndarray:
    """Rotate vector ``v`` by unit quaternion ``q`` (wxyz)."""
    return np.array(rotate_floats(_f64(q) or [float(c) for c in q], _f64(v) or [float(c) for c in v]))


def rotate_floats(q: Sequence[float], v: Sequence[float]) -> tuple[float, float, float]:
    """:func:`quat_rotate` on Python floats (``q`` wxyz), as a tuple: the same operations, the same
    bits, without the arrays (the contact tracker takes the gripper's z axis so on many steps)."""
    w, x, y, z = q
    vx, vy, vz = v
    tx, ty, tz = 2.0 * (y * vz - z * vy), 2.0 * (z * vx - x * vz), 2.0 * (x * vy - y * vx)
    return (
        vx + w * tx + (y * tz - z * ty),
        vy + w * ty + (z * tx - x * tz),
        vz + w * tz + (x * ty - y * tx),
    )


def slerp(q0: Sequence[float] | np.ndarray, q1: Sequence[float] | np.ndarray, s: float) -> np.ndarray:
    """Shortest-path spherical interpolation from ``q0`` (s=0) to ``q1`` (s=1), unit wxyz.

    In Python floats, element by element: the same roundings as the numpy expressions
    ``q / norm(q)``, ``q0 + s * (q1 - q0)`` and ``a * q0 + b * q1``, without their overhead."""
    a, b = _unit4(q0), _unit4(q1)
    c = dot(a, b)
    if c < 0.0:
        b, c = [-x for x in b], -c
    if c > 0.9995:
        return quat_normalize(np.array([x + s * (y - x) for x, y in zip(a, b, strict=True)]))
    th = math.acos(min(1.0, c))
    sin = math.sin(th)
    wa, wb = math.sin((1 - s) * th) / sin, math.sin(s * th) / sin
    return np.array([wa * x + wb * y for x, y in zip(a, b, strict=True)])


def _unit4(q: Sequence[float] | np.ndarray) -> list[float]:
    """``quat_normalize(q)`` as a list of Python floats."""
    v = q if type(q) is list else np.asarray(q, dtype=float).tolist()
    n = norm(v)
    return [x / n for x in v]


def quat_to_matrix(q: Sequence[float] | np.ndarray) -> np.ndarray:
    """Rotation matrix of a quaternion given as (w, x, y, z); normalised first."""
    w, x, y, z = np.asarray(q, dtype=float) / np.linalg.norm(q)
    return np.array(
        [
            [1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
            [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
            [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)],
        ]
    )


def pose_matrix(pos: Sequence[float] | np.ndarray, quat: Sequence[float] | np.ndarray) -> np.ndarray:
    """4x4 homogeneous transform from a position and a (w, x, y, z) quaternion."""
    t = np.eye(4)
    t[:3, :3] = quat_to_matrix(quat)
    t[:3, 3] = np.asarray(pos, dtype=float)
    return t


def matrix_to_rotvec(r: np.ndarray) -> np.ndarray:
    """Rotation vector (axis * angle, rad) of a rotation matrix."""
    cos = max(-1.0, min(1.0, (float(np.trace(r)) - 1.0) / 2.0))
    angle = math.acos(cos)
    if angle < 1e-12:
        return np.zeros(3)
    if math.pi - angle < 1e-6:
        # near 180°: axis from the diagonal
        axis = np.sqrt(np.maximum((np.diag(r) + 1.0) / 2.0, 0.0))
        k = int(np.argmax(axis))
        axis[(k + 1) % 3] = math.copysign(axis[(k + 1) % 3], r[k, (k + 1) % 3])
        axis[(k + 2) % 3] = math.copysign(axis[(k + 2) % 3], r[k, (k + 2) % 3])
        return axis / np.linalg.norm(axis) * angle
    axis = np.array([r[2, 1] - r[1, 2], r[0, 2] - r[2, 0], r[1, 0] - r[0, 1]]) / (2 * math.sin(angle))
    return axis * angle


def rotvec_to_quat(w: Sequence[float] | np.ndarray) -> np.ndarray:
    """Unit quaternion (wxyz) of a rotation vector ``w`` (axis * angle, rad)."""
    th = math.sqrt(w[0] * w[0] + w[1] * w[1] + w[2] * w[2])
    if th < 1e-12:
        return np.array([1.0, 0.0, 0.0, 0.0])
    s = math.sin(0.5 * th) / th
    return np.array([math.cos(0.5 * th), w[0] * s, w[1] * s, w[2] * s])


def quat_to_rotvec(q: Sequence[float] | np.ndarray) -> tuple[float, float, float]:
    """Rotation vector (axis * angle, rad) of a unit quaternion (wxyz), the short way round."""
    w, x, y, z = (float(c) for c in q)
    if w < 0.0:
        w, x, y, z = -w, -x, -y, -z
    n = math.sqrt(x * x + y * y + z * z)
    if n < 1e-15:
        return (2.0 * x, 2.0 * y, 2.0 * z)
    th = 2.0 * math.atan2(n, w)
    return (x * th / n, y * th / n, z * th / n)


__all__ = [
    "angle_deg",
    "dot",
    "matrix_to_rotvec",
    "norm",
    "pose_matrix",
    "quat_mul",
    "quat_normalize",
    "quat_rotate",
    "quat_to_matrix",
    "quat_to_rotvec",
    "rotvec_to_quat",
    "slerp",
    "unit",
    "units",
]
