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
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any, Literal

from dlovr.inputs import LIMITS, Fields, InputError, read_toml
from dlovr.model.discrete import ModelParams

Vec3 = tuple[float, float, float]
Quat = tuple[float, float, float, float]

NAME_RE = re.compile(r"^[A-Za-z_][A-Za-z0-9_\-]*$")
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


def load_scene(name_or_path: str | Path) -> Scene:
    """Load and validate a scene: a built-in name (``peg_in_hole``) or a path to a TOML file.

    The file's values are checked here (types, ranges, :data:`dlovr.inputs.LIMITS`, mesh paths);
    the checks that need the objects' geometry (meshes watertight, objects not overlapping, the cable
    fitting the scene) are :func:`dlovr.geometry.scene_checks.load_checked_scene`'s.
    """
    path = resolve_scene_path(name_or_path)
    data = read_toml(path, SceneError, "scene file")
    f = Fields(path, SceneError)
    f.table(data, "", _TOP_KEYS)
    name = data.get("name", path.stem)
    if not isinstance(name, str) or not name:
        raise f.err("name", "must be a non-empty string")
    desc = data.get("description", "")
    if not isinstance(desc, str):
        raise f.err("description", "must be a string")
    dlo = _dlo(f, data.get("dlo", {}))
    raw_g = f.table(data.get("gripper", {}), "gripper", _GRIPPER_KEYS)
    gripper = GripperSpec(
        _vec3(f, raw_g.get("pos", [0.0, 0.0, 0.5]), "gripper.pos"),
        _orientation(f, raw_g.get("quat", [1, 0, 0, 0]), "gripper.quat"),
    )
    params = _params(f, data.get("model", {}))
    return Scene(name, desc, path, dlo, gripper, params, _objects(f, path, data.get("objects", [])))


def _vec3(f: Fields, raw: Any, where: str) -> Vec3:
    """A list of 3 finite numbers."""
    x, y, z = f.vec(raw, where, 3)
    return (x, y, z)


def _orientation(f: Fields, raw: Any, where: str) -> Quat:
    """A rotation (wxyz), normalized; all zeros is an error."""
    q = f.vec(raw, where, 4)
    norm = math.sqrt(sum(x * x for x in q))
    if norm < 1e-9:
        raise f.err(where, "quaternion has zero length")
    w, x, y, z = (c / norm for c in q)
    return (w, x, y, z)


def _dlo(f: Fields, raw: Any) -> DloSpec:
    """The ``[dlo]`` table, defaults filled in."""
    raw_dlo = f.table(raw, "dlo", _DLO_KEYS)
    vals: dict[str, Any] = {}
    for k, default in _DLO_DEFAULTS.items():
        v = raw_dlo.get(k, default)
        if k == "segments":
            vals[k] = f.integer(v, "dlo.segments", 2, int(LIMITS["dlo_segments"]))
        elif k in ("damping", "friction"):
            vals[k] = f.number(v, f"dlo.{k}", nonneg=True)
        elif k == "poisson":
            vals[k] = f.number(v, "dlo.poisson")
            if not -1.0 < vals[k] < 0.5:
                raise f.err("dlo.poisson", f"must be in (-1, 0.5), got {v!r}")
        else:
            vals[k] = f.number(v, f"dlo.{k}", positive=True)
    if vals["young"] > LIMITS["dlo_young_pa"]:
        raise f.err("dlo.young", f"must be at most {LIMITS['dlo_young_pa']:g} Pa, got {vals['young']:g}")
    if vals["length"] > LIMITS["dlo_length_m"]:
        raise f.err("dlo.length", f"must be at most {LIMITS['dlo_length_m']:g} m, got {vals['length']:g}")
    if vals["radius"] >= vals["length"] / 2:
        raise f.err("dlo.radius", f"must be less than half the length, got {vals['radius']:g} m")
    return DloSpec(**vals)


def _params(f: Fields, raw: Any) -> ModelParams:
    """The ``[model]`` table: the contact model's angles (degrees)."""
    raw_m = f.table(raw, "model", _MODEL_KEYS)
    mvals = {k: f.number(v, f"model.{k}") for k, v in raw_m.items()}
    try:
        return ModelParams(**mvals)
    except ValueError as e:
        raise f.err("model", str(e)) from None


def _objects(f: Fields, path: Path, raw: Any) -> tuple[SceneObject, ...]:
    """The ``[[objects]]``: each a box or a mesh, names unique."""
    if not isinstance(raw, list):
        raise f.err("objects", "must be an array of tables ([[objects]])")
    f.at_most(len(raw), "scene_objects", "objects", "objects")
    objects: list[SceneObject] = []
    seen: set[str] = set()
    for i, ro in enumerate(raw):
        f.table(ro, f"objects[{i}]", _OBJ_KEYS)
        oname = ro.get("name")
        if not isinstance(oname, str) or not NAME_RE.match(oname):
            raise f.err(f"objects[{i}].name", f"must be a name of letters, digits, '_' or '-', got {oname!r}")
        where = f"object {oname!r}"
        if oname in seen:
            raise f.err(where, "duplicate object name")
        seen.add(oname)
        if ("box" in ro) == ("mesh" in ro):
            raise f.err(where, "needs exactly one of 'box' or 'mesh'")
        pos = _vec3(f, ro.get("pos", [0, 0, 0]), f"{where}.pos")
        quat = _orientation(f, ro.get("quat", [1, 0, 0, 0]), f"{where}.quat")
        color = None
        if "color" in ro:
            color = _vec3(f, ro["color"], f"{where}.color")
            if any(not 0.0 <= c <= 1.0 for c in color):
                raise f.err(f"{where}.color", "components must be in [0, 1]")
        if "box" in ro:
            objects.append(_box(f, where, ro, SceneObject(oname, "box", pos, quat, color=color)))
        else:
            objects.append(_mesh(f, where, ro, path, SceneObject(oname, "mesh", pos, quat, color=color)))
    return tuple(objects)


def _box(f: Fields, where: str, ro: dict, obj: SceneObject) -> SceneObject:
    """A box object: ``obj`` with its size (and a pose given in the box table)."""
    box = f.table(ro["box"], f"{where}.box", _BOX_KEYS)
    if "size" not in box:
        raise f.err(f"{where}.box", "missing key 'size'")
    size = _vec3(f, box["size"], f"{where}.box.size")
    if any(s <= 0 for s in size):
        raise f.err(f"{where}.box.size", f"sizes must be positive, got {list(size)}")
    for k in ("pos", "quat"):
        if k in box and k in ro:
            raise f.err(where, f"'{k}' given both in the object and in its box")
    pos = _vec3(f, box["pos"], f"{where}.box.pos") if "pos" in box else obj.pos
    quat = _orientation(f, box["quat"], f"{where}.box.quat") if "quat" in box else obj.quat
    if "scale" in ro:
        raise f.err(f"{where}.scale", "only mesh objects take a scale")
    return replace(obj, pos=pos, quat=quat, size=size)


def _mesh(f: Fields, where: str, ro: dict, path: Path, obj: SceneObject) -> SceneObject:
    """A mesh object: ``obj`` with its mesh file (inside the scene file's directory) and scale."""
    mesh = ro["mesh"]
    if not isinstance(mesh, str) or not mesh:
        raise f.err(f"{where}.mesh", "must be a relative file path")
    mp = Path(mesh)
    if mp.is_absolute():
        raise f.err(f"{where}.mesh", f"{mesh!r}: must be relative to the scene file")
    base = path.resolve().parent
    try:
        full = (base / mp).resolve()
    except (RuntimeError, OSError) as e:  # a symlink loop (RuntimeError before Python 3.13)
        raise f.err(f"{where}.mesh", f"{mesh!r}: cannot be resolved: {e}") from None
    if base not in full.parents:
        raise f.err(f"{where}.mesh", f"{mesh!r}: must lie inside the scene file's directory")
    if full.suffix.lower() not in MESH_SUFFIXES:
        raise f.err(f"{where}.mesh", f"{mesh!r}: unsupported format (use {', '.join(MESH_SUFFIXES)})")
    if not full.is_file():
        raise f.err(f"{where}.mesh", f"mesh file {mesh!r} not found")
    limit = int(LIMITS["mesh_bytes"])
    if full.stat().st_size > limit:
        raise f.err(f"{where}.mesh", f"mesh file {mesh!r} is larger than {limit >> 20} MiB")
    scale = f.number(ro.get("scale", 1.0), f"{where}.scale", positive=True)
    return replace(obj, mesh_path=full, scale=scale)


__all__ = [
    "DloSpec",
    "GripperSpec",
    "Scene",
    "SceneError",
    "SceneObject",
    "builtin_scenes",
    "load_scene",
    "resolve_scene_path",
    "scenes_dir",
]
