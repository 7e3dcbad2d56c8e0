"""Geometric facts and parameters: the inputs of the discrete-state classifier (docs/model.md, section 3).

Pure Python. :class:`FaceFact` (a face's outward normal), :class:`PairFact` (how two faces meet:
concave or convex, opening angle), :class:`ContactFacts` (the facts of one contact) and
:class:`FactBook` (a scene's facts, looked up per contact) are plain values that the geometry computes
from a scene or a test writes by hand; :class:`ModelParams` holds the model's angles. Vectors are unit
vectors in the world frame; angles are in degrees.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass

from dlovr.model.topology import Contact, Vec3


@dataclass(frozen=True)
class FaceFact:
    """One face: its name (``obj.F3``), owning object, outward unit normal (world frame).

    ``internal`` marks a face that a convex decomposition introduced inside a solid: it never counts.
    """

    name: str
    obj: str
    normal: Vec3
    internal: bool = False


@dataclass(frozen=True)
class PairFact:
    """How two faces meet: concave or convex, and the free-space opening angle in degrees.

    The opening angle is 180 - α for a concave pair and 180 + α for a convex one, α being the angle
    between the normals. ``crease`` is the unit direction of their common line (world frame), if known.
    """

    a: str
    b: str
    concave: bool
    opening_deg: float
    crease: Vec3 | None = None

    @property
    def key(self) -> frozenset[str]:
        return frozenset((self.a, self.b))


@dataclass(frozen=True)
class ModelParams:
    """Parameters of the model (docs/model.md, section 7). Angles in degrees.

    ``critical_angle_deg``: a concave opening at or above it is semi-stable (§3.3).
    ``parallel_tol_deg``: a DLO edge within this angle of an environment edge is a line contact.
    ``tip_angle_deg``: the end-vertex rule (§2): the tip touches only when pointing into the surface
    by more than this.
    ``normal_merge_deg``: normals closer than this count as one direction when ranking (§3.3 step 1).
    """

    critical_angle_deg: float = 170.0
    parallel_tol_deg: float = 10.0
    tip_angle_deg: float = 15.0
    normal_merge_deg: float = 0.01

    def __post_init__(self) -> None:
        if not 90.0 < self.critical_angle_deg <= 180.0:
            raise ValueError(f"critical_angle_deg must be in (90, 180], got {self.critical_angle_deg}")
        if not 0.0 <= self.parallel_tol_deg < 90.0:
            raise ValueError(f"parallel_tol_deg must be in [0, 90), got {self.parallel_tol_deg}")
        if not 0.0 <= self.tip_angle_deg < 90.0:
            raise ValueError(f"tip_angle_deg must be in [0, 90), got {self.tip_angle_deg}")
        if not 0.0 <= self.normal_merge_deg < 45.0:
            raise ValueError(f"normal_merge_deg must be in [0, 45), got {self.normal_merge_deg}")


@dataclass(frozen=True)
class ContactFacts:
    """The geometric facts about one (single or multiple) contact that the classifier needs.

    ``faces``: every face of the contact's primitives. ``pairs``: how each pair of its real faces
    with distinct normals meets. ``dlo_vector``: the DLO vector at the contact (any length, world
    frame), needed for edge contacts. ``crease``: direction of the environment edge, if the caller
    knows it (else taken from the normals). ``gripper_z``: the gripper's z axis for ``G`` contacts.
    """

    faces: tuple[FaceFact, ...]
    pairs: tuple[PairFact, ...] = ()
    dlo_vector: Vec3 | None = None
    crease: Vec3 | None = None
    gripper_z: Vec3 | None = None


class FactBook:
    """Geometric facts about a whole scene, keyed by face name; builds :class:`ContactFacts`.

    ``faces`` maps face names to :class:`FaceFact`; ``pairs`` lists :class:`PairFact` for face pairs
    (in either order).
    """

    def __init__(self, faces: Mapping[str, FaceFact], pairs: list[PairFact] | tuple[PairFact, ...] = ()):
        self.faces = dict(faces)
        self.pairs = {p.key: p for p in pairs}

    def for_contact(self, contact: Contact, dlo_vector: Vec3 | None = None) -> ContactFacts:
        """Facts for one topological contact; raises ``KeyError`` naming a face or pair not known."""
        names = contact.faces
        missing = [f for f in names if f not in self.faces]
        if missing:
            raise KeyError(f"no facts for face {missing[0]}")
        facts = tuple(self.faces[f] for f in names)
        pairs = tuple(
            self.pairs[frozenset((a, b))]
            for i, a in enumerate(names)
            for b in names[i + 1 :]
            if frozenset((a, b)) in self.pairs
        )
        z = next((e.z for e in contact.env if e.kind == "G"), None)
        vec = dlo_vector if dlo_vector is not None else contact.dlo.vector
        return ContactFacts(facts, pairs, vec, None, z)
