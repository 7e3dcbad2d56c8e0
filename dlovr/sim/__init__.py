"""Simulation: the MuJoCo model of a scene, the simulator, and the per-step contact tracker.

- :mod:`dlovr.sim.build`: the MuJoCo model (obstacles as convex pieces, the cable rod, the gripper)
  and its MJCF export;
- :mod:`dlovr.sim.contacts`: the rod's raw contacts with normal forces, read from MuJoCo's arrays;
- :mod:`dlovr.sim.kernels`, :mod:`dlovr.sim.track_kernels`: the compiled per-step kernels of the
  simulator and the tracker; :mod:`dlovr.sim.warmup`: compiling them on the first run;
- :mod:`dlovr.sim.simulator`: :class:`Simulator`, stepping, bounded gripper motion, divergence checks,
  per-step records;
- :mod:`dlovr.sim.tracker`: :class:`ContactTracker`, each step's contacts -> topological and discrete
  situations -> debounced transitions; :mod:`dlovr.sim.behind`: the tracker on a thread of its own,
  beside the simulation (a replay's).

These are the only modules of dlovr that import :mod:`mujoco` (besides replay in
:mod:`dlovr.recording`).
"""

from dlovr.sim.build import (
    CONTACT_GAP,
    EQ_SOLIMP,
    GRIPPER,
    ROD,
    TIMESTEP,
    BuiltModel,
    DloParams,
    GripperPose,
    Obstacle,
    SimulationDiverged,
    build_model,
    edge_solimp,
    export_xml,
)
from dlovr.sim.contacts import ContactArrays, RodContact
from dlovr.sim.simulator import (
    DEFAULT_MAX_STRETCH,
    SimState,
    Simulator,
    StepRecord,
    obstacles_from_scene,
)

__all__ = [
    "CONTACT_GAP",
    "DEFAULT_MAX_STRETCH",
    "EQ_SOLIMP",
    "GRIPPER",
    "ROD",
    "TIMESTEP",
    "BuiltModel",
    "ContactArrays",
    "DloParams",
    "GripperPose",
    "Obstacle",
    "RodContact",
    "SimState",
    "SimulationDiverged",
    "Simulator",
    "StepRecord",
    "build_model",
    "edge_solimp",
    "export_xml",
    "obstacles_from_scene",
]
