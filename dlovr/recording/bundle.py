"""The embedded scene: a scene TOML and its meshes as bytes, and the obstacles' convex pieces as JSON."""

from __future__ import annotations

import hashlib
import json
import tomllib
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path, PurePosixPath

import numpy as np

from dlovr.recording.format import RecordingError


def safe_relpath(name: str) -> PurePosixPath:
    """``name`` as a relative path that stays inside its folder; :class:`RecordingError` otherwise."""
    p = PurePosixPath(name)
    if p.is_absolute() or not p.parts or any(part in ("..", "") for part in p.parts) or "\\" in name:
        raise RecordingError(f"unsafe file name {name!r} in the embedded scene")
    return p


@dataclass(frozen=True)
class SceneBundle:
    """A scene file and the mesh files it names, as bytes (paths relative to the scene file)."""

    toml: bytes
    files: tuple[tuple[str, bytes], ...] = ()

    @classmethod
    def from_path(cls, path: str | Path) -> SceneBundle:
        """Read a scene TOML and the meshes its ``[[objects]]`` name (``mesh = "…"``)."""
        path = Path(path)
        raw = path.read_bytes()
        data = tomllib.loads(raw.decode("utf-8"))
        files = []
        for obj in data.get("objects", []):
            mesh = obj.get("mesh") if isinstance(obj, dict) else None
            if isinstance(mesh, str):
                rel = safe_relpath(mesh)
                files.append((str(rel), (path.parent / rel).read_bytes()))
        return cls(raw, tuple(sorted(set(files))))

    @property
    def digest(self) -> str:
        """sha256 over the TOML and every file (name and content)."""
        h = hashlib.sha256()
        h.update(b"scene.toml\0" + self.toml)
        for name, data in self.files:
            h.update(b"\0" + name.encode() + b"\0" + hashlib.sha256(data).digest())
        return h.hexdigest()

    def materialize(self, directory: str | Path) -> Path:
        """Write the scene into ``directory`` (only the embedded files); return the TOML's path."""
        root = Path(directory)
        for name, data in self.files:
            dst = root / safe_relpath(name)
            dst.parent.mkdir(parents=True, exist_ok=True)
            dst.write_bytes(data)
        out = root / "scene.toml"
        out.write_bytes(self.toml)
        return out


def pieces_to_json(pieces: Mapping[str, tuple[Sequence[np.ndarray], bool]]) -> bytes:
    """The obstacles' convex decomposition as JSON (floats written exactly)."""
    data = {
        name: {"approximate": bool(approx), "pieces": [np.asarray(p, dtype=float).tolist() for p in ps]}
        for name, (ps, approx) in pieces.items()
    }
    return json.dumps(data, allow_nan=False).encode()


def pieces_from_json(raw: bytes) -> dict[str, tuple[list[np.ndarray], bool]]:
    """Parse and check :func:`pieces_to_json` output (finite (k, 3) vertex arrays, k >= 4)."""
    try:
        data = json.loads(raw)
    except (json.JSONDecodeError, UnicodeDecodeError) as e:
        raise ValueError(f"not JSON: {e}") from None
    if not isinstance(data, dict):
        raise ValueError("expected an object of objects")
    out = {}
    for name, entry in data.items():
        try:
            ps = [np.asarray(p, dtype=float) for p in entry["pieces"]]
            approx = bool(entry["approximate"])
        except KeyError as e:
            raise ValueError(f"object {name}: {e.args[0]!r} missing") from None
        except (TypeError, ValueError) as e:
            raise ValueError(f"object {name}: {e}") from None
        if not ps or any(
            p.ndim != 2 or p.shape[1] != 3 or len(p) < 4 or not np.all(np.isfinite(p)) for p in ps
        ):
            raise ValueError(f"object {name}: pieces must be finite (k, 3) vertex arrays with k >= 4")
        out[str(name)] = (ps, approx)
    return out
