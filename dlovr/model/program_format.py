"""The program format (``*.program.json``, paper §VI, docs/model.md): one :class:`Program` type that
is written by the compiler (:func:`dlovr.model.program.compile_program`), read back
(:meth:`Program.from_json`, :meth:`Program.load`) and run by the execution engine
(:mod:`dlovr.execution.engine`). The format's JSON Schema ships in ``dlovr/data/program.schema.json``;
the reader takes the format's version, classes, risks and motion fields from it.

Pure Python. Frames and units: positions in metres and quaternions ``wxyz`` in the world frame; the
relative motion is expressed in the gripper frame at the macro's start; rotation vectors in radians;
times in seconds; forces in newtons.
"""

from __future__ import annotations

import json
import math
from collections.abc import Sequence
from dataclasses import asdict, dataclass, field
from functools import cache
from importlib import resources
from pathlib import Path
from typing import Any, Protocol

import numpy as np

from dlovr.inputs import Fields, InputError, read_json
from dlovr.model.transitions import CLASS_NAMES, format_classes

PROGRAM_VERSION = 2
"""Version of the program JSON format (``version`` field); bump on incompatible changes.

2: macros name the principal contacts that change (``changes``), carry a ``risk`` (none, caution,
risky) instead of ``risky``, a ``kind`` (``transition`` or ``final``: the motion after the last
classed transition), and expected contacts carry a pinch ``axis``."""


@dataclass(frozen=True)
class Motion:
    """The demonstrated gripper motion of one macro.

    ``world``: displacement in the world frame (m); ``relative``: the same in the gripper frame at
    the start; ``rotation``: rotation vector (rad) from the start orientation, gripper frame;
    ``duration`` s; ``start_pos``/``start_quat`` the pose where it starts (world, wxyz).
    """

    world: tuple[float, float, float]
    relative: tuple[float, float, float]
    rotation: tuple[float, float, float]
    duration: float
    start_pos: tuple[float, float, float]
    start_quat: tuple[float, float, float, float]

    @property
    def distance(self) -> float:
        """Length of the demonstrated displacement (m)."""
        return math.sqrt(sum(x * x for x in self.world))

    @property
    def angle(self) -> float:
        """Angle of the demonstrated rotation (rad)."""
        return math.sqrt(sum(x * x for x in self.rotation))


RISKY = frozenset({"S", "I"})
RISK_OF_CLASS = {"C": "none", "E": "none", "T": "caution", "I": "risky", "S": "risky"}
"""Risk of a transition class (§IV.B, §VI): stable ones none, semi-stable caution, instable risky."""
RISK_LEVELS = ("none", "caution", "risky")


def risk(classes: Sequence[str]) -> str:
    """The risk of a macro: that of its riskiest class (``none`` for no class)."""
    return max((RISK_OF_CLASS[c] for c in classes), key=RISK_LEVELS.index, default="none")


@dataclass(frozen=True)
class Detection:
    """The detection of one class: its algorithm, parameters (forces N, angles degrees, times s) and,
    per parameter, how it was derived from the demonstration (``derived: ...``) or that it is the
    class's default (``default: why``); see :mod:`dlovr.model.derivation`."""

    cls: str
    algorithm: str
    params: dict[str, float]
    derivation: dict[str, str] = field(default_factory=dict)


@dataclass(frozen=True)
class ContactSpec:
    """A principal contact a macro expects: its state with face names and its contact vector (unit,
    world frame). A pinch (the DLO clamped between opposite faces) has the zero vector and, when its
    faces' normals share one line, that line's ``axis`` (unit, world frame): a detector then looks
    for force along the axis, either sign (docs/model.md, Contact vectors)."""

    state: str
    vector: tuple[float, float, float] | None
    axis: tuple[float, float, float] | None = None

    @property
    def objects(self) -> frozenset[str]:
        """Objects named by the contact's faces (``table`` of ``table.F1``)."""
        if "[" not in self.state:
            return frozenset()
        faces = self.state[self.state.index("[") + 1 : self.state.rindex("]")].split(",")
        return frozenset(f.rpartition(".")[0] for f in faces if "." in f)


@dataclass(frozen=True)
class ContactChange:
    """One principal contact that changes in a macro's transition and its classes.

    ``from_contact``/``to_contact``: before and after, ``None`` for free space ``N`` (a contact
    established or released)."""

    classes: tuple[str, ...]
    from_contact: ContactSpec | None
    to_contact: ContactSpec | None


@dataclass(frozen=True)
class Macro:
    """One guarded motion of a program.

    ``kind``: ``transition`` (ends when its detection sees the transition ``classes``) or ``final``
    (the motion after the last classed transition, to the demonstrated end pose, no detection).
    ``t``: when the demonstrated transition happened, or the demonstration's end (s). ``changes``:
    the principal contacts that change; ``from_contacts``/``to_contacts``: all principal contacts
    of the whole situations before and after. ``risk``: ``none`` (C, E), ``caution`` (T) or
    ``risky`` (I, S). ``frame``: ``world`` or ``relative`` when the program says which frame the
    motion is to be repeated in, else ``None`` (the executor's default; not written then).
    """

    index: int
    kind: str
    classes: tuple[str, ...]
    t: float
    from_situation: str
    to_situation: str
    changes: tuple[ContactChange, ...]
    from_contacts: tuple[ContactSpec, ...]
    to_contacts: tuple[ContactSpec, ...]
    motion: Motion
    detection: tuple[Detection, ...]
    risk: str
    frame: str | None = None

    @property
    def label(self) -> str:
        return "end" if self.kind == "final" else format_classes(self.classes)

    @property
    def risky(self) -> bool:
        return self.risk == "risky"

    @property
    def final(self) -> bool:
        """The motion after the last classed transition (no detection)."""
        return self.kind == "final"

    @property
    def released(self) -> tuple[ContactSpec, ...]:
        """Principal contacts of the from-situation that the transition ends (by state and faces)."""
        to = {c.state for c in self.to_contacts}
        return tuple(c for c in self.from_contacts if c.state not in to)

    @property
    def established(self) -> tuple[ContactSpec, ...]:
        """Principal contacts of the to-situation that the transition begins."""
        fr = {c.state for c in self.from_contacts}
        return tuple(c for c in self.to_contacts if c.state not in fr)

    @property
    def expected(self) -> str:
        """The expected change of principal contacts, ``X -> Y`` (``N`` for none)."""
        a = " + ".join(c.state for c in self.released) or "N"
        b = " + ".join(c.state for c in self.established) or "N"
        return f"{a} -> {b}"


class ProgramError(InputError):
    """A program file cannot be read or executed; the message is one line (``dlovr.inputs``)."""


class Runnable(Protocol):
    """What ``dlovr run`` and the execution engine (:mod:`dlovr.execution.engine`) take: a compiled
    :class:`Program` or a :class:`dlovr.model.planning.NetworkProgram`."""

    @property
    def name(self) -> str: ...

    @property
    def source(self) -> str: ...

    def dumps(self) -> str: ...

    def listing(self) -> str: ...


@dataclass(frozen=True)
class Program:
    """A compiled program: its macros in order (the classed ones, then the final one), as written to
    and read from ``*.program.json`` (:meth:`dumps`, :meth:`from_json`, :meth:`load`; the format is
    ``dlovr/data/program.schema.json``). ``scene``: the scene the file names, if any; ``path``: the
    file it was read from. Neither is written. ``smoothing_s``: the moving-average window (s) the
    demonstrated wrench and orientation were smoothed over, the positions' tremor taken out
    (:mod:`dlovr.model.smoothing`; 0: taken as recorded), and ``smoothing`` says why; both written
    only when not 0 (the executor follows the demonstrated track treated the same way).
    ``goal_tolerance_deg``: how far (degrees) the contact vector sensed at a run's end may turn from
    the demonstration's end one for the goal check to confirm the goal, derived from how far it turned
    in the demonstration while the goal held (:func:`dlovr.model.derivation.goal_tolerance_deg`);
    None (not written): no contact at the goal, or a program compiled before it existed (the executor's
    default then). ``calibration``: what the compiler's calibration in simulation ran and what came of
    it per macro (``dlovr compile --calibrate``, :mod:`dlovr.execution.calibration`; the calibrated
    parameters' texts say ``calibrated: ...``); empty (not written): not calibrated."""

    name: str
    source: str
    macros: tuple[Macro, ...]
    version: int = PROGRAM_VERSION
    summary: dict[str, int] = field(default_factory=dict)
    scene: str | None = None
    path: Path | None = None
    smoothing_s: float = 0.0
    smoothing: str = ""
    goal_tolerance_deg: float | None = None
    calibration: str = ""

    def to_json(self) -> dict[str, Any]:
        d = asdict(self)
        d.pop("calibration")
        for m in d["macros"]:
            if m["frame"] is None:
                del m["frame"]
        out = {"version": d["version"], "name": d["name"], "source": d["source"]}
        if self.smoothing_s > 0:
            out |= {"smoothing_s": self.smoothing_s, "smoothing": self.smoothing}
        if self.goal_tolerance_deg is not None:
            out["goal_tolerance_deg"] = self.goal_tolerance_deg
        if self.calibration:
            out["calibration"] = self.calibration
        return {**out, "macros": d["macros"], "summary": d["summary"]}

    def dumps(self) -> str:
        return json.dumps(self.to_json(), indent=2, sort_keys=False, ensure_ascii=False) + "\n"

    @staticmethod
    def from_json(raw: Any, source: str | Path = "<program>") -> Program:
        """A program from its parsed JSON (``source`` names it in errors); raises
        :class:`ProgramError`. Tolerant: fields this dlovr does not know are ignored, so programs
        of a newer compiler still run; format 1 (no ``kind``, ``risk``, ``changes``) is read too."""
        return _read_program(raw, source)

    @staticmethod
    def load(path: str | Path) -> Program:
        """Read and check a ``*.program.json``; raises :class:`ProgramError` (one line)."""
        return _read_program(read_json(path, ProgramError, "program file"), path)

    @property
    def classed(self) -> tuple[Macro, ...]:
        """The macros ended by a detection (all but the final one)."""
        return tuple(m for m in self.macros if not m.final)

    @property
    def final(self) -> Macro | None:
        """The final macro (no detection), when the program has one."""
        return self.macros[-1] if self.macros and self.macros[-1].final else None

    @property
    def goal(self) -> tuple[str, ...]:
        """Principal contacts of the goal situation (the demonstration's last), sorted."""
        classed, final = self.classed, self.final
        last = final if final is not None and final.to_contacts else None
        if last is None and classed:
            last = classed[-1]
        return tuple(sorted(c.state for c in last.to_contacts)) if last is not None else ()

    @property
    def goal_situation(self) -> str:
        classed = self.classed
        last = classed[-1] if classed else self.final
        return last.to_situation if last is not None else ""

    @property
    def objects(self) -> frozenset[str]:
        """Every object the program's contacts name."""
        return frozenset(
            o for m in self.macros for c in (*m.from_contacts, *m.to_contacts) for o in c.objects
        )

    @property
    def start(self) -> Motion:
        """The first macro's motion (its start pose is the demonstration's)."""
        return self.macros[0].motion

    def listing(self) -> str:
        """A readable text listing of the program."""
        lines = [f"program {self.name}  (from {self.source}, format v{self.version})"]
        for m in self.macros:
            mv = m.motion
            lines.append(f"{m.index:>3}  {m.label:<4} t={m.t:8.3f}s  risk {m.risk}")
            for c in m.changes:
                lines.append(
                    f"       {format_classes(c.classes):<4} {_name(c.from_contact)} -> {_name(c.to_contact)}"
                )
            lines.append(f"       from {m.from_situation}")
            lines.append(f"       to   {m.to_situation}")
            lines.append(
                "       move {:+.4f} {:+.4f} {:+.4f} m (world) in {:.3f} s, rotate {:.1f} deg".format(
                    *mv.world, mv.duration, math.degrees(float(np.linalg.norm(mv.rotation)))
                )
            )
            for det in m.detection:
                params = ", ".join(f"{k}={v:g}" for k, v in det.params.items())
                lines.append(f"       until {det.algorithm} ({params})  [{CLASS_NAMES[det.cls]}]")
                for k, how in det.derivation.items():
                    lines.append(f"         {k}: {how}")
            if m.kind == "final":
                lines.append("       to the demonstrated end pose (no detection)")
        if self.calibration:
            lines.append(f"calibration: {self.calibration}")
        s = self.summary
        lines.append(
            f"{s.get('macros', 0)} macros (the last one final), {s.get('risky', 0)} risky, "
            f"{s.get('caution', 0)} caution"
        )
        return "\n".join(lines) + "\n"


def _name(c: ContactSpec | None) -> str:
    return "N" if c is None else c.state


def summarize(macros: Sequence[Macro]) -> dict[str, int]:
    """A program's ``summary``: how many macros, risky ones and caution ones."""
    return {
        "macros": len(macros),
        "risky": sum(m.risk == "risky" for m in macros),
        "caution": sum(m.risk == "caution" for m in macros),
    }


@cache
def program_schema() -> dict[str, Any]:
    """The JSON Schema of the program format, shipped with the package (``dlovr/data/``). The
    reader takes the format's version, classes, kinds, risks and motion fields from it."""
    return json.loads(resources.files("dlovr").joinpath("data/program.schema.json").read_text("utf-8"))


def _schema_enum(name: str) -> tuple[str, ...]:
    return tuple(program_schema()["$defs"][name]["enum"])


def readable_versions() -> tuple[int, ...]:
    """Program formats this reader understands (each later one only adds fields)."""
    return tuple(range(1, int(program_schema()["properties"]["version"]["const"]) + 1))


# --------------------------------------------------------------------------------------------------
# Reading (tolerant: unknown fields are ignored; every problem a one-line ProgramError)
# --------------------------------------------------------------------------------------------------


class _Reader(Fields):
    """The checks of one program document (see :class:`dlovr.inputs.Fields`)."""

    def __init__(self, source: str | Path):
        super().__init__(source, ProgramError)
        self.classes = _schema_enum("class")

    def text(self, raw: Any, where: str) -> str:
        """A string (empty allowed)."""
        if not isinstance(raw, str):
            raise self.err(where, f"must be a string, got {raw!r}")
        return raw

    def obj(self, raw: Any, where: str) -> dict:
        if not isinstance(raw, dict):
            raise self.err(where, "must be an object")
        return raw

    def items(self, raw: Any, where: str) -> list:
        if not isinstance(raw, list):
            raise self.err(where, "must be a list")
        return raw

    def contact(self, c: Any, w: str) -> ContactSpec:
        if not isinstance(c, dict):
            raise self.err(w, "must be an object with 'state' and 'vector'")
        vec, ax = c.get("vector"), c.get("axis")
        v = None if vec is None else self.vec(vec, f"{w}.vector", 3)  # zero for a pinch, kept
        a = None if ax is None else self.vec(ax, f"{w}.axis", 3)
        if a is not None and abs(math.sqrt(sum(x * x for x in a)) - 1.0) > 1e-6:
            raise self.err(f"{w}.axis", f"must be a unit vector, got {list(a)}")
        state = self.text(self.require(c, "state", w), f"{w}.state")
        return ContactSpec(state, None if v is None else _v3(v), None if a is None else _v3(a))

    def contacts(self, raw: Any, where: str) -> tuple[ContactSpec, ...]:
        if not isinstance(raw, list):
            raise self.err(where, "must be a list of contacts")
        return tuple(self.contact(c, f"{where}[{i}]") for i, c in enumerate(raw))

    def change(self, raw: Any, w: str) -> ContactChange:
        raw = self.obj(raw, w)
        a, b = raw.get("from_contact"), raw.get("to_contact")
        return ContactChange(
            self.class_list(raw.get("classes", []), f"{w}.classes"),
            None if a is None else self.contact(a, f"{w}.from_contact"),
            None if b is None else self.contact(b, f"{w}.to_contact"),
        )

    def class_list(self, raw: Any, where: str) -> tuple[str, ...]:
        if not isinstance(raw, list) or any(c not in self.classes for c in raw):
            raise self.err(where, f"must be a list of classes {', '.join(self.classes)}")
        return tuple(raw)

    def motion(self, raw: Any, where: str) -> Motion:
        raw = self.obj(raw, where)
        fields = program_schema()["$defs"]["macro"]["properties"]["motion"]["required"]
        v = {k: self.require(raw, k, where) for k in fields}
        q = self.vec(v["start_quat"], f"{where}.start_quat", 4)
        if math.sqrt(sum(x * x for x in q)) < 1e-9:
            raise self.err(f"{where}.start_quat", "quaternion has zero length")
        return Motion(
            world=_v3(self.vec(v["world"], f"{where}.world", 3)),
            relative=_v3(self.vec(v["relative"], f"{where}.relative", 3)),
            rotation=_v3(self.vec(v["rotation"], f"{where}.rotation", 3)),
            duration=self.number(v["duration"], f"{where}.duration", nonneg=True),
            start_pos=_v3(self.vec(v["start_pos"], f"{where}.start_pos", 3)),
            start_quat=(q[0], q[1], q[2], q[3]),
        )

    def detection(self, raw: Any, w: str) -> Detection:
        d = self.obj(raw, w)
        cls = self.require(d, "cls", w)
        if cls not in self.classes:
            raise self.err(f"{w}.cls", f"unknown class {cls!r} (known: {', '.join(self.classes)})")
        params = self.obj(d.get("params", {}), f"{w}.params")
        nums = {
            str(k): self.number(v, f"{w}.params.{k}")
            for k, v in params.items()
            if isinstance(v, int | float) and not isinstance(v, bool)  # other kinds (notes) are skipped
        }
        how = d.get("derivation", {})
        derivation = (
            {str(k): v for k, v in how.items() if isinstance(v, str)} if isinstance(how, dict) else {}
        )
        return Detection(cls, str(d.get("algorithm", "")), nums, derivation)

    def macro(self, raw: Any, where: str, final: bool = False) -> Macro:
        raw = self.obj(raw, where)

        def g(key: str, default: Any = None) -> Any:
            return raw.get(key, default) if final else self.require(raw, key, where)

        classes = self.class_list(g("classes", []), f"{where}.classes")
        if not classes and not final:
            raise self.err(f"{where}.classes", "a macro needs at least one class")
        frame = raw.get("frame")
        if frame is not None and frame not in ("world", "relative"):
            raise self.err(f"{where}.frame", f"must be 'world' or 'relative', got {frame!r}")
        detection = tuple(
            self.detection(d, f"{where}.detection[{i}]")
            for i, d in enumerate(self.items(g("detection", []), f"{where}.detection"))
        )
        if not final and {d.cls for d in detection} != set(classes):
            raise self.err(f"{where}.detection", "needs one detection per class of the macro")
        return Macro(
            index=int(self.number(g("index", 0), f"{where}.index")),
            kind="final" if final else "transition",
            classes=classes,
            t=self.number(g("t", 0.0), f"{where}.t"),
            from_situation=self.text(g("from_situation", ""), f"{where}.from_situation"),
            to_situation=self.text(g("to_situation", ""), f"{where}.to_situation"),
            changes=tuple(
                self.change(c, f"{where}.changes[{i}]")
                for i, c in enumerate(self.items(raw.get("changes", []), f"{where}.changes"))
            ),
            from_contacts=self.contacts(g("from_contacts", []), f"{where}.from_contacts"),
            to_contacts=self.contacts(g("to_contacts", []), f"{where}.to_contacts"),
            motion=self.motion(self.require(raw, "motion", where), f"{where}.motion"),
            detection=detection,
            risk=self.risk(raw, classes, where),
            frame=frame,
        )

    def risk(self, raw: dict, classes: tuple[str, ...], where: str) -> str:
        """The macro's ``risk`` (format 2), else that of its classes (format 1)."""
        if "risk" not in raw:
            return risk(classes)
        levels = tuple(program_schema()["$defs"]["macro"]["properties"]["risk"]["enum"])
        if raw["risk"] not in levels:
            raise self.err(f"{where}.risk", f"must be one of {', '.join(levels)}, got {raw['risk']!r}")
        return str(raw["risk"])


def _v3(v: Sequence[float]) -> tuple[float, float, float]:
    return (v[0], v[1], v[2])


def _is_final(m: Any) -> bool:
    return isinstance(m, dict) and (m.get("final") is True or m.get("classes") == [])


def _read_macros(r: _Reader, raw: dict) -> tuple[Macro, ...]:
    """The classed macros, then the final one (in the list's last place, or under ``final``)."""
    items = r.items(r.require(raw, "macros"), "macros")
    macros: list[Macro] = []
    final: Macro | None = None
    for i, m in enumerate(items):
        if _is_final(m):
            if i != len(items) - 1:
                raise r.err(f"macros[{i}]", "the final macro (no class) must come last")
            final = r.macro(m, f"macros[{i}]", final=True)
        else:
            macros.append(r.macro(m, f"macros[{i}]"))
    if isinstance(raw.get("final"), dict):
        final = r.macro(raw["final"], "final", final=True)
    if not macros and final is None:
        raise r.err("macros", "the program has no macro")
    return (*macros, *((final,) if final is not None else ()))


def _read_program(raw: Any, source: str | Path) -> Program:
    r = _Reader(source)
    if not isinstance(raw, dict):
        raise r.err("", "not a program (a JSON object with 'macros' expected)")
    versions = readable_versions()
    if raw.get("version", 1) not in versions:
        known = ", ".join(str(v) for v in versions)
        raise r.err("version", f"program format {raw.get('version')!r}, this dlovr runs formats {known}")
    macros = _read_macros(r, raw)
    scene, path = raw.get("scene"), str(source)
    smoothing = raw.get("smoothing_s", 0.0)
    if not isinstance(smoothing, int | float) or isinstance(smoothing, bool) or not 0 <= smoothing <= 10:
        raise r.err("smoothing_s", f"must be a number of seconds in [0, 10], got {smoothing!r}")
    tol = raw.get("goal_tolerance_deg")
    if tol is not None and (not isinstance(tol, int | float) or isinstance(tol, bool) or not 0 < tol <= 180):
        raise r.err("goal_tolerance_deg", f"must be a number of degrees in (0, 180], got {tol!r}")
    return Program(
        name=str(raw.get("name", Path(path).stem)),
        source=str(raw.get("source", "")),
        macros=macros,
        summary=summarize(macros),
        scene=scene if isinstance(scene, str) and scene else None,
        path=Path(path) if path != "<program>" else None,
        smoothing_s=float(smoothing),
        smoothing=str(raw.get("smoothing", "")),
        goal_tolerance_deg=None if tol is None else float(tol),
        calibration=str(raw.get("calibration", "")),
    )
