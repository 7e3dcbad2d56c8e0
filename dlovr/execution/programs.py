"""Reading a compiled program (``*.program.json``) for execution: a small, tolerant reader.

The program format (``dlovr/data/program.schema.json``, written by :mod:`dlovr.model.program`) may
gain fields; this reader takes the ones execution needs and ignores the rest, so that programs
written by newer compilers still run. Every problem is a :class:`ProgramError` whose message is one
line naming the file, the macro and the field.

Units and frames as in the program: positions in metres and quaternions ``wxyz`` in the world frame,
``relative`` displacements and ``rotation`` vectors (rad) in the gripper frame at the macro's start,
times in seconds, forces in newtons.
"""

from __future__ import annotations

import json
import math
from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from dlovr.model.program import PROGRAM_VERSION

#: Program formats this reader understands (each later one only adds fields).
READABLE_VERSIONS = tuple(range(1, PROGRAM_VERSION + 1))

CLASSES = ("E", "S", "I", "T", "C")


class ProgramError(ValueError):
    """A program file cannot be executed; the message is one line."""


@dataclass(frozen=True)
class ContactVec:
    """A principal contact as the program writes it (``E/F[table.F1]``) and its contact vector
    (unit, world frame; ``None`` when it has none; zero for a pinch, the DLO clamped between
    opposite faces, which then has its ``axis``: unit, world frame, docs/model.md)."""

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
class MotionSpec:
    """The demonstrated gripper motion of a macro (see :class:`dlovr.model.program.Motion`)."""

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


@dataclass(frozen=True)
class DetectionSpec:
    """A detection algorithm of one class with its parameters (forces N, angles degrees)."""

    cls: str
    algorithm: str
    params: Mapping[str, float] = field(default_factory=dict)


@dataclass(frozen=True)
class MacroSpec:
    """One macro: a guarded motion ended by the detection of its classes' transition.

    ``final``: the motion after the last classed transition, ended at the demonstrated pose without
    detection. ``frame``: ``"world"`` or ``"relative"`` when the program says which frame the motion
    is to be repeated in, else ``None`` (the executor's default).
    """

    index: int
    classes: tuple[str, ...]
    t: float
    from_situation: str
    to_situation: str
    from_contacts: tuple[ContactVec, ...]
    to_contacts: tuple[ContactVec, ...]
    motion: MotionSpec
    detection: tuple[DetectionSpec, ...]
    final: bool = False
    frame: str | None = None

    @property
    def label(self) -> str:
        return ",".join(self.classes) if self.classes else "-"

    @property
    def released(self) -> tuple[ContactVec, ...]:
        """Principal contacts of the from-situation that the transition ends (by state and faces)."""
        to = {c.state for c in self.to_contacts}
        return tuple(c for c in self.from_contacts if c.state not in to)

    @property
    def established(self) -> tuple[ContactVec, ...]:
        """Principal contacts of the to-situation that the transition begins."""
        fr = {c.state for c in self.from_contacts}
        return tuple(c for c in self.to_contacts if c.state not in fr)

    @property
    def expected(self) -> str:
        """The expected change of principal contacts, ``X -> Y`` (``N`` for none)."""
        a = " + ".join(c.state for c in self.released) or "N"
        b = " + ".join(c.state for c in self.established) or "N"
        return f"{a} -> {b}"


@dataclass(frozen=True)
class ProgramSpec:
    """A program to execute: its classed macros in order, and the final macro when it has one."""

    name: str
    source: str
    macros: tuple[MacroSpec, ...]
    final: MacroSpec | None = None
    scene: str | None = None
    path: Path | None = None

    @property
    def goal(self) -> tuple[str, ...]:
        """Principal contacts of the goal situation (the demonstration's last), sorted."""
        last = self.final if self.final is not None and self.final.to_contacts else None
        if last is None and self.macros:
            last = self.macros[-1]
        return tuple(sorted(c.state for c in last.to_contacts)) if last is not None else ()

    @property
    def goal_situation(self) -> str:
        last = self.macros[-1] if self.macros else self.final
        return last.to_situation if last is not None else ""

    @property
    def objects(self) -> frozenset[str]:
        """Every object the program's contacts name."""
        out: set[str] = set()
        for m in (*self.macros, *((self.final,) if self.final else ())):
            for c in (*m.from_contacts, *m.to_contacts):
                out |= c.objects
        return frozenset(out)

    @property
    def start(self) -> MotionSpec:
        """The first macro's motion (its start pose is the demonstration's)."""
        return (self.macros[0] if self.macros else self.final).motion  # type: ignore[union-attr]


# --------------------------------------------------------------------------------------------------


class _Reader:
    def __init__(self, path: str):
        self.path = path

    def err(self, where: str, msg: str) -> ProgramError:
        return ProgramError(f"{self.path}: {where}: {msg}" if where else f"{self.path}: {msg}")

    def get(self, raw: Mapping[str, Any], key: str, where: str) -> Any:
        if key not in raw:
            raise self.err(where, f"missing field {key!r}")
        return raw[key]

    def num(self, raw: Any, where: str, *, nonneg: bool = False) -> float:
        if isinstance(raw, bool) or not isinstance(raw, int | float) or not math.isfinite(raw):
            raise self.err(where, f"must be a finite number, got {raw!r}")
        if nonneg and raw < 0:
            raise self.err(where, f"must not be negative, got {raw!r}")
        return float(raw)

    def vec(self, raw: Any, where: str, n: int) -> tuple[float, ...]:
        if not isinstance(raw, list) or len(raw) != n:
            raise self.err(where, f"must be a list of {n} numbers, got {raw!r}")
        return tuple(self.num(x, f"{where}[{i}]") for i, x in enumerate(raw))

    def text(self, raw: Any, where: str) -> str:
        if not isinstance(raw, str):
            raise self.err(where, f"must be a string, got {raw!r}")
        return raw

    def contacts(self, raw: Any, where: str) -> tuple[ContactVec, ...]:
        if not isinstance(raw, list):
            raise self.err(where, "must be a list of contacts")
        out = []
        for i, c in enumerate(raw):
            w = f"{where}[{i}]"
            if not isinstance(c, dict):
                raise self.err(w, "must be an object with 'state' and 'vector'")
            vec, ax = c.get("vector"), c.get("axis")
            v = None if vec is None else self.vec(vec, f"{w}.vector", 3)  # zero for a pinch, kept
            a = None if ax is None else self.vec(ax, f"{w}.axis", 3)
            if a is not None and abs(math.sqrt(sum(x * x for x in a)) - 1.0) > 1e-6:
                raise self.err(f"{w}.axis", f"must be a unit vector, got {list(a)}")
            state = self.text(self.get(c, "state", w), f"{w}.state")
            out.append(ContactVec(state, v, a))  # type: ignore[arg-type]
        return tuple(out)

    def motion(self, raw: Any, where: str) -> MotionSpec:
        if not isinstance(raw, dict):
            raise self.err(where, "must be an object")
        g = lambda k: self.get(raw, k, where)  # noqa: E731
        q = self.vec(g("start_quat"), f"{where}.start_quat", 4)
        if math.sqrt(sum(x * x for x in q)) < 1e-9:
            raise self.err(f"{where}.start_quat", "quaternion has zero length")
        return MotionSpec(
            self.vec(g("world"), f"{where}.world", 3),  # type: ignore[arg-type]
            self.vec(g("relative"), f"{where}.relative", 3),  # type: ignore[arg-type]
            self.vec(g("rotation"), f"{where}.rotation", 3),  # type: ignore[arg-type]
            self.num(g("duration"), f"{where}.duration", nonneg=True),
            self.vec(g("start_pos"), f"{where}.start_pos", 3),  # type: ignore[arg-type]
            q,  # type: ignore[arg-type]
        )

    def detection(self, raw: Any, where: str) -> tuple[DetectionSpec, ...]:
        if not isinstance(raw, list):
            raise self.err(where, "must be a list")
        out = []
        for i, d in enumerate(raw):
            w = f"{where}[{i}]"
            if not isinstance(d, dict):
                raise self.err(w, "must be an object")
            cls = self.get(d, "cls", w)
            if cls not in CLASSES:
                raise self.err(f"{w}.cls", f"unknown class {cls!r} (known: {', '.join(CLASSES)})")
            params = d.get("params", {})
            if not isinstance(params, dict):
                raise self.err(f"{w}.params", "must be an object")
            nums = {}
            for k, v in params.items():
                if isinstance(v, int | float) and not isinstance(v, bool):
                    nums[str(k)] = self.num(v, f"{w}.params.{k}")  # other kinds (notes) are skipped
            out.append(DetectionSpec(cls, str(d.get("algorithm", "")), nums))
        return tuple(out)

    def macro(self, raw: Any, where: str, final: bool = False) -> MacroSpec:
        if not isinstance(raw, dict):
            raise self.err(where, "must be an object")
        g = lambda k, default=None: raw.get(k, default) if final else self.get(raw, k, where)  # noqa: E731
        classes = g("classes", [])
        if not isinstance(classes, list) or any(c not in CLASSES for c in classes):
            raise self.err(f"{where}.classes", f"must be a list of classes {', '.join(CLASSES)}")
        if not classes and not final:
            raise self.err(f"{where}.classes", "a macro needs at least one class")
        frame = raw.get("frame")
        if frame is not None and frame not in ("world", "relative"):
            raise self.err(f"{where}.frame", f"must be 'world' or 'relative', got {frame!r}")
        detection = self.detection(g("detection", []), f"{where}.detection")
        if not final and {d.cls for d in detection} != set(classes):
            raise self.err(f"{where}.detection", "needs one detection per class of the macro")
        return MacroSpec(
            index=int(self.num(g("index", 0), f"{where}.index")),
            classes=tuple(classes),
            t=self.num(g("t", 0.0), f"{where}.t"),
            from_situation=self.text(g("from_situation", ""), f"{where}.from_situation"),
            to_situation=self.text(g("to_situation", ""), f"{where}.to_situation"),
            from_contacts=self.contacts(g("from_contacts", []), f"{where}.from_contacts"),
            to_contacts=self.contacts(g("to_contacts", []), f"{where}.to_contacts"),
            motion=self.motion(self.get(raw, "motion", where), f"{where}.motion"),
            detection=detection,
            final=final,
            frame=frame,
        )


def parse_program(raw: Any, path: str = "<program>") -> ProgramSpec:
    """A program from its parsed JSON; raises :class:`ProgramError` (one line)."""
    r = _Reader(path)
    if not isinstance(raw, dict):
        raise r.err("", "not a program (a JSON object with 'macros' expected)")
    if raw.get("version", 1) not in READABLE_VERSIONS:
        known = ", ".join(str(v) for v in READABLE_VERSIONS)
        raise r.err("version", f"program format {raw.get('version')!r}, this dlovr runs formats {known}")
    macros_raw = r.get(raw, "macros", "")
    if not isinstance(macros_raw, list):
        raise r.err("macros", "must be a list")
    macros, final = [], None
    for i, m in enumerate(macros_raw):
        is_final = isinstance(m, dict) and (m.get("final") is True or m.get("classes") == [])
        spec = r.macro(m, f"macros[{i}]", final=is_final)
        if is_final:
            if i != len(macros_raw) - 1:
                raise r.err(f"macros[{i}]", "the final macro (no class) must come last")
            final = spec
        else:
            macros.append(spec)
    if isinstance(raw.get("final"), dict):
        final = r.macro(raw["final"], "final", final=True)
    if not macros and final is None:
        raise r.err("macros", "the program has no macro")
    scene = raw.get("scene")
    return ProgramSpec(
        name=str(raw.get("name", Path(path).stem)),
        source=str(raw.get("source", "")),
        macros=tuple(macros),
        final=final,
        scene=scene if isinstance(scene, str) and scene else None,
        path=Path(path) if path != "<program>" else None,
    )


def load_program(path: str | Path) -> ProgramSpec:
    """Read and check a ``*.program.json``; raises :class:`ProgramError` (one line)."""
    p = str(path)
    try:
        text = Path(p).read_text(encoding="utf-8")
    except FileNotFoundError:
        raise ProgramError(f"{p}: no such program file") from None
    except IsADirectoryError:
        raise ProgramError(f"{p}: is a directory, not a program file") from None
    except OSError as e:
        raise ProgramError(f"{p}: cannot read: {e.strerror}") from None
    except UnicodeDecodeError:
        raise ProgramError(f"{p}: not a UTF-8 text file") from None
    try:
        raw = json.loads(text)
    except json.JSONDecodeError as e:
        raise ProgramError(f"{p}: not valid JSON: {e.msg} at line {e.lineno}") from None
    return parse_program(raw, p)


def find_recording(program: ProgramSpec, given: str | Path | None = None) -> Path | None:
    """The demonstration a program was compiled from: ``given``, else its ``source`` looked up beside
    the program file, in its parent directory and in the working directory; ``None`` if not found."""
    if given is not None:
        return Path(given)
    if not program.source:
        return None
    src = Path(program.source)
    cands = [src] if src.is_absolute() else []
    if program.path is not None and not src.is_absolute():
        cands += [program.path.parent / src, program.path.parent.parent / src]
    if not src.is_absolute():
        cands += [Path.cwd() / src, Path.cwd() / "recordings" / src]
    return next((c for c in cands if c.is_file()), None)
