"""Every message from a browser tab is untrusted input: :func:`guard_incoming` checks each one before
any handler (the gizmo's, the panels') sees it, and :func:`checked_pose` checks a gripper target before
it reaches the simulation thread.

A message holding a number that is not finite (NaN, inf: msgpack carries them) is refused, and so is a
gizmo pose that is not a pose (a position that is not 3 finite numbers within :data:`MAX_COORD`, a
quaternion that is not 4 finite numbers of non-zero length); a handler that raises is reported instead
of ending the message's task. Each refusal is reported as one line (:class:`Reporter`: on stderr and on
every tab, at most once a second for the same kind of problem).
"""

from __future__ import annotations

import dataclasses
import math
import sys
import time
from collections.abc import Callable
from typing import Any

import numpy as np

#: Largest gripper target coordinate accepted (m, world frame): far beyond any scene's workspace.
MAX_COORD = 100.0
#: How deep and how many values of a message are checked (client messages are small).
MAX_DEPTH, MAX_VALUES = 12, 100_000


class Reporter:
    """One line on stderr, and a notification on every tab of ``server`` (when given) for each
    problem; the same ``kind`` of problem at most once every ``every`` seconds (a hostile client may
    send many)."""

    def __init__(self, server: Any = None, every: float = 1.0) -> None:
        self.server = server
        self.every = every
        self._last: dict[str, float] = {}
        self.lines: list[str] = []  # every line reported (tests read it)

    def __call__(self, kind: str, line: str) -> None:
        now = time.monotonic()
        if now - self._last.get(kind, -math.inf) < self.every:
            return
        self._last[kind] = now
        self.lines.append(line)
        print(f"dlovr serve: {line}", file=sys.stderr, flush=True)
        srv: Any = self.server() if callable(self.server) else self.server
        if srv is None:
            return
        try:
            for client in list(srv.get_clients().values()):
                client.add_notification("dlovr", line, color="red", auto_close_seconds=10.0)
        except Exception:  # a tab that went away: the line on stderr is enough
            pass


def message_problem(message: Any) -> str | None:
    """Why a client's message is refused (a number that is not finite), or None."""
    stack: list[tuple[str, Any, int]] = [(type(message).__name__, message, 0)]
    seen = 0
    while stack:
        where, x, depth = stack.pop()
        seen += 1
        if seen > MAX_VALUES or depth > MAX_DEPTH:
            return "too large or too deeply nested"
        if isinstance(x, float | np.floating):
            if not math.isfinite(x):
                return f"{where}: {x} is not a finite number"
        elif dataclasses.is_dataclass(x) and not isinstance(x, type):
            if hasattr(x, "position") and hasattr(x, "wxyz"):  # a pose (the gizmo's)
                try:
                    checked_pose(getattr(x, "position"), getattr(x, "wxyz"))  # noqa: B009
                except ValueError as e:
                    return f"{where}: {str(e).split(': ', 1)[1]}"
            fields = dataclasses.fields(x)
            stack.extend((f"{where}.{f.name}", getattr(x, f.name, None), depth + 1) for f in fields)
        elif isinstance(x, dict):
            stack.extend((f"{where}[{k!r}]", v, depth + 1) for k, v in x.items())
        elif isinstance(x, list | tuple):
            stack.extend((f"{where}[{i}]", v, depth + 1) for i, v in enumerate(x))
        elif isinstance(x, np.ndarray) and x.dtype.kind == "f" and not np.isfinite(x).all():
            return f"{where}: holds numbers that are not finite"
    return None


def _short(x: Any) -> str:
    """A client's value in a message: its repr, cut to 60 characters."""
    text = repr(x.tolist() if isinstance(x, np.ndarray) else x)
    return text if len(text) <= 60 else text[:57] + "..."


def checked_pose(pos: Any, quat: Any) -> tuple[np.ndarray, np.ndarray]:
    """A gripper target as given by a client: position (m, world) and unit quaternion (wxyz,
    normalised here); raise ``ValueError`` (one line) when it is not a pose."""
    try:
        p = np.asarray(pos, dtype=float).reshape(-1)
        q = np.asarray(quat, dtype=float).reshape(-1)
    except (TypeError, ValueError):
        raise ValueError(f"gripper target: not numbers: {_short(pos)}, {_short(quat)}") from None
    if p.shape != (3,) or not np.isfinite(p).all() or np.abs(p).max() > MAX_COORD:
        within = f"within {MAX_COORD:g} m"
        raise ValueError(f"gripper target: position must be 3 finite numbers {within}, got {_short(pos)}")
    n = float(np.linalg.norm(q)) if q.shape == (4,) and np.isfinite(q).all() else 0.0
    if not n > 1e-9:
        raise ValueError(f"gripper target: orientation must be a quaternion (4 finite numbers, not all 0), "
                         f"got {_short(quat)}")
    return p, q / n


def guard_incoming(server: Any, report: Callable[[str, str], None]) -> bool:
    """Check every message a client sends to ``server`` (a started ``viser.ViserServer``) before its
    handlers run (:func:`message_problem`), and report a handler that raises; False if this viser
    has no place to hook it (then only :func:`checked_pose` guards the simulation)."""
    ws = getattr(server, "_websock_server", None)
    inner = getattr(ws, "_handle_incoming_message", None)
    if inner is None:
        return False

    async def guarded(client_id: Any, message: Any) -> None:
        name = type(message).__name__
        problem = message_problem(message)
        if problem is not None:
            report(f"refused:{name}", f"a message from tab {client_id} was refused: {problem}")
            return
        try:
            await inner(client_id, message)
        except Exception as e:  # the message's task would end with a traceback on stderr only
            text = " ".join(str(e).split()) or type(e).__name__
            report(f"failed:{name}", f"a message from tab {client_id} ({name}) failed: {text}")

    setattr(ws, "_handle_incoming_message", guarded)  # noqa: B010 - viser's one entry point of messages
    return True


__all__ = ["MAX_COORD", "Reporter", "checked_pose", "guard_incoming", "message_problem"]
