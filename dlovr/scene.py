"""Scene files (TOML): the cable, the gripper, the model parameters and the environment objects.

The schema is documented in ``docs/scenes.md``. Built-in scenes live in the repository's ``scenes/``
directory (shipped in the package as ``dlovr/_scenes``, see :func:`scenes_dir`) and are found by
name (``peg_in_hole``); any other argument is a path to a TOML file. Meshes
are resolved relative to the scene file and must lie inside its directory.

Every problem is a :class:`SceneError` with a one-line message naming the file, the key or object,
and the problem.
"""

from __future__ import annotations

import math
import re
import tomllib
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Literal

import numpy as np

from dlovr.inputs import InputError
from dlovr.model.discrete import ModelParams

Vec3 = tuple[float, float, float]
Quat = tuple[float, float, float, float]

NAME_RE = re.compile(r"^[A-Za-z_][A-Za-z0-9_\-]*$")
MAX_MESH_BYTES = 20 * 1024 * 1024
#: Most cable segments: at 200 one simulation step with contact extraction takes about the 2 ms it
#: simulates on the development machine (real time for the browser UI); more only runs slower.
MAX_SEGMENTS = 200
#: Longest cable in metres.
MAX_LENGTH_M = 10.0
#: Most environment objects (their pairwise overlap check grows with the square).
MAX_OBJECTS = 64
MESH_SUFFIXES = (".obj", ".stl", ".ply", ".off")


class SceneError(InputError):
    """A problem in a scene file: one line naming the file, the key or object, and the problem."""


@dataclass(frozen=True)
class DloSpec:
    """The cable: length (m), radius (m), segments, Young's modulus (Pa), damping (s), mass (kg)."""

    length: float
    radius: float
    segments: int
    young: float
    damping: float
    mass: float
    poisson: float = 0.3
    friction: float = 0.5


@dataclass(frozen=True)
class GripperSpec:
    """The gripper's initial pose (world frame); it holds V_S, its z axis is G_z. ``quat`` is wxyz."""

    pos: Vec3
    quat: Quat = (1.0, 0.0, 0.0, 0.0)


@dataclass(frozen=True)
class SceneObject:
    """An environment object: a box (full extents ``size``) or a mesh file, at a pose (``quat`` wxyz)."""

    name: str
    kind: Literal["box", "mesh"]
    pos: Vec3 = (0.0, 0.0, 0.0)
    quat: Quat = (1.0, 0.0, 0.0, 0.0)
    mesh_path: Path | None = None
    size: Vec3 | None = None
    scale: float = 1.0
    color: tuple[float, float, float] | None = None


@dataclass(frozen=True)
class Scene:
    name: str
    description: str
    path: Path
    dlo: DloSpec
    gripper: GripperSpec
    params: ModelParams
    objects: tuple[SceneObject, ...]

    def object(self, name: str) -> SceneObject:
        for o in self.objects:
            if o.name == name:
                return o
        raise KeyError(name)


# --------------------------------------------------------------------------------------------------
# Built-in scenes
# --------------------------------------------------------------------------------------------------


def scenes_dir() -> Path:
    """Directory of the built-in scenes, scripts and meshes.

    An installed package carries them as its resource folder ``dlovr/_scenes`` (``setup.py`` maps the
    repository's ``scenes/`` there); a checkout or an editable install uses ``scenes/`` at the
    repository top.
    """
    from importlib.resources import files

    shipped = files("dlovr") / "_scenes"
    if shipped.is_dir():
        return Path(str(shipped))
    return Path(__file__).resolve().parent.parent / "scenes"


def builtin_scenes() -> list[tuple[str, str]]:
    """(name, description) of every built-in scene, sorted by name."""
    out = []
    for p in sorted(scenes_dir().glob("*.toml")):
        if not NAME_RE.match(p.stem):
            continue  # e.g. table.script.toml: a script, not a scene
        try:
            with p.open("rb") as fh:
                desc = str(tomllib.load(fh).get("description", ""))
        except (OSError, tomllib.TOMLDecodeError):
            desc = "(unreadable)"
        out.append((p.stem, desc))
    return out


def resolve_scene_path(name_or_path: str | Path) -> Path:
    s = str(name_or_path)
    if NAME_RE.match(s) and not s.endswith(".toml"):
        p = scenes_dir() / f"{s}.toml"
        if p.is_file():
            return p
        if not Path(s).exists():
            known = ", ".join(n for n, _ in builtin_scenes())
            raise SceneError(f"{s}: no built-in scene of that name (known: {known}) and no such file")
    return Path(s)


# --------------------------------------------------------------------------------------------------
# Loading and validation
# --------------------------------------------------------------------------------------------------

_TOP_KEYS = {"name", "description", "dlo", "gripper", "model", "objects"}
_DLO_KEYS = {"length", "radius", "segments", "young", "damping", "mass", "poisson", "friction"}
_DLO_DEFAULTS = {
    "length": 0.6,
    "radius": 0.005,
    "segments": 40,
    "young": 2e7,
    "damping": 0.01,
    "mass": 0.06,
    "poisson": 0.3,
    "friction": 0.5,
}
_GRIPPER_KEYS = {"pos", "quat"}
_MODEL_KEYS = {"critical_angle_deg", "tip_angle_deg", "parallel_tol_deg", "normal_merge_deg"}
_OBJ_KEYS = {"name", "box", "mesh", "pos", "quat", "scale", "color"}
_BOX_KEYS = {"size", "pos", "quat"}


class _Ctx:
    def __init__(self, path: Path):
        self.path = path

    def err(self, where: str, msg: str) -> SceneError:
        return SceneError(f"{self.path}: {where}: {msg}" if where else f"{self.path}: {msg}")

    def table(self, raw: Any, where: str, keys: set[str]) -> dict:
        if not isinstance(raw, dict):
            raise self.err(where, "must be a table")
        unknown = sorted(set(raw) - keys)
        if unknown:
            raise self.err(
                f"{where}.{unknown[0]}" if where else unknown[0],
                f"unknown key (allowed: {', '.join(sorted(keys))})",
            )
        return raw

    def number(self, raw: Any, where: str, *, positive: bool = False, nonneg: bool = False) -> float:
        if isinstance(raw, bool) or not isinstance(raw, int | float) or not math.isfinite(raw):
            raise self.err(where, f"must be a finite number, got {raw!r}")
        if positive and raw <= 0:
            raise self.err(where, f"must be positive, got {raw!r}")
        if nonneg and raw < 0:
            raise self.err(where, f"must not be negative, got {raw!r}")
        return float(raw)

    def vec(self, raw: Any, where: str, n: int, *, positive: bool = False) -> tuple[float, ...]:
        if not isinstance(raw, list) or len(raw) != n:
            raise self.err(where, f"must be a list of {n} numbers, got {raw!r}")
        return tuple(self.number(x, f"{where}[{i}]", positive=positive) for i, x in enumerate(raw))

    def quat(self, raw: Any, where: str) -> Quat:
        q = self.vec(raw, where, 4)
        norm = math.sqrt(sum(x * x for x in q))
        if norm < 1e-9:
            raise self.err(where, "quaternion has zero length")
        return tuple(x / norm for x in q)  # type: ignore[return-value]


def load_scene(name_or_path: str | Path, *, check_geometry: bool = True) -> Scene:
    """Load and validate a scene: a built-in name (``peg_in_hole``) or a path to a TOML file.

    ``check_geometry`` also loads every mesh and checks it (watertight, not self-intersecting), checks
    that objects do not overlap and that the cable fits the scene.
    """
    path = resolve_scene_path(name_or_path)
    ctx = _Ctx(path)
    try:
        data = tomllib.loads(path.read_text(encoding="utf-8"))
    except FileNotFoundError:
        raise SceneError(f"{path}: no such scene file") from None
    except IsADirectoryError:
        raise SceneError(f"{path}: is a directory, not a scene file") from None
    except OSError as e:
        raise SceneError(f"{path}: cannot read: {e.strerror}") from None
    except UnicodeDecodeError:
        raise SceneError(f"{path}: not a UTF-8 text file") from None
    except tomllib.TOMLDecodeError as e:
        raise SceneError(f"{path}: TOML syntax error: {e}") from None

    ctx.table(data, "", _TOP_KEYS)
    name = data.get("name", path.stem)
    if not isinstance(name, str) or not name:
        raise ctx.err("name", "must be a non-empty string")
    desc = data.get("description", "")
    if not isinstance(desc, str):
        raise ctx.err("description", "must be a string")

    raw_dlo = ctx.table(data.get("dlo", {}), "dlo", _DLO_KEYS)
    vals: dict[str, Any] = {}
    for k, default in _DLO_DEFAULTS.items():
        v = raw_dlo.get(k, default)
        if k == "segments":
            if isinstance(v, bool) or not isinstance(v, int) or not 2 <= v <= MAX_SEGMENTS:
                raise ctx.err("dlo.segments", f"must be an integer from 2 to {MAX_SEGMENTS}, got {v!r}")
            vals[k] = v
        elif k in ("damping", "friction"):
            vals[k] = ctx.number(v, f"dlo.{k}", nonneg=True)
        elif k == "poisson":
            vals[k] = ctx.number(v, "dlo.poisson")
            if not -1.0 < vals[k] < 0.5:
                raise ctx.err("dlo.poisson", f"must be in (-1, 0.5), got {v!r}")
        else:
            vals[k] = ctx.number(v, f"dlo.{k}", positive=True)
    if vals["length"] > MAX_LENGTH_M:
        raise ctx.err("dlo.length", f"must be at most {MAX_LENGTH_M:g} m, got {vals['length']:g}")
    if vals["radius"] >= vals["length"] / 2:
        raise ctx.err("dlo.radius", f"must be less than half the length, got {vals['radius']:g} m")
    dlo = DloSpec(**vals)
    if dlo.length / dlo.segments <= 0.0:
        raise ctx.err("dlo.segments", "segments too short")

    raw_g = ctx.table(data.get("gripper", {}), "gripper", _GRIPPER_KEYS)
    gripper = GripperSpec(
        ctx.vec(raw_g.get("pos", [0.0, 0.0, 0.5]), "gripper.pos", 3),  # type: ignore[arg-type]
        ctx.quat(raw_g.get("quat", [1, 0, 0, 0]), "gripper.quat"),
    )

    raw_m = ctx.table(data.get("model", {}), "model", _MODEL_KEYS)
    mvals = {k: ctx.number(v, f"model.{k}") for k, v in raw_m.items()}
    try:
        params = ModelParams(**mvals)
    except ValueError as e:
        raise ctx.err("model", str(e)) from None

    raw_objs = data.get("objects", [])
    if not isinstance(raw_objs, list):
        raise ctx.err("objects", "must be an array of tables ([[objects]])")
    if len(raw_objs) > MAX_OBJECTS:
        raise ctx.err("objects", f"{len(raw_objs)} objects, at most {MAX_OBJECTS} allowed")
    objects: list[SceneObject] = []
    seen: set[str] = set()
    for i, ro in enumerate(raw_objs):
        where = f"objects[{i}]"
        ctx.table(ro, where, _OBJ_KEYS)
        oname = ro.get("name")
        if not isinstance(oname, str) or not NAME_RE.match(oname):
            raise ctx.err(f"{where}.name", f"must be a name of letters, digits, '_' or '-', got {oname!r}")
        where = f"object {oname!r}"
        if oname in seen:
            raise ctx.err(where, "duplicate object name")
        seen.add(oname)
        has_box, has_mesh = "box" in ro, "mesh" in ro
        if has_box == has_mesh:
            raise ctx.err(where, "needs exactly one of 'box' or 'mesh'")
        pos = ctx.vec(ro.get("pos", [0, 0, 0]), f"{where}.pos", 3)
        quat = ctx.quat(ro.get("quat", [1, 0, 0, 0]), f"{where}.quat")
        color = None
        if "color" in ro:
            color = ctx.vec(ro["color"], f"{where}.color", 3)
            if any(not 0.0 <= c <= 1.0 for c in color):
                raise ctx.err(f"{where}.color", "components must be in [0, 1]")
        if has_box:
            box = ctx.table(ro["box"], f"{where}.box", _BOX_KEYS)
            if "size" not in box:
                raise ctx.err(f"{where}.box", "missing key 'size'")
            size = ctx.vec(box["size"], f"{where}.box.size", 3)
            if any(s <= 0 for s in size):
                raise ctx.err(f"{where}.box.size", f"sizes must be positive, got {list(size)}")
            for k in ("pos", "quat"):
                if k in box and k in ro:
                    raise ctx.err(where, f"'{k}' given both in the object and in its box")
            if "pos" in box:
                pos = ctx.vec(box["pos"], f"{where}.box.pos", 3)
            if "quat" in box:
                quat = ctx.quat(box["quat"], f"{where}.box.quat")
            if "scale" in ro:
                raise ctx.err(f"{where}.scale", "only mesh objects take a scale")
            objects.append(SceneObject(oname, "box", pos, quat, None, size, 1.0, color))  # type: ignore[arg-type]
        else:
            mesh = ro["mesh"]
            if not isinstance(mesh, str) or not mesh:
                raise ctx.err(f"{where}.mesh", "must be a relative file path")
            mp = Path(mesh)
            if mp.is_absolute():
                raise ctx.err(f"{where}.mesh", f"{mesh!r}: must be relative to the scene file")
            base = path.resolve().parent
            full = (base / mp).resolve()
            if base not in full.parents:
                raise ctx.err(f"{where}.mesh", f"{mesh!r}: must lie inside the scene file's directory")
            if full.suffix.lower() not in MESH_SUFFIXES:
                raise ctx.err(
                    f"{where}.mesh", f"{mesh!r}: unsupported format (use {', '.join(MESH_SUFFIXES)})"
                )
            if not full.is_file():
                raise ctx.err(f"{where}.mesh", f"mesh file {mesh!r} not found")
            if full.stat().st_size > MAX_MESH_BYTES:
                raise ctx.err(
                    f"{where}.mesh", f"mesh file {mesh!r} is larger than {MAX_MESH_BYTES >> 20} MiB"
                )
            scale = ctx.number(ro.get("scale", 1.0), f"{where}.scale", positive=True)
            objects.append(SceneObject(oname, "mesh", pos, quat, full, None, scale, color))  # type: ignore[arg-type]

    scene = Scene(name, desc, path, dlo, gripper, params, tuple(objects))
    if check_geometry:
        _check_geometry(ctx, scene)
    return scene


def object_local_mesh(obj: SceneObject):
    """The object's mesh in its own frame (trimesh); raises SceneError for an unreadable mesh file."""
    from dlovr.geometry import MeshError
    from dlovr.geometry import object_local_mesh as local_mesh

    try:
        return local_mesh(obj)
    except MeshError as e:
        raise SceneError(str(e)) from None


def _check_geometry(ctx: _Ctx, scene: Scene) -> None:
    from dlovr.geometry import check_mesh, to_manifold
    from dlovr.transforms import pose_matrix

    worlds = []
    for o in scene.objects:
        try:
            local = object_local_mesh(o)
        except SceneError as e:
            raise ctx.err(f"object {o.name!r}", str(e)) from None
        why = check_mesh(local)
        if why:
            raise ctx.err(f"object {o.name!r}", why)
        w = local.copy()
        w.apply_transform(pose_matrix(o.pos, o.quat))
        worlds.append((o.name, w, to_manifold(w)))
    for i in range(len(worlds)):
        for j in range(i + 1, len(worlds)):
            na, wa, ma = worlds[i]
            nb, wb, mb = worlds[j]
            lo = np.maximum(wa.bounds[0], wb.bounds[0])
            hi = np.minimum(wa.bounds[1], wb.bounds[1])
            if (hi - lo <= 0).any():
                continue
            vol = (ma ^ mb).volume()
            if vol > 1e-9 * min(ma.volume(), mb.volume()) + 1e-12:
                raise ctx.err(f"objects {na!r} and {nb!r}", f"overlap (common volume {vol:.3g} m^3)")
    pts = [np.asarray(scene.gripper.pos)[None]] + [w.bounds for _, w, _ in worlds]
    allp = np.vstack(pts)
    diag = float(np.linalg.norm(allp.max(axis=0) - allp.min(axis=0)))
    if worlds and scene.dlo.length > diag:
        raise ctx.err(
            "dlo.length",
            f"cable of {scene.dlo.length:g} m is longer than the scene "
            f"(its bounding box diagonal is {diag:.3g} m)",
        )


__all__ = [
    "DloSpec",
    "GripperSpec",
    "Scene",
    "SceneError",
    "SceneObject",
    "builtin_scenes",
    "describe_scene",
    "format_scene",
    "load_scene",
    "object_local_mesh",
    "scenes_dir",
]


# --------------------------------------------------------------------------------------------------
# Description (``dlovr scene show``)
# --------------------------------------------------------------------------------------------------


def describe_scene(scene: Scene, geom=None) -> dict:
    """JSON-able description of a scene and its geometry (objects, pieces, faces, edge table)."""
    from dataclasses import asdict

    from dlovr.geometry import SceneGeometry

    geom = geom if geom is not None else SceneGeometry.from_scene(scene)
    g = geom.describe()["objects"]
    objs = []
    for o, go in zip(scene.objects, g, strict=True):
        d = {
            "name": o.name,
            "kind": o.kind,
            "pos": list(o.pos),
            "quat": list(o.quat),
            "size": list(o.size) if o.size is not None else None,
            "mesh": str(o.mesh_path) if o.mesh_path is not None else None,
        }
        d.update({k: v for k, v in go.items() if k != "name"})
        objs.append(d)
    return {
        "name": scene.name,
        "description": scene.description,
        "path": str(scene.path),
        "dlo": asdict(scene.dlo),
        "gripper": {"pos": list(scene.gripper.pos), "quat": list(scene.gripper.quat)},
        "model": asdict(scene.params),
        "objects": objs,
    }


def format_scene(desc: dict) -> str:
    """Human-readable text of :func:`describe_scene`'s output."""

    def v(x) -> str:
        return "[" + ", ".join(f"{float(c):.4g}" for c in x) + "]"

    d = desc["dlo"]
    lines = [
        f"scene {desc['name']}: {desc['description']}",
        f"  file: {desc['path']}",
        f"  cable: length {d['length']:g} m, radius {d['radius']:g} m, {d['segments']} segments, "
        f"E {d['young']:g} Pa, mass {d['mass']:g} kg",
        f"  gripper: pos {v(desc['gripper']['pos'])}, quat {v(desc['gripper']['quat'])}",
        "  model: " + ", ".join(f"{k} {val:g}" for k, val in desc["model"].items()),
    ]
    for o in desc["objects"]:
        what = f"box {v(o['size'])}" if o["kind"] == "box" else f"mesh {o['mesh']}"
        kinds = sorted({p["kind"] for p in o["pieces"]})
        lines.append(
            f"object {o['name']}: {what} at {v(o['pos'])}, "
            f"{len(o['pieces'])} piece(s) ({', '.join(kinds)}), {len(o['faces'])} faces"
        )
        for f in o["faces"]:
            lines.append(f"  face {f['name']:<16} normal {v(f['normal'])}  area {f['area']:.4g} m^2")
        for p in o["pieces"]:
            fl = ", ".join(f"{x['face'] or '-'}:{x['kind']}" for x in p["faces"])
            lines.append(f"  piece {p['index']} ({p['kind']}, volume {p['volume']:.4g} m^3): {fl}")
        for e in o["edges"]:
            lines.append(
                f"  edge {e['faces'][0]} / {e['faces'][1]}: {e['kind']}, opening {e['opening_deg']:.4g} deg, "
                f"length {e['length']:.4g} m"
            )
    return "\n".join(lines)
