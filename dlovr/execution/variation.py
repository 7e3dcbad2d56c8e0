"""Perturbing a scene for robustness trials: ``--vary KEY=SPEC``.

Keys name scene-file entries (docs/scenes.md):

- ``dlo.length``, ``dlo.radius``, ``dlo.young``, ``dlo.damping``, ``dlo.mass``, ``dlo.poisson``,
  ``dlo.friction``: a number of the cable;
- ``gripper.pos``: the gripper's start position (the cable hangs from it);
- ``objects.pos``: the positions of all objects together (one common shift: the environment as a
  whole sits elsewhere); ``objects.NAME.pos``: the position of the object ``NAME`` alone;
- ``objects.yaw``: the objects turned together about the vertical through their common centre (the
  mean of their positions), the angle (degrees) drawn uniformly from ``[-DEG, DEG]``;
- ``demo.KEY`` (``dlovr record --trials`` only): the person-like demonstrator
  (:mod:`dlovr.recording.person`, docs/people.md): ``demo.person=S`` (drift and tremor ``S`` times the
  defaults), ``demo.drift=M`` (m), ``demo.turn=DEG``, ``demo.tremor=M`` (m), ``demo.pace=A..B``,
  ``demo.ease=E``, ``demo.hesitate=S`` (s), ``demo.jog=M`` (m; 0: no key jogging). A demonstrator key
  is a level, not a draw: each trial's hand is drawn from the seed and the trial.

Specs:

- ``P%`` (numbers only): a relative change, the factor drawn uniformly from ``[1 - P/100, 1 + P/100]``;
- ``A..B`` (numbers only): a factor drawn from ``[A, B]``, log-uniformly (``0.5..2`` makes halving
  as likely as doubling); ``0 < A <= B``;
- ``D`` (positions only): an absolute offset in metres, each coordinate drawn uniformly from
  ``[-D, D]``; ``DEG`` (``objects.yaw`` only): the bound of the angle in degrees (at most 45).

Draws are deterministic: trial ``k`` of seed ``s`` draws key ``K`` from a generator seeded with
``(s, k, crc32(K))``, so a trial's perturbation does not depend on the other keys or trials.
Every problem is a :class:`VaryError` (one line).
"""

from __future__ import annotations

import math
import re
import zlib
from collections.abc import Sequence
from dataclasses import dataclass, replace
from typing import Any, cast

import numpy as np

from dlovr.inputs import InputError
from dlovr.transforms import quat_mul, quat_normalize, quat_rotate

NUMBER_KEYS = ("length", "radius", "young", "damping", "mass", "poisson", "friction")
#: ``demo.KEY`` keys (the person-like demonstrator's levels; ``pace`` a range, the others numbers).
DEMO_KEYS = ("person", "drift", "turn", "tremor", "pace", "ease", "hesitate", "jog")
_POS_HINT = "positions vary by an absolute offset in metres, e.g. {key}=0.005"
_NUM = r"[0-9]*\.?[0-9]+(?:[eE][-+]?[0-9]+)?"


class VaryError(InputError):
    """A ``--vary`` argument is not understood; the message is one line."""


@dataclass(frozen=True)
class Variation:
    """One ``--vary`` item: ``key``, ``kind`` (``relative``, ``range``, ``offset`` or ``level``) and its
    bounds: ``lo``/``hi`` factors, or ``hi`` the offset bound (m), or a demonstrator level ``lo..hi``
    (``lo == hi`` for a number)."""

    key: str
    kind: str
    lo: float
    hi: float
    spec: str

    @property
    def is_position(self) -> bool:
        return self.key.endswith(".pos")

    @property
    def is_angle(self) -> bool:
        return self.kind == "angle"

    def draw(self, seed: int, trial: int) -> float | tuple[float, ...]:
        """This variation's value in ``trial`` of ``seed``: a factor, or an offset (m, world); a
        demonstrator level is the level itself (a number, or ``(lo, hi)`` for a range)."""
        if self.kind == "level":
            return (self.lo, self.hi) if self.key == "demo.pace" else self.lo
        rng = np.random.default_rng([int(seed) & 0xFFFFFFFF, int(trial), zlib.crc32(self.key.encode())])
        if self.kind == "offset":
            offset = tuple(float(x) for x in rng.uniform(-self.hi, self.hi, 3))
            return cast(tuple[float, float, float], offset)
        if self.kind == "range":
            return float(math.exp(rng.uniform(math.log(self.lo), math.log(self.hi))))
        if self.kind == "angle":
            return float(rng.uniform(-self.hi, self.hi))
        return float(rng.uniform(self.lo, self.hi))

    def level(self, value: float | Sequence[float]) -> float:
        """A scalar for plotting: the factor, the angle's size (deg), or the offset's length (m)."""
        if isinstance(value, int | float):
            return abs(float(value)) if self.kind == "angle" else float(value)
        return float(math.sqrt(sum(float(x) ** 2 for x in value)))


def _parse_demo(item: str, key: str, spec: str) -> Variation:
    """A ``demo.KEY=LEVEL`` item (``pace``: ``A..B``, the others a number >= 0)."""
    name = key.split(".", 1)[1]
    if name not in DEMO_KEYS:
        known = ", ".join("demo." + k for k in DEMO_KEYS)
        raise VaryError(f"--vary {item!r}: unknown key {key!r} (known: {known})")
    if name == "pace":
        m = re.fullmatch(rf"({_NUM})\s*\.\.\s*({_NUM})", spec)
        if m is None or not 0 < float(m.group(1)) <= float(m.group(2)) <= 10:
            raise VaryError(f"--vary {item!r}: demo.pace is a range A..B of duration factors, "
                            "0 < A <= B <= 10")
        return Variation(key, "level", float(m.group(1)), float(m.group(2)), spec)
    bound = {"ease": 1.0, "hesitate": 10.0, "person": 20.0, "turn": 20.0}.get(name, 0.05)
    if re.fullmatch(_NUM, spec) is None or not 0 <= float(spec) <= bound:
        unit = {"ease": "", "hesitate": " s", "person": "x", "turn": " deg"}.get(name, " m")
        raise VaryError(f"--vary {item!r}: {key} is a number in [0, {bound:g}]{unit}")
    return Variation(key, "level", float(spec), float(spec), spec)


def parse_vary(item: str, scene: Any = None, demo: bool = False) -> Variation:
    """Parse ``KEY=SPEC`` (see the module docstring); with ``scene``, object names are checked;
    ``demo``: the demonstrator's ``demo.*`` keys are allowed (recording demonstrations)."""
    if "=" not in item:
        raise VaryError(f"--vary {item!r}: expected KEY=SPEC, e.g. dlo.length=10%")
    key, spec = (x.strip() for x in item.split("=", 1))
    parts = key.split(".")
    if parts[0] == "demo":
        if not demo:
            raise VaryError(
                f"--vary {item!r}: demo.* keys vary demonstrations (dlovr record --script S --trials N)"
            )
        return _parse_demo(item, key, spec)
    if key == "objects.yaw":
        if re.fullmatch(_NUM, spec) is None or not 0 <= float(spec) <= 45:
            why = "objects.yaw is an angle bound in [0, 45] degrees, e.g. objects.yaw=5"
            raise VaryError(f"--vary {item!r}: {why}")
        return Variation(key, "angle", 0.0, float(spec), spec)
    valid = (
        (len(parts) == 2 and parts[0] == "dlo" and parts[1] in NUMBER_KEYS)
        or key in ("gripper.pos", "objects.pos")
        or (len(parts) == 3 and parts[0] == "objects" and parts[2] == "pos")
    )
    if not valid:
        known = ", ".join(
            [*(f"dlo.{k}" for k in NUMBER_KEYS), "gripper.pos", "objects.pos", "objects.NAME.pos",
             "objects.yaw"]
        )
        raise VaryError(f"--vary {item!r}: unknown key {key!r} (known: {known})")
    if len(parts) == 3 and scene is not None and parts[1] not in {o.name for o in scene.objects}:
        names = ", ".join(o.name for o in scene.objects)
        raise VaryError(f"--vary {item!r}: scene {scene.name} has no object {parts[1]!r} (objects: {names})")
    is_pos = key.endswith(".pos")
    if m := re.fullmatch(rf"({_NUM})\s*%", spec):
        p = float(m.group(1))
        if is_pos:
            raise VaryError(f"--vary {item!r}: {_POS_HINT.format(key=key)}")
        if not 0 <= p < 100:
            raise VaryError(f"--vary {item!r}: a relative change must be in [0, 100) %")
        return Variation(key, "relative", 1.0 - p / 100.0, 1.0 + p / 100.0, spec)
    if m := re.fullmatch(rf"({_NUM})\s*\.\.\s*({_NUM})", spec):
        a, b = float(m.group(1)), float(m.group(2))
        if is_pos:
            raise VaryError(f"--vary {item!r}: {_POS_HINT.format(key=key)}")
        if not (0 < a <= b) or not math.isfinite(b):
            raise VaryError(f"--vary {item!r}: a factor range A..B needs 0 < A <= B")
        return Variation(key, "range", a, b, spec)
    if re.fullmatch(_NUM, spec):
        d = float(spec)
        if not is_pos:
            raise VaryError(f"--vary {item!r}: {key} varies by a relative change (10%) or a range (0.5..2)")
        if not (0 <= d <= 0.1):
            raise VaryError(f"--vary {item!r}: a position offset must be in [0, 0.1] m")
        return Variation(key, "offset", 0.0, d, spec)
    raise VaryError(f"--vary {item!r}: bad spec {spec!r} (use P%, A..B or metres)")



def parse_varies(items: Sequence[str], scene: Any = None, demo: bool = False) -> tuple[Variation, ...]:
    """Every ``--vary KEY=SPEC`` of a command; a key given twice is an error (:class:`VaryError`);
    ``demo``: the demonstrator's keys are allowed."""
    variations = tuple(parse_vary(v, scene, demo) for v in items)
    keys = [v.key for v in variations]
    if len(set(keys)) != len(keys):
        raise VaryError(f"--vary: key {next(k for k in keys if keys.count(k) > 1)!r} given twice")
    return variations

def _shift(pos: Sequence[float], d: Sequence[float]) -> tuple[float, float, float]:
    return (float(pos[0]) + d[0], float(pos[1]) + d[1], float(pos[2]) + d[2])


def perturb(scene: Any, variations: Sequence[Variation], seed: int, trial: int) -> tuple[Any, dict[str, Any]]:
    """The scene of ``trial`` (a ``dlovr.scene.Scene`` with its values changed) and the drawn values
    by key (factors; offsets as lists, m). The scene keeps its name and files: the convex
    decomposition of its objects (their own frames) still applies."""
    values: dict[str, Any] = {}
    dlo, gripper, objects = scene.dlo, scene.gripper, list(scene.objects)
    for v in variations:
        x = v.draw(seed, trial)
        values[v.key] = list(x) if isinstance(x, tuple) else x
        parts = v.key.split(".")
        if parts[0] == "demo":
            continue  # the demonstrator's level: no change of the scene
        off = cast(tuple[float, float, float], x)  # what a ".pos" key draws; the others draw a factor
        if parts[0] == "dlo":
            dlo = replace(dlo, **{parts[1]: getattr(dlo, parts[1]) * float(cast(float, x))})
        elif v.key == "gripper.pos":
            gripper = replace(gripper, pos=_shift(gripper.pos, off))
        elif v.key == "objects.pos":
            objects = [replace(o, pos=_shift(o.pos, off)) for o in objects]
        elif v.key == "objects.yaw":
            objects = _turned(objects, float(cast(float, x)))
        else:
            objects = [replace(o, pos=_shift(o.pos, off)) if o.name == parts[1] else o for o in objects]
    if not -1.0 < dlo.poisson < 0.5:
        dlo = replace(dlo, poisson=min(max(dlo.poisson, -0.99), 0.49))
    return replace(scene, dlo=dlo, gripper=gripper, objects=tuple(objects)), values


def _turned(objects: Sequence[Any], deg: float) -> list[Any]:
    """``objects`` turned together by ``deg`` about the vertical through the mean of their positions
    (positions and orientations)."""
    if not objects or deg == 0.0:
        return list(objects)
    c = [sum(float(o.pos[i]) for o in objects) / len(objects) for i in range(3)]
    half = math.radians(deg) / 2.0
    q = np.array([math.cos(half), 0.0, 0.0, math.sin(half)])
    out = []
    for o in objects:
        d = quat_rotate(q, np.array([float(o.pos[i]) - c[i] for i in range(3)]))
        pos = (c[0] + float(d[0]), c[1] + float(d[1]), c[2] + float(d[2]))
        quat = quat_normalize(quat_mul(q, np.asarray(o.quat, float)))
        out.append(replace(o, pos=pos, quat=tuple(float(x) for x in quat)))
    return out


def object_turns(nominal: Any, actual: Any) -> tuple[tuple[str, tuple[float, float, float, float]], ...]:
    """How each object of ``actual`` is turned against the same object of ``nominal`` (the rotation
    ``R = R_actual R_nominal^T`` as a unit quaternion wxyz, world), by name, for those turned by more
    than 1e-9 rad: what a registered run is told besides :func:`object_shifts`."""
    before = {o.name: np.asarray(o.quat, float) for o in nominal.objects}
    out = []
    for o in actual.objects:
        if o.name not in before:
            continue
        q0 = before[o.name]
        r = quat_normalize(quat_mul(np.asarray(o.quat, float), np.array([q0[0], -q0[1], -q0[2], -q0[3]])))
        if r[0] < 0.0:
            r = -r
        if math.sqrt(float(r[1]) ** 2 + float(r[2]) ** 2 + float(r[3]) ** 2) > 1e-9:
            out.append((o.name, cast(tuple[float, float, float, float], tuple(float(x) for x in r))))
    return tuple(out)


def object_shifts(nominal: Any, actual: Any) -> tuple[tuple[str, tuple[float, float, float]], ...]:
    """Where each object of ``actual`` (a scene) sits against the same object of ``nominal``, by
    name: the translation ``t`` of the rigid motion ``p -> R p + t`` (m, world) that takes the
    nominal object to the actual one, ``R`` its turn (:func:`object_turns`; for an object that is
    not turned, ``t`` is its position's shift): what a registered run is told
    (:class:`dlovr.execution.executor.ExecOptions` ``object_shifts``). Objects only one scene has
    are left out."""
    before = {o.name: o.pos for o in nominal.objects}
    turns = dict(object_turns(nominal, actual))
    out = []
    for o in actual.objects:
        if o.name not in before:
            continue
        p0 = np.array([float(x) for x in before[o.name]])
        moved = quat_rotate(np.asarray(turns[o.name], float), p0) if o.name in turns else p0
        out.append((o.name, (float(o.pos[0]) - float(moved[0]), float(o.pos[1]) - float(moved[1]),
                             float(o.pos[2]) - float(moved[2]))))
    return tuple(out)
