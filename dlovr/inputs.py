"""The input layer: one error type, one wording and one table of limits for every file a user gives
dlovr (scene, script, facts, program, network).

Every problem with a user's input is an :class:`InputError` (or a subclass naming the format, such
as ``SceneError``): one line, ``<file>: <where>: <problem>``, which the CLI prints and exits with
code 2. :class:`Fields` checks the values of a parsed TOML or JSON document with that wording;
:func:`read_bytes`, :func:`read_text`, :func:`read_toml` and :func:`read_json` read a file with it.

This module is pure (standard library only), so the model's readers use it too.
"""

from __future__ import annotations

import json
import math
import os
import tomllib
from pathlib import Path
from typing import Any

#: Documented limits of every input, in one place (``docs/inputs.md`` lists them).
LIMITS: dict[str, float] = {
    "file_bytes": 64 * 1024 * 1024,  # any scene, script, facts, program or network file
    "mesh_bytes": 20 * 1024 * 1024,  # one mesh file of a scene
    "recording_bytes": 2048 * 1024 * 1024,  # a recording read whole (recover, the tolerant scan)
    "dlo_segments": 200,  # at 200 a simulation step with contact extraction takes about real time
    "dlo_length_m": 10.0,
    "dlo_young_pa": 1e12,  # Young's modulus of the cable (steel is 2e11 Pa); 1e308 overflowed the solver
    "scene_objects": 64,  # their pairwise overlap check grows with the square
    "script_waypoints": 10_000,
    "script_duration_s": 600.0,
    "dataset_fps": 500,  # a dataset's frame rate: at most one frame a simulation step (2 ms)
    "image_width": 1920,  # a dataset camera's image (dlovr export --size)
    "image_height": 1080,
}


class InputError(ValueError):
    """A problem with a user's input: one line naming the file, where in it, and the problem."""


def _finite(x: int | float) -> bool:
    """A finite number (an integer too large for a float is not one)."""
    try:
        return math.isfinite(x)
    except OverflowError:
        return False


def shown(raw: Any, width: int = 60) -> str:
    """A user's value as a message shows it: its repr, a huge integer in scientific form (not 180
    digits), anything longer than ``width`` characters cut."""
    if isinstance(raw, int) and not isinstance(raw, bool) and abs(raw) >= 10**15:
        digits = int(abs(raw).bit_length() * math.log10(2)) + 1  # str() fails beyond 4300 digits
        return f"an integer of about {digits} digits"
    text = repr(raw)
    return text if len(text) <= width else text[: width - 3] + "..."


def where_msg(source: str | Path, where: str, msg: str) -> str:
    """The one wording: ``<source>: <where>: <msg>`` (``where`` left out when empty)."""
    return f"{source}: {where}: {msg}" if where else f"{source}: {msg}"


class Fields:
    """Checks the fields of one parsed document; every error is ``error_type`` worded by
    :func:`where_msg` with the document's ``source``."""

    def __init__(self, source: str | Path, error_type: type[InputError] = InputError):
        self.source = source
        self.error_type = error_type

    def err(self, where: str, msg: str) -> InputError:
        """The error (to raise) for ``msg`` at ``where``."""
        return self.error_type(where_msg(self.source, where, msg))

    def table(self, raw: Any, where: str, keys: set[str] | frozenset[str]) -> dict:
        """``raw`` as a table whose keys all lie in ``keys``."""
        if not isinstance(raw, dict):
            raise self.err(where, "must be a table")
        unknown = sorted(set(raw) - set(keys))
        if unknown:
            raise self.err(
                f"{where}.{unknown[0]}" if where else str(unknown[0]),
                f"unknown key (allowed: {', '.join(sorted(keys))})",
            )
        return raw

    def require(self, raw: dict, key: str, where: str = "") -> Any:
        """``raw[key]``; missing is an error."""
        if key not in raw:
            raise self.err(f"{where}.{key}" if where else key, "missing")
        return raw[key]

    def number(self, raw: Any, where: str, *, positive: bool = False, nonneg: bool = False) -> float:
        """A finite number (bool is not one), optionally > 0 or >= 0."""
        if isinstance(raw, bool) or not isinstance(raw, int | float) or not _finite(raw):
            raise self.err(where, f"must be a finite number, got {shown(raw)}")
        if positive and raw <= 0:
            raise self.err(where, f"must be positive, got {shown(raw)}")
        if nonneg and raw < 0:
            raise self.err(where, f"must not be negative, got {shown(raw)}")
        return float(raw)

    def integer(self, raw: Any, where: str, lo: int, hi: int) -> int:
        """An integer from ``lo`` to ``hi`` inclusive."""
        if isinstance(raw, bool) or not isinstance(raw, int) or not lo <= raw <= hi:
            raise self.err(where, f"must be an integer from {lo} to {hi}, got {shown(raw)}")
        return raw

    def vec(self, raw: Any, where: str, n: int, *, positive: bool = False) -> tuple[float, ...]:
        """A list of ``n`` finite numbers."""
        if not isinstance(raw, list) or len(raw) != n:
            raise self.err(where, f"must be a list of {n} numbers, got {shown(raw)}")
        return tuple(self.number(x, f"{where}[{i}]", positive=positive) for i, x in enumerate(raw))

    def at_most(self, count: int, limit_key: str, where: str, what: str) -> None:
        """``count`` ``what`` within ``LIMITS[limit_key]``."""
        limit = LIMITS[limit_key]
        if count > limit:
            raise self.err(where, f"{count:g} {what}, at most {limit:g} allowed")


def read_bytes(
    path: str | Path,
    error_type: type[InputError] = InputError,
    what: str = "file",
    limit_key: str = "file_bytes",
) -> bytes:
    """A regular file's bytes, at most ``LIMITS[limit_key]`` of them: a missing, unreadable or oversized
    file is an error, and so is one that is not a regular file (``/dev/zero``, a FIFO: reading it
    would never end)."""
    import stat

    p = Path(path)
    limit = int(LIMITS[limit_key])
    allowed = f"at most {limit >> 20} MiB allowed for a {what}"
    try:
        with open(p, "rb") as fh:
            st = os.fstat(fh.fileno())
            if stat.S_ISDIR(st.st_mode):
                raise error_type(f"{p}: is a directory, not a {what}")
            if not stat.S_ISREG(st.st_mode):
                raise error_type(f"{p}: not a regular file (a device or a pipe), not a {what}")
            if st.st_size > limit:
                raise error_type(f"{p}: {st.st_size >> 20} MiB, {allowed}")
            data = fh.read(limit + 1)  # bounded even if the file grows meanwhile
    except IsADirectoryError:
        raise error_type(f"{p}: is a directory, not a {what}") from None
    except FileNotFoundError:
        raise error_type(f"{p}: no such {what}") from None
    except OSError as e:
        raise error_type(f"{p}: cannot read: {e.strerror or e}") from None
    if len(data) > limit:
        raise error_type(f"{p}: more than {limit >> 20} MiB, {allowed}")
    return data


def read_text(path: str | Path, error_type: type[InputError] = InputError, what: str = "file") -> str:
    """A UTF-8 text file's contents; a missing, unreadable, oversized or binary file is an error."""
    p = Path(path)
    data = read_bytes(p, error_type, what)
    try:
        return data.decode("utf-8")
    except UnicodeDecodeError:
        raise error_type(f"{p}: not a UTF-8 text file") from None


def read_toml(path: str | Path, error_type: type[InputError] = InputError, what: str = "file") -> dict:
    """A TOML file parsed (see :func:`read_text`); invalid TOML is an error."""
    text = read_text(path, error_type, what)
    try:
        return tomllib.loads(text)
    except tomllib.TOMLDecodeError as e:
        raise error_type(f"{path}: invalid TOML: {e}".replace("\n", " ")) from None


def read_json(path: str | Path, error_type: type[InputError] = InputError, what: str = "file") -> Any:
    """A JSON file parsed (see :func:`read_text`); invalid JSON is an error."""
    return parse_json(read_text(path, error_type, what), path, error_type)


def parse_json(text: str, source: str | Path, error_type: type[InputError] = InputError) -> Any:
    """JSON text parsed; invalid JSON is an error naming ``source`` and the line."""
    try:
        return json.loads(text)
    except json.JSONDecodeError as e:
        raise error_type(f"{source}: not valid JSON: {e.msg} at line {e.lineno}") from None
