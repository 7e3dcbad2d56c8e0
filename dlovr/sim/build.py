"""Building the MuJoCo model of a scene: obstacles, the cable rod and the gripper.

The model (MuJoCo 4.0):

- obstacles: one static body per scene object, one mesh geom per *convex piece* of the object
  (geom name ``"<object>.P<k>"``), so that every contact names its object and piece;
- the DLO: a 1-D ``flexcomp`` rod named ``dlo`` lying in the world (not inside the gripper body), with
  ``<elasticity young poisson damping>`` and ``<edge equality="true">``; its point ``i`` is the flex
  vertex ``i`` (``P_0 = V_S`` held by the gripper, ``P_n = V_E``);
- the gripper: a mocap body ``gripper`` whose z axis is ``G_z``. The rod starts straight, leaving the
  gripper along ``-G_z`` (point ``i`` at ``gripper.pos - i * seg * G_z``): ``G_z`` points from the cable
  into the gripper, so the identity orientation holds the cable hanging straight down, and the
  gripper's contact vector ``C(V_S/G_z) = z`` (eq. 2, docs/model.md) is, like ``-N(F)`` of a face, the
  direction in which the gripper blocks the cable. It is held by two
  ``<connect>`` equalities (points 0 and 1) and a joint equality locking the first twist joint
  ``dlo_twist_0`` (so a dragged cable does not roll).

The MjSpec Python API cannot give a ``make_flex`` rod its elasticity (``body.make_flex`` has no
elasticity arguments and the rod's twist bodies are only generated for an elastic flexcomp when it
is expanded), so the rod alone is parsed from a generated ``<flexcomp>`` element (built with
:mod:`xml.etree`, never by string concatenation); every other element is added with ``MjSpec``.

Typical use (headless)::

    from dlovr.scene import load_scene
    from dlovr.script import load_script
    from dlovr.sim import Simulator

    sim = Simulator(load_scene("table"), track=True)
    for step in sim.run(load_script("scenes/table.script.toml")):
        step.time, step.points, step.contacts, step.situation, step.discrete
    sim.tracker.transitions()   # the debounced situations with their transition classes

``dlovr scene export NAME -o model.xml``: ``export_xml(build_model(...).spec, path)`` writes the
compiled MJCF together with its meshes (see :func:`export_xml`).
"""

from __future__ import annotations

import xml.etree.ElementTree as ET
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import mujoco
import numpy as np

from dlovr.transforms import quat_normalize, quat_rotate

#: Name of the rod (flexcomp) and prefix of its generated bodies/joints (``dlo_<i>``, ``dlo_twist_<i>``).
ROD = "dlo"
#: Name of the mocap gripper body.
GRIPPER = "gripper"

TIMESTEP = 0.002
CONTACT_SOLREF = (0.004, 1.0)
#: Impedance of the cable's contacts: 0.95 at the surface rising to 0.999 at 1 mm deep. The 0.999
#: (0.99 before) keeps a loaded contact from giving way: a stiff cable pushed 40 mm along a 60° V sank
#: 6.2 mm and diverged, now 0.95 mm (docs/recordings.md, "Reducing jams", measured there with other
#: settings that did not help). A narrower width (0.5 mm) sank 0.65 mm but lost a corner state.
CONTACT_SOLIMP = (0.95, 0.999, 0.001, 0.5, 2.0)
#: Detect-only band (no force) beyond the surface: cuts contact flicker.
CONTACT_GAP = 0.001
EQ_SOLREF = (0.004, 1.0)
EQ_SOLIMP = (0.95, 0.99, 0.001, 0.5, 2.0)

#: Segment count up to which the rod's edge constraints use :data:`EQ_SOLIMP` as it is.
EDGE_SOLIMP_SEGMENTS = 40


def edge_solimp(segments: int) -> tuple[float, ...]:
    """Impedance of the rod's edge (length) constraints for a rod of ``segments`` segments.

    Under a load (the cable's weight, a drag) a soft constraint settles at a violation proportional
    to ``(1 - d) / d`` over its stiffness, which scales with the segment mass: relative to the
    segment length the stretch grows with the square of the segment count (a hanging 0.25 m cable
    stretched 1% at 25 segments, 10% at 80). Beyond :data:`EDGE_SOLIMP_SEGMENTS` the impedance
    ``d`` is raised so that ``1 - d`` falls with that square and a finer rod stretches as one of
    :data:`EDGE_SOLIMP_SEGMENTS` segments does; up to it :data:`EQ_SOLIMP` applies unchanged.
    """
    dmin, dmax, *rest = EQ_SOLIMP
    scale = min(1.0, (EDGE_SOLIMP_SEGMENTS / max(int(segments), 1)) ** 2)
    if scale == 1.0:
        return tuple(EQ_SOLIMP)
    return (1.0 - (1.0 - dmin) * scale, 1.0 - (1.0 - dmax) * scale, *rest)


_WARNINGS_FATAL = (
    "mjWARN_BADQACC",
    "mjWARN_BADQPOS",
    "mjWARN_BADQVEL",
    "mjWARN_CNSTRFULL",
    "mjWARN_CONTACTFULL",
)


class SimulationDiverged(RuntimeError):
    """The simulation became invalid (NaN, MuJoCo instability warning, cable over-stretched).

    ``step`` is the index of the offending step (1 = the first ``mj_step``), ``time`` its time in s.
    """

    def __init__(self, step: int, time: float, reason: str):
        super().__init__(f"simulation diverged at step {step} (t = {time:.4f} s): {reason}")
        self.step = step
        self.time = time
        self.reason = reason


# --------------------------------------------------------------------------------------------------
# Inputs


@dataclass(frozen=True)
class Obstacle:
    """A static scene object given as its convex pieces.

    ``pieces``: vertex arrays (k, 3) in the object's local frame, each the vertices of one convex piece
    (MuJoCo collides with their convex hull). ``pos``/``quat`` (wxyz) place the object in the world.
    """

    name: str
    pieces: Sequence[np.ndarray]
    pos: Sequence[float] = (0.0, 0.0, 0.0)
    quat: Sequence[float] = (1.0, 0.0, 0.0, 0.0)
    friction: float | None = None
    rgba: Sequence[float] = (0.6, 0.6, 0.65, 1.0)


@dataclass(frozen=True)
class DloParams:
    """The cable. Any object with these attributes (e.g. ``dlovr.scene.DloSpec``) is accepted too."""

    length: float = 0.3
    radius: float = 0.005
    segments: int = 20
    young: float = 2e7
    damping: float = 0.01
    mass: float = 0.05
    poisson: float = 0.3
    friction: float = 0.5


@dataclass(frozen=True)
class GripperPose:
    """Start pose of the gripper (``quat`` wxyz); the cable leaves it along ``-G_z`` (straight down for
    the identity orientation)."""

    pos: Sequence[float] = (0.0, 0.0, 1.0)
    quat: Sequence[float] = (1.0, 0.0, 0.0, 0.0)


# --------------------------------------------------------------------------------------------------
# Model


@dataclass
class BuiltModel:
    """A compiled model and the name -> index maps the simulator needs."""

    spec: mujoco.MjSpec
    model: mujoco.MjModel
    flex_id: int
    vert_adr: int
    nvert: int
    mocap_id: int
    seg_length: float
    geom_piece: dict[int, tuple[str, int]]  # geom id -> (object name, piece index)
    twist_joints: list[str] = field(default_factory=list)


def _rod_spec(dlo: Any, start: np.ndarray, direction: np.ndarray) -> mujoco.MjSpec:
    n = int(dlo.segments)
    if n < 2:
        raise ValueError(f"the DLO needs at least 2 segments, got {n}")
    seg = float(dlo.length) / n
    pts = [start - i * seg * direction for i in range(n + 1)]
    root = ET.Element("mujoco", model="dlovr")
    wb = ET.SubElement(root, "worldbody")
    selfcollide = "auto" if seg > 2.2 * float(dlo.radius) else "none"
    fc = ET.SubElement(
        wb,
        "flexcomp",
        name=ROD,
        type="direct",
        dim="1",
        radius=repr(float(dlo.radius)),
        mass=repr(float(dlo.mass)),
        point=" ".join(repr(float(c)) for p in pts for c in p),
        element=" ".join(f"{i} {i + 1}" for i in range(n)),
        rgba="0.85 0.35 0.1 1",
    )
    ET.SubElement(
        fc,
        "elasticity",
        young=repr(float(dlo.young)),
        poisson=repr(float(getattr(dlo, "poisson", 0.3))),
        damping=repr(float(dlo.damping)),
    )
    ET.SubElement(
        fc,
        "edge",
        equality="true",
        solref=" ".join(map(repr, EQ_SOLREF)),
        solimp=" ".join(map(repr, edge_solimp(n))),
    )
    mu = float(getattr(dlo, "friction", 0.5))
    ET.SubElement(
        fc,
        "contact",
        selfcollide=selfcollide,
        solref=" ".join(map(repr, CONTACT_SOLREF)),
        solimp=" ".join(map(repr, CONTACT_SOLIMP)),
        gap=repr(CONTACT_GAP),
        friction=f"{mu!r} 0.005 0.0001",
        condim="3",
    )
    return mujoco.MjSpec.from_string(ET.tostring(root, encoding="unicode"))


def build_model(
    obstacles: Sequence[Obstacle],
    dlo: Any,
    gripper: Any,
    *,
    timestep: float = TIMESTEP,
    gravity: Sequence[float] = (0.0, 0.0, -9.81),
) -> BuiltModel:
    """Build and compile the MuJoCo model of a scene.

    ``dlo``: attributes ``length radius segments young damping mass`` (and optionally ``poisson
    friction``), e.g. :class:`DloParams` or ``dlovr.scene.DloSpec``. ``gripper``: attributes ``pos`` and
    ``quat`` (wxyz), e.g. :class:`GripperPose` or ``dlovr.scene.GripperSpec``.
    """
    gpos = np.asarray(gripper.pos, dtype=float)
    gquat = quat_normalize(np.asarray(gripper.quat, dtype=float))
    gz = quat_rotate(gquat, np.array([0.0, 0.0, 1.0]))
    spec = _rod_spec(dlo, gpos, gz)
    spec.modelname = "dlovr"
    _set_options(spec, timestep, gravity)
    mu = float(getattr(dlo, "friction", 0.5))
    for ob in obstacles:
        _add_obstacle(spec, ob, mu)
    seg = float(dlo.length) / int(dlo.segments)
    _add_gripper(spec, gpos, gquat, seg, int(dlo.segments))
    model = spec.compile()
    flex_id = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_FLEX, ROD)
    geom_piece: dict[int, tuple[str, int]] = {}
    for ob in obstacles:
        for k in range(len(ob.pieces)):
            gid = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_GEOM, f"{ob.name}.P{k}")
            geom_piece[gid] = (ob.name, k)
    twist = [j.name for j in spec.joints if j.name.startswith(f"{ROD}_twist")]
    return BuiltModel(
        spec=spec,
        model=model,
        flex_id=flex_id,
        vert_adr=int(model.flex_vertadr[flex_id]),
        nvert=int(model.flex_vertnum[flex_id]),
        mocap_id=int(model.body_mocapid[mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_BODY, GRIPPER)]),
        seg_length=seg,
        geom_piece=geom_piece,
        twist_joints=twist,
    )


def _set_options(spec: mujoco.MjSpec, timestep: float, gravity: Sequence[float]) -> None:
    """The simulation options: ``timestep``, discrete integrator, Newton solver, ``gravity``; angles
    in radians."""
    opt = spec.option
    opt.timestep = float(timestep)
    opt.integrator = mujoco.mjtIntegrator.mjINT_DISCRETE
    opt.solver = mujoco.mjtSolver.mjSOL_NEWTON
    opt.tolerance = 1e-6
    opt.gravity = list(map(float, gravity))
    spec.compiler.degree = False


def _add_obstacle(spec: mujoco.MjSpec, ob: Obstacle, mu: float) -> None:
    """Obstacle ``ob`` as a body with one mesh geom per convex piece (geom ``"<obj>.P<k>"``), its
    friction ``mu`` unless it has its own."""
    body = spec.worldbody.add_body(
        name=ob.name, pos=list(map(float, ob.pos)), quat=list(map(float, ob.quat))
    )
    for k, verts in enumerate(ob.pieces):
        v = np.asarray(verts, dtype=float).reshape(-1, 3)
        mname = f"{ob.name}.P{k}"
        spec.add_mesh(name=mname, uservert=v.ravel().tolist())
        f = mu if ob.friction is None else float(ob.friction)
        body.add_geom(
            name=mname,
            type=mujoco.mjtGeom.mjGEOM_MESH,
            meshname=mname,
            solref=list(CONTACT_SOLREF),
            solimp=list(CONTACT_SOLIMP),
            gap=CONTACT_GAP,
            friction=[f, 0.005, 0.0001],
            condim=3,
            rgba=list(map(float, ob.rgba)),
        )


def _add_gripper(spec: mujoco.MjSpec, gpos: np.ndarray, gquat: np.ndarray, seg: float, segments: int) -> None:
    """The gripper: a mocap body at ``gpos``/``gquat`` holding the rod's first two vertices (``seg``
    apart) and its first twist joint by equality constraints."""
    g = spec.worldbody.add_body(name=GRIPPER, mocap=True, pos=gpos.tolist(), quat=gquat.tolist())
    g.add_site(name="gripper_site", size=[0.01, 0.0, 0.0], rgba=[0.2, 0.6, 0.9, 0.5])
    for i, anchor in ((0, [0.0, 0.0, 0.0]), (1, [0.0, 0.0, -seg])):
        eq = spec.add_equality(
            name=f"hold_{i}",
            type=mujoco.mjtEq.mjEQ_CONNECT,
            objtype=mujoco.mjtObj.mjOBJ_BODY,
            name1=GRIPPER,
            name2=f"{ROD}_{i}",
            solref=list(EQ_SOLREF),
            solimp=list(edge_solimp(segments)),  # as stiff as the rod's edges: see edge_solimp
        )
        eq.data[0:3] = anchor
    spec.add_equality(
        name="hold_twist",
        type=mujoco.mjtEq.mjEQ_JOINT,
        objtype=mujoco.mjtObj.mjOBJ_JOINT,
        name1=f"{ROD}_twist_0",
        solref=list(EQ_SOLREF),
        solimp=list(EQ_SOLIMP),
    )


def export_xml(built: BuiltModel, path: str | Path) -> Path:
    """Write the compiled model as MJCF at ``path`` (meshes inline as vertex lists).

    The file is loadable by plain MuJoCo (``mujoco.MjModel.from_xml_path``) and gives the same model.
    Intended for ``dlovr scene export NAME -o model.xml``.
    """
    from dlovr.outputs import write_output

    path = Path(path)
    write_output(path, built.spec.to_xml())  # atomic: never half a file (replaces: the caller checks)
    return path


