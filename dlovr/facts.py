"""Geometric facts for hand-written topological situations (``dlovr transitions --facts FILE``).

A facts file is JSON::

    {"faces": {"box.F1": {"normal": [0, 0, 1]}, "box.F2": {"normal": [1, 0, 0], "internal": false}},
     "pairs": [{"a": "box.F1", "b": "box.F2", "concave": false, "opening_deg": 270}],
     "dlo_vectors": {"15": [1, 0, 0]}}

``faces``: every face a situation names, with its outward normal (world frame; any length but zero)
and whether a convex decomposition introduced it inside a solid (``internal``, default false);
``pairs``: how two faces meet (concave or convex, the free-space opening angle in degrees, in
(0, 360)); ``dlo_vectors``: the DLO vector (tangent, world frame) at a point index, needed to tell a
line contact along an edge from a point contact across it. Every problem is a :class:`FactsError`
with a one-line message naming the file and the key.
"""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

from dlovr.inputs import Fields, InputError, read_json
from dlovr.model.discrete import FaceFact, FactBook, PairFact
from dlovr.model.topology import FACE_NAME_RE, face_object

Vec3 = tuple[float, float, float]

_TOP_KEYS = ("faces", "pairs", "dlo_vectors")
_FACE_KEYS = ("normal", "internal")
_PAIR_KEYS = ("a", "b", "concave", "opening_deg")


class FactsError(InputError):
    """A facts file is unusable: ``FILE: key: what is wrong`` (one line)."""


def _show(v: Any) -> str:
    """A JSON value as it was written (not a Python repr)."""
    s = json.dumps(v)
    return s if len(s) <= 60 else s[:57] + "..."


def load_facts(path: str | Path) -> tuple[FactBook, dict[int, Vec3]]:
    """Read a facts file: the :class:`FactBook` of its faces and pairs, and DLO vectors by point index."""
    f = Fields(path, FactsError)
    raw = _object(f, read_json(path, FactsError, "facts file"), "", _TOP_KEYS)
    faces = _faces(f, raw.get("faces", {}))
    raw_pairs = raw.get("pairs", [])
    if not isinstance(raw_pairs, list):
        raise f.err("pairs", f"must be a list of objects, got {_show(raw_pairs)}")
    pairs = [_pair(f, p, f"pairs[{i}]") for i, p in enumerate(raw_pairs)]
    raw_vectors = raw.get("dlo_vectors", {})
    if not isinstance(raw_vectors, dict):
        raise f.err("dlo_vectors", f"must be an object of point index -> [x, y, z], got {_show(raw_vectors)}")
    vectors: dict[int, Vec3] = {}
    for k, v in raw_vectors.items():
        if not k.isdigit():
            raise f.err("dlo_vectors", f"keys are point indices (0, 1, ...), got {_show(k)}")
        vectors[int(k)] = _direction(f, v, f"dlo_vectors.{k}")
    return FactBook(faces, pairs), vectors


def _object(f: Fields, v: Any, where: str, keys: tuple[str, ...]) -> dict[str, Any]:
    """A JSON object whose keys all lie in ``keys``."""
    if not isinstance(v, dict):
        raise f.err(where, f"must be a JSON object with keys {', '.join(keys)}, got {_show(v)}")
    return f.table(v, where, set(keys))


def _direction(f: Fields, v: Any, where: str) -> Vec3:
    """A non-zero vector (world frame, any length)."""
    x, y, z = f.vec(v, where, 3)
    if not (x or y or z):
        raise f.err(where, "must not be the zero vector")
    return (x, y, z)


def _flag(f: Fields, v: Any, where: str) -> bool:
    if not isinstance(v, bool):
        raise f.err(where, f"must be true or false, got {_show(v)}")
    return v


def _face_name(f: Fields, v: Any, where: str) -> str:
    if not isinstance(v, str) or not FACE_NAME_RE.match(v):
        raise f.err(where, f"must be a face name OBJECT.F<number> such as box.F1, got {_show(v)}")
    return v


def _faces(f: Fields, raw: Any) -> dict[str, FaceFact]:
    """The ``faces`` object: name -> outward normal and ``internal``."""
    if not isinstance(raw, dict):
        raise f.err("faces", f"must be an object of face name -> {{...}}, got {_show(raw)}")
    faces: dict[str, FaceFact] = {}
    for name, face in raw.items():
        where = f"faces.{name}"
        _face_name(f, name, "faces")
        _object(f, face, where, _FACE_KEYS)
        normal = _direction(f, f.require(face, "normal", where), f"{where}.normal")
        internal = _flag(f, face.get("internal", False), f"{where}.internal")
        faces[name] = FaceFact(name, face_object(name), normal, internal)
    return faces


def _pair(f: Fields, p: Any, where: str) -> PairFact:
    """One entry of ``pairs``: two faces, concave or not, the opening angle (degrees, in (0, 360))."""
    _object(f, p, where, _PAIR_KEYS)
    for k in _PAIR_KEYS:
        f.require(p, k, where)
    a, b = _face_name(f, p["a"], f"{where}.a"), _face_name(f, p["b"], f"{where}.b")
    opening = p["opening_deg"]
    if isinstance(opening, bool) or not isinstance(opening, int | float) or not 0 < opening < 360:
        raise f.err(f"{where}.opening_deg", f"must be a number in (0, 360), got {_show(opening)}")
    return PairFact(a, b, _flag(f, p["concave"], f"{where}.concave"), float(opening), None)


__all__ = ["FactsError", "load_facts"]
