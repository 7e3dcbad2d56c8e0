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
import math
from pathlib import Path
from typing import Any

from dlovr.inputs import InputError
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

    def bad(where: str, msg: str) -> FactsError:
        return FactsError(f"{path}: {where}: {msg}" if where else f"{path}: {msg}")

    def table(v: Any, where: str, keys: tuple[str, ...]) -> dict[str, Any]:
        if not isinstance(v, dict):
            raise bad(where, f"must be a JSON object with keys {', '.join(keys)}, got {_show(v)}")
        unknown = sorted(set(v) - set(keys))
        if unknown:
            raise bad(where, f"unknown key {unknown[0]!r} (allowed: {', '.join(keys)})")
        return v

    def vec3(v: Any, where: str) -> Vec3:
        ok = isinstance(v, list) and len(v) == 3
        ok = ok and all(not isinstance(x, bool) and isinstance(x, int | float) for x in v)
        if not ok or not all(math.isfinite(x) for x in v):
            raise bad(where, f"must be a list of 3 numbers, got {_show(v)}")
        if not any(v):
            raise bad(where, "must not be the zero vector")
        return (float(v[0]), float(v[1]), float(v[2]))

    def flag(v: Any, where: str) -> bool:
        if not isinstance(v, bool):
            raise bad(where, f"must be true or false, got {_show(v)}")
        return v

    def face_name(v: Any, where: str) -> str:
        if not isinstance(v, str) or not FACE_NAME_RE.match(v):
            raise bad(where, f"must be a face name OBJECT.F<number> such as box.F1, got {_show(v)}")
        return v

    try:
        with open(path, encoding="utf-8") as fh:
            raw = json.load(fh)
    except OSError as e:
        raise FactsError(f"{path}: cannot read facts file: {e.strerror or e}") from None
    except UnicodeDecodeError:
        raise FactsError(f"{path}: not a UTF-8 text file") from None
    except json.JSONDecodeError as e:
        raise FactsError(f"{path}: not valid JSON: {e.msg} at line {e.lineno}") from None
    table(raw, "", _TOP_KEYS)
    faces: dict[str, FaceFact] = {}
    raw_faces = raw.get("faces", {})
    if not isinstance(raw_faces, dict):
        raise bad("faces", f"must be an object of face name -> {{...}}, got {_show(raw_faces)}")
    for name, f in raw_faces.items():
        where = f"faces.{name}"
        face_name(name, "faces")
        table(f, where, _FACE_KEYS)
        if "normal" not in f:
            raise bad(where, "missing key 'normal'")
        normal = vec3(f["normal"], f"{where}.normal")
        internal = flag(f.get("internal", False), f"{where}.internal")
        faces[name] = FaceFact(name, face_object(name), normal, internal)
    raw_pairs = raw.get("pairs", [])
    if not isinstance(raw_pairs, list):
        raise bad("pairs", f"must be a list of objects, got {_show(raw_pairs)}")
    pairs = []
    for i, p in enumerate(raw_pairs):
        where = f"pairs[{i}]"
        table(p, where, _PAIR_KEYS)
        missing = [k for k in _PAIR_KEYS if k not in p]
        if missing:
            raise bad(where, f"missing key {missing[0]!r}")
        a, b = face_name(p["a"], f"{where}.a"), face_name(p["b"], f"{where}.b")
        opening = p["opening_deg"]
        if isinstance(opening, bool) or not isinstance(opening, int | float) or not 0 < opening < 360:
            raise bad(f"{where}.opening_deg", f"must be a number in (0, 360), got {_show(opening)}")
        pairs.append(PairFact(a, b, flag(p["concave"], f"{where}.concave"), float(opening), None))
    raw_vectors = raw.get("dlo_vectors", {})
    if not isinstance(raw_vectors, dict):
        raise bad("dlo_vectors", f"must be an object of point index -> [x, y, z], got {_show(raw_vectors)}")
    vectors: dict[int, Vec3] = {}
    for k, v in raw_vectors.items():
        if not k.isdigit():
            raise bad("dlo_vectors", f"keys are point indices (0, 1, ...), got {_show(k)}")
        vectors[int(k)] = vec3(v, f"dlo_vectors.{k}")
    return FactBook(faces, pairs), vectors


__all__ = ["FactsError", "load_facts"]
