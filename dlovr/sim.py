"""MuJoCo simulation of the cable (the only module of dlovr that imports :mod:`mujoco`).

The model (see ``../shared/NOTES.md``, "The cable in MuJoCo 4.0"):

- obstacles: one static body per scene object, one mesh geom per *convex piece* of the object
  (geom name ``"<object>.P<k>"``), so that every contact names its object and piece;
- the DLO: a 1-D ``flexcomp`` rod named ``dlo`` lying in the world (not inside the gripper body), with
  ``<elasticity young poisson damping>`` and ``<edge equality="true">``; its point ``i`` is the flex
  vertex ``i`` (``P_0 = V_S`` held by the gripper, ``P_n = V_E``);
- the gripper: a mocap body ``gripper`` whose z axis is ``G_z``. The rod starts straight, leaving the
  gripper along ``-G_z`` (point ``i`` at ``gripper.pos - i * seg * G_z``): ``G_z`` points from the cable
  into the gripper, so the identity orientation holds the cable hanging straight down, and the
  gripper's contact vector ``C(V_S/G_z) = z`` (MODEL.md eq. 2) is, like ``-N(F)`` of a face, the
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

import math
import xml.etree.ElementTree as ET
from collections.abc import Iterator, Sequence
from dataclasses import dataclass, field
from functools import cached_property
from pathlib import Path
from typing import Any

import mujoco
import numpy as np

from dlovr.script import Script, dot, norm, quat_normalize, quat_rotate, slerp

#: Name of the rod (flexcomp) and prefix of its generated bodies/joints (``dlo_<i>``, ``dlo_twist_<i>``).
ROD = "dlo"
#: Name of the mocap gripper body.
GRIPPER = "gripper"

TIMESTEP = 0.002
CONTACT_SOLREF = (0.004, 1.0)
CONTACT_SOLIMP = (0.95, 0.99, 0.001, 0.5, 2.0)
#: Detect-only band (no force) beyond the surface: cuts contact flicker (NOTES.md).
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
    opt = spec.option
    opt.timestep = float(timestep)
    opt.integrator = mujoco.mjtIntegrator.mjINT_DISCRETE
    opt.solver = mujoco.mjtSolver.mjSOL_NEWTON
    opt.tolerance = 1e-6
    opt.gravity = list(map(float, gravity))
    spec.compiler.degree = False
    mu = float(getattr(dlo, "friction", 0.5))

    for ob in obstacles:
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

    seg = float(dlo.length) / int(dlo.segments)
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
            solimp=list(edge_solimp(int(dlo.segments))),  # as stiff as the rod's edges: see edge_solimp
        )
        eq.data[0:3] = anchor
    eq = spec.add_equality(
        name="hold_twist",
        type=mujoco.mjtEq.mjEQ_JOINT,
        objtype=mujoco.mjtObj.mjOBJ_JOINT,
        name1=f"{ROD}_twist_0",
        solref=list(EQ_SOLREF),
        solimp=list(EQ_SOLIMP),
    )
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


def export_xml(built: BuiltModel, path: str | Path) -> Path:
    """Write the compiled model as MJCF at ``path`` (meshes inline as vertex lists).

    The file is loadable by plain MuJoCo (``mujoco.MjModel.from_xml_path``) and gives the same model.
    Intended for ``dlovr scene export NAME -o model.xml``.
    """
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(built.spec.to_xml())
    return path


# --------------------------------------------------------------------------------------------------
# Per-step records


@dataclass(frozen=True)
class RodContact:
    """One raw MuJoCo contact between the rod and an obstacle piece.

    ``point``: cable point index when MuJoCo reports a vertex (plane-like contacts), else ``None``;
    ``segment``: segment index (segment ``i`` joins points ``i`` and ``i+1``) when it reports an element.
    ``normal`` points from the obstacle toward the rod; ``pos`` is MuJoCo's contact point (midway),
    ``surface`` the obstacle's surface point; ``dist`` < 0 is penetration. ``force``: normal force (N),
    0 for contacts in the detect-only gap band (``active`` False).
    """

    point: int | None
    segment: int | None
    obj: str
    piece: int
    geom: str
    dist: float
    normal: np.ndarray
    pos: np.ndarray
    surface: np.ndarray
    force: float
    active: bool


@dataclass(frozen=True, eq=False)
class ContactArrays:
    """Raw rod-obstacle contacts of one step, one row per MuJoCo contact (see :class:`RodContact`).

    ``point``/``segment``: -1 where MuJoCo does not report a vertex/element; ``geom``: MuJoCo geom id;
    ``obj``: index into ``names[0]`` (object names); ``names[1]``: geom names by ``geom`` id.
    ``self_pairs``: (k, 2) touching segment pairs of the rod itself.
    """

    point: np.ndarray
    segment: np.ndarray
    geom: np.ndarray
    obj: np.ndarray
    piece: np.ndarray
    dist: np.ndarray
    normal: np.ndarray
    pos: np.ndarray
    force: np.ndarray
    active: np.ndarray
    self_pairs: np.ndarray
    names: tuple[tuple[str, ...], dict[int, str]]

    def __len__(self) -> int:
        return len(self.dist)

    @property
    def surface(self) -> np.ndarray:
        """Surface points of the obstacles (``pos - normal * dist / 2``)."""
        return self.pos - self.normal * (self.dist / 2.0)[:, None]

    def as_list(self) -> tuple[RodContact, ...]:
        objs, gnames = self.names
        surf = self.surface
        return tuple(
            RodContact(
                point=int(self.point[i]) if self.point[i] >= 0 else None,
                segment=int(self.segment[i]) if self.segment[i] >= 0 else None,
                obj=objs[self.obj[i]],
                piece=int(self.piece[i]),
                geom=gnames[int(self.geom[i])],
                dist=float(self.dist[i]),
                normal=self.normal[i].copy(),
                pos=self.pos[i].copy(),
                surface=surf[i].copy(),
                force=float(self.force[i]),
                active=bool(self.active[i]),
            )
            for i in range(len(self.dist))
        )


_NO_PAIRS = np.zeros((0, 2), int)
#: Default relative segment-length change beyond which a run is declared diverged (see Simulator).
DEFAULT_MAX_STRETCH = 0.25
_PYRAMIDAL = int(mujoco.mjtCone.mjCONE_PYRAMIDAL)
_EDGES = [np.arange(2 * (k - 1)) for k in range(7)]  # a pyramidal cone's edge rows, by contact dim

_EMPTY_CONTACTS = ContactArrays(
    point=np.zeros(0, int),
    segment=np.zeros(0, int),
    geom=np.zeros(0, int),
    obj=np.zeros(0, int),
    piece=np.zeros(0, int),
    dist=np.zeros(0),
    normal=np.zeros((0, 3)),
    pos=np.zeros((0, 3)),
    force=np.zeros(0),
    active=np.zeros(0, bool),
    self_pairs=np.zeros((0, 2), int),
    names=((), {}),
)


@dataclass(frozen=True)
class StepRecord:
    """What one simulation step yields.

    ``points``: (n+1, 3) centerline points ``P_0..P_n``; ``vectors``: (n, 3) DLO vectors
    ``P_{i+1} - P_i``; gripper pose (``gripper_quat`` wxyz, ``gripper_z`` = ``G_z``) and the commanded
    target; ``contact_arrays``: raw rod-obstacle contacts as arrays (``contacts``: the same as
    :class:`RodContact` objects); ``self_contacts``: pairs of touching segments; ``gripper_force``:
    the force (N, world frame) the cable exerts on the gripper, as a wrist force sensor would read it.
    """

    step: int
    time: float
    points: np.ndarray
    gripper_pos: np.ndarray
    gripper_quat: np.ndarray
    target_pos: np.ndarray
    target_quat: np.ndarray
    contact_arrays: ContactArrays
    gripper_force: np.ndarray = field(default_factory=lambda: np.zeros(3))
    state: Any = None  # the step's dlovr.contacts.ContactState when the simulator tracks contacts

    @cached_property
    def vectors(self) -> np.ndarray:
        """(n, 3) DLO vectors ``P_{i+1} - P_i`` (m, world frame)."""
        return np.diff(self.points, axis=0)

    @cached_property
    def gripper_z(self) -> np.ndarray:
        """The gripper's z axis ``G_z`` (unit, world frame)."""
        return quat_rotate(self.gripper_quat, np.array([0.0, 0.0, 1.0]))

    @property
    def situation(self) -> Any:
        """Topological contact situation of this step (``Simulator(..., track=True)``)."""
        return None if self.state is None else self.state.topological

    @property
    def discrete(self) -> Any:
        """Discrete contact situation of this step (``Simulator(..., track=True)``)."""
        return None if self.state is None else self.state.discrete

    @cached_property
    def contacts(self) -> tuple[RodContact, ...]:
        """The raw rod-obstacle contacts as :class:`RodContact` objects (built on first access)."""
        return self.contact_arrays.as_list()

    @property
    def self_contacts(self) -> tuple[tuple[int, int], ...]:
        """Pairs of touching segments of the rod (self-collision)."""
        return tuple((int(a), int(b)) for a, b in self.contact_arrays.self_pairs)


@dataclass(frozen=True)
class SimState:
    """Full checkpoint: MuJoCo's ``mjSTATE_INTEGRATION`` plus the simulator's own counters/target."""

    mj: np.ndarray
    step: int
    target_pos: np.ndarray
    target_quat: np.ndarray


# --------------------------------------------------------------------------------------------------
# Simulator


def obstacles_from_scene(scene: Any, pieces: dict[str, tuple[list[np.ndarray], bool]]) -> list[Obstacle]:
    """Obstacles of a ``dlovr.scene.Scene`` from its convex decomposition
    (``dlovr.geometry.scene_pieces``): MuJoCo piece ``k`` (geom ``"<obj>.P<k>"``) is geometry's
    ``Piece.index == k``."""
    out = []
    for obj in scene.objects:
        rgba = (*obj.color, 1.0) if getattr(obj, "color", None) else (0.6, 0.6, 0.65, 1.0)
        out.append(
            Obstacle(
                name=obj.name,
                pieces=[np.asarray(p, dtype=float) for p in pieces[obj.name][0]],
                pos=tuple(obj.pos),
                quat=tuple(obj.quat),
                rgba=rgba,
            )
        )
    return out


class Simulator:
    """Steps the cable model; the gripper follows a commanded target with bounded speed.

    ``Simulator(scene)`` with a ``dlovr.scene.Scene``, or ``Simulator.from_parts(obstacles, dlo,
    gripper)``. Set the target with :meth:`set_target`; :meth:`step` advances one time step (2 ms) and
    returns a :class:`StepRecord`; :meth:`run` plays a :class:`dlovr.script.Script`.

    ``max_speed`` (m/s) and ``max_angular_speed`` (rad/s) bound the gripper's motion toward the target;
    ``max_stretch`` is the relative change of a segment's length (stretch or squeeze) beyond which the
    run is declared diverged. Its default, 25%, lies above what ordinary motion does to the rod: its
    edges are soft constraints, and a tip pushed onto a surface at the gripper's top speed squeezes
    the segments behind it by up to about 11% for a few steps (measured on the table scene at 40
    segments; 80-segment demos reach about 18%), while a numerical blow-up goes far beyond.
    ``pieces`` fixes the obstacles' convex decomposition (``dlovr.geometry.scene_pieces``; computed
    when not given; kept as ``sim.pieces``). ``track=True`` (scene needed) also extracts the contact
    states every step: ``sim.tracker`` is a :class:`dlovr.contacts.ContactTracker` and each record
    carries its ``state`` (``.situation``, ``.discrete``).
    """

    def __init__(
        self,
        scene: Any = None,
        *,
        built: BuiltModel | None = None,
        max_speed: float = 0.25,
        max_angular_speed: float = 2.0,
        max_stretch: float = DEFAULT_MAX_STRETCH,
        track: bool = False,
        pieces: dict[str, tuple[list[np.ndarray], bool]] | None = None,
    ):
        self.pieces = pieces
        if built is None:
            if scene is None:
                raise ValueError("Simulator needs a scene or a built model")
            if self.pieces is None:
                from dlovr.geometry import scene_pieces

                self.pieces = scene_pieces(scene)
            built = build_model(obstacles_from_scene(scene, self.pieces), scene.dlo, scene.gripper)
        self.scene = scene
        self.tracker: Any = None
        if track:
            if scene is None:
                raise ValueError("contact tracking needs the scene")
            from dlovr.contacts import ContactTracker
            from dlovr.geometry import SceneGeometry

            geometry = SceneGeometry.from_scene(scene, pieces=self.pieces)
            self.tracker = ContactTracker(geometry, scene.params)
        self.built = built
        self.max_stretch = max_stretch
        self.model = built.model
        self.data = mujoco.MjData(self.model)
        self.max_speed = float(max_speed)
        self.max_angular_speed = float(max_angular_speed)
        self.step_index = 0
        m = self.model
        self._fatal = np.array([int(getattr(mujoco.mjtWarning, w)) for w in _WARNINGS_FATAL])
        self._geom_names = {g: mujoco.mj_id2name(m, mujoco.mjtObj.mjOBJ_GEOM, g) for g in built.geom_piece}
        objs = tuple(dict.fromkeys(o for o, _ in built.geom_piece.values()))
        self._obj_of_geom = np.full(m.ngeom, -1, dtype=int)
        self._piece_of_geom = np.full(m.ngeom, -1, dtype=int)
        for g, (o, k) in built.geom_piece.items():
            self._obj_of_geom[g] = objs.index(o)
            self._piece_of_geom[g] = k
        self._names = (objs, self._geom_names)
        eq = mujoco.mjtObj.mjOBJ_EQUALITY
        self._hold_rows: tuple[int, np.ndarray] | None = None
        self._hold_ids = np.array([mujoco.mj_name2id(m, eq, f"hold_{i}") for i in range(2)], dtype=np.int32)
        mujoco.mj_forward(m, self.data)
        self._reset_warnings()
        mid = built.mocap_id
        self.target_pos = self.data.mocap_pos[mid].copy()
        self.target_quat = self.data.mocap_quat[mid].copy()
        deep = [c for c in self.contacts() if c.dist < -0.5 * float(m.flex_radius[built.flex_id])]
        if deep:
            c = min(deep, key=lambda c: c.dist)
            raise ValueError(
                f"the cable's start pose (straight along -G_z from the gripper) penetrates {c.geom} "
                f"by {-c.dist * 1000:.1f} mm at segment {c.segment}: change the gripper pose"
            )

    @classmethod
    def from_parts(cls, obstacles: Sequence[Obstacle], dlo: Any, gripper: Any, **kw: Any) -> Simulator:
        """Simulator from obstacles given as convex pieces (no scene file needed)."""
        timestep = kw.pop("timestep", TIMESTEP)
        return cls(built=build_model(obstacles, dlo, gripper, timestep=timestep), **kw)

    # -- gripper ------------------------------------------------------------------------------------

    def set_target(self, pos: Sequence[float], quat: Sequence[float] | None = None) -> None:
        """Command the gripper pose (world ``pos``, ``quat`` wxyz; ``None`` keeps the orientation)."""
        p = np.asarray(pos, dtype=float)
        if p.shape != (3,) or not np.all(np.isfinite(p)):
            raise ValueError(f"gripper target position must be 3 finite numbers, got {pos!r}")
        self.target_pos = p.copy()
        if quat is not None:
            q = np.asarray(quat, dtype=float)
            if q.shape != (4,) or not np.all(np.isfinite(q)) or norm(q) < 1e-9:
                raise ValueError(f"gripper target quaternion must be 4 finite numbers, not all 0: {quat!r}")
            self.target_quat = quat_normalize(q)

    def _move_mocap(self) -> None:
        d, mid, dt = self.data, self.built.mocap_id, self.model.opt.timestep
        pos = d.mocap_pos[mid]
        # a gripper already at its target stays put (the general formulas below give the same values)
        if pos.tolist() != self.target_pos.tolist():
            delta = self.target_pos - pos
            dist = norm(delta)  # not np.linalg.norm: this feeds MuJoCo (see dlovr.script.dot)
            vmax = self.max_speed * dt
            d.mocap_pos[mid] = self.target_pos if dist <= vmax else pos + delta * (vmax / dist)
        q = d.mocap_quat[mid]
        tq = self.target_quat
        if q.tolist() != tq.tolist():
            q = q.copy()
            angle = 2.0 * math.acos(min(1.0, abs(dot(q, tq))))
            wmax = self.max_angular_speed * dt
            d.mocap_quat[mid] = tq if angle <= wmax else slerp(q, tq, wmax / angle)

    # -- stepping -----------------------------------------------------------------------------------

    @property
    def max_stretch(self) -> float:
        """Relative segment stretch beyond which a step is declared diverged."""
        return self._max_stretch

    @max_stretch.setter
    def max_stretch(self, value: float) -> None:
        self._max_stretch = float(value)
        seg = float(self.built.seg_length)
        # squared segment lengths beyond these go to the exact test (bounds slightly inside it)
        self._length2_bounds = (
            (seg * (1.0 - self._max_stretch)) ** 2 * (1.0 + 1e-9),
            (seg * (1.0 + self._max_stretch)) ** 2 * (1.0 - 1e-9),
        )

    @property
    def time(self) -> float:
        return float(self.data.time)

    def points(self) -> np.ndarray:
        """Centerline points P_0..P_n, shape (n+1, 3) (a copy)."""
        b = self.built
        return self.data.flexvert_xpos[b.vert_adr : b.vert_adr + b.nvert].copy()

    def step(self, n: int = 1) -> StepRecord:
        """Advance ``n`` time steps; return the record of the last one. Raises SimulationDiverged."""
        m, d, tracker = self.model, self.data, self.tracker
        for k in range(n):
            self._move_mocap()
            mujoco.mj_step(m, d)
            self.step_index += 1
            pts = self._check()
            if tracker is not None and k < n - 1:
                tracker.update(self.record(pts))
        rec = self.record(pts)
        if tracker is not None:
            object.__setattr__(rec, "state", tracker.update(rec))
        return rec

    def _warning_count(self) -> int:
        return int(self.data.warning.number[self._fatal].sum())

    def _check(self) -> np.ndarray:
        """Divergence checks after a step; returns the cable points (a copy)."""
        d = self.data
        count = self._warning_count()
        if count != self._warnings:
            now = self.data.warning.number
            w = next(w for w, n0 in zip(self._fatal, self._warnings_each, strict=True) if now[w] > n0)
            name = mujoco.mjtWarning(int(w)).name
            self._reset_warnings()
            raise SimulationDiverged(self.step_index, d.time, f"MuJoCo warning {name}")
        # a sum is NaN/inf as soon as one element is: one cheap test per array
        if not math.isfinite(float(d.qpos.sum()) + float(d.qvel.sum())):
            raise SimulationDiverged(self.step_index, d.time, "NaN/inf in the state")
        pts = self.points()
        if not math.isfinite(float(pts.sum())):
            raise SimulationDiverged(self.step_index, d.time, "NaN/inf in the cable points")
        seg = pts[1:] - pts[:-1]
        length2 = np.einsum("ij,ij->i", seg, seg)
        lo, hi = self._length2_bounds
        if length2.min() < lo or length2.max() > hi:  # rare: the exact test, naming the segment
            dev = np.abs(np.sqrt(length2) / self.built.seg_length - 1.0)
            stretch = float(dev.max())
            if stretch > self.max_stretch:
                i = int(np.argmax(dev))
                raise SimulationDiverged(
                    self.step_index,
                    d.time,
                    f"segment {i} length off by {stretch:.1%} (bound {self.max_stretch:.0%})",
                )
        return pts

    def _reset_warnings(self) -> None:
        """Take MuJoCo's current warning counts as the baseline of :meth:`_check`."""
        self._warnings_each = self.data.warning.number[self._fatal].copy()
        self._warnings = int(self._warnings_each.sum())

    def contact_arrays(self) -> ContactArrays:
        """Raw rod contacts of the current step as arrays (vectorised; no per-contact Python objects)."""
        d, f = self.data, self.built.flex_id
        nc = int(d.ncon)
        if nc == 0:
            return _EMPTY_CONTACTS
        c = d.contact
        flex = c.flex[:nc]
        geom = c.geom[:nc]
        gid = geom[:, 0]
        rows: Any
        side: Any
        if (flex[:, 1] == f).all() and (gid >= 0).all() and (self._piece_of_geom[gid] >= 0).all():
            # the usual case: every contact has an obstacle piece as side 0 and the rod as side 1
            rows, side, self_pairs = slice(None), 1, _NO_PAIRS
            normal = c.frame[:, :3].copy()
        else:
            selfm = (flex[:, 0] == f) & (flex[:, 1] == f)
            side1 = (flex[:, 1] == f) & (geom[:, 0] >= 0)  # obstacle is geom[0], rod is side 1
            side0 = (flex[:, 0] == f) & (geom[:, 1] >= 0) & ~side1
            sel = np.nonzero(side0 | side1)[0]
            s1 = side1[sel]
            gid = np.where(s1, geom[sel, 0], geom[sel, 1])
            known = self._piece_of_geom[gid] >= 0
            rows, s1, gid = sel[known], s1[known], gid[known]
            side = np.where(s1, 1, 0)
            sign = np.where(s1, 1.0, -1.0)[:, None]  # frame normal points from side 0 toward side 1
            normal = sign * c.frame[rows, :3]
            self_pairs = np.sort(c.elem[:nc][selfm], axis=1).astype(int)
        adr = c.efc_address[rows]
        act = adr >= 0
        return ContactArrays(
            point=c.vert[rows, side].astype(int),
            segment=c.elem[rows, side].astype(int),
            geom=gid.astype(int),
            obj=self._obj_of_geom[gid],
            piece=self._piece_of_geom[gid],
            dist=c.dist[rows].copy(),
            normal=normal,
            pos=c.pos[rows].copy(),
            force=self._normal_forces(c.dim[rows], adr, act),
            active=act,
            self_pairs=self_pairs,
            names=self._names,
        )

    def _normal_forces(self, dims: np.ndarray, adr: np.ndarray, act: np.ndarray) -> np.ndarray:
        """Normal force (N) of contacts with constraint rows at ``adr`` (0 where not ``act``ive), as
        ``mj_contactForce`` decodes it: with pyramidal cones the sum of the 2*(dim-1) edge forces."""
        ef = self.data.efc_force
        every = len(adr) > 0 and bool(act.all())  # the usual: every contact has constraint rows
        if not every and not act.any():
            return np.zeros(len(adr))
        dims, a = (dims, adr) if every else (dims[act], adr[act])
        k = int(dims[0])
        if self.model.opt.cone != _PYRAMIDAL:
            f = ef[a]
        elif k > 1 and (dims == k).all():
            f = ef[a[:, None] + _EDGES[k]].sum(axis=1)
        else:
            f = np.array(
                [
                    float(ef[i : i + 2 * (n - 1)].sum()) if n > 1 else float(ef[i])
                    for i, n in zip(a, dims, strict=True)
                ]
            )
        if every:
            return f
        force = np.zeros(len(adr))
        force[act] = f
        return force

    def contacts(self) -> tuple[RodContact, ...]:
        """Raw contacts of the rod with obstacle pieces at the current step, as objects."""
        return self.contact_arrays().as_list()

    def record(self, points: np.ndarray | None = None) -> StepRecord:
        """The current step's record (``points``: the cable points if already copied)."""
        d, mid = self.data, self.built.mocap_id
        return StepRecord(
            step=self.step_index,
            time=float(d.time),
            points=self.points() if points is None else points,
            gripper_pos=d.mocap_pos[mid].copy(),
            gripper_quat=d.mocap_quat[mid].copy(),
            target_pos=self.target_pos.copy(),
            target_quat=self.target_quat.copy(),
            contact_arrays=self.contact_arrays(),
            gripper_force=self.gripper_force(),
        )

    def gripper_force(self) -> np.ndarray:
        """Force (N, world frame) the cable exerts on the gripper: the two holding constraints' forces
        (a hanging cable pulls with its weight, -m g along z)."""
        d = self.data
        ne = int(d.ne)  # equality constraint rows come first, in a fixed layout while ne is unchanged
        if self._hold_rows is None or self._hold_rows[0] != ne:
            ids = d.efc_id[:ne]
            rows = np.nonzero((ids == self._hold_ids[0]) | (ids == self._hold_ids[1]))[0]
            self._hold_rows = (ne, rows)
        return d.efc_force[self._hold_rows[1]].reshape(-1, 3).sum(axis=0)

    def run(self, script: Script, *, settle: float = 0.0) -> Iterator[StepRecord]:
        """Play ``script`` from the current gripper pose; yield one record per step.

        The script's first waypoint is reached from the gripper's pose at the call over its
        ``duration``. ``settle`` extra seconds are simulated at the last waypoint at the end.
        """
        mid = self.built.mocap_id
        plan = script.plan(self.data.mocap_pos[mid], self.data.mocap_quat[mid])
        dt = self.model.opt.timestep
        nsteps = round((script.total_duration + settle) / dt)
        for k in range(1, nsteps + 1):
            pos, quat = plan.at(k * dt)
            self.set_target(pos, quat)
            yield self.step()

    # -- state --------------------------------------------------------------------------------------

    def get_state(self) -> SimState:
        """Checkpoint with ``mjSTATE_INTEGRATION`` (includes the rod's plastic state and warm start)."""
        m, d = self.model, self.data
        spec = mujoco.mjtState.mjSTATE_INTEGRATION
        buf = np.empty(mujoco.mj_stateSize(m, spec))
        mujoco.mj_getState(m, d, buf, spec)
        return SimState(buf, self.step_index, self.target_pos.copy(), self.target_quat.copy())

    def set_state(self, state: SimState) -> None:
        """Restore a checkpoint from :meth:`get_state`; later steps are bit-identical to the original."""
        m, d = self.model, self.data
        mujoco.mj_setState(m, d, state.mj, mujoco.mjtState.mjSTATE_INTEGRATION)
        mujoco.mj_forward(m, d)
        self._reset_warnings()
        self.step_index = state.step
        self.target_pos = state.target_pos.copy()
        self.target_quat = state.target_quat.copy()
