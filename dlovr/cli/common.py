"""Shared pieces of the ``dlovr`` commands: the one user-error class and the exit codes, the group
that turns every problem with the user's input into that error (one line, exit code 2), loading
scenes and scripts, progress bars, and the decorators for SIGTERM and unwritable outputs."""

from __future__ import annotations

import functools
import math
import os
import signal
import sys
from collections.abc import Callable
from typing import Any, NoReturn, ParamSpec, TypeVar

import click

from dlovr import signals
from dlovr.inputs import InputError
from dlovr.outputs import OutputError

#: Exit status of every ``dlovr`` command, in one place.
EXIT_OK = 0
EXIT_FAILED = 1
EXIT_BAD_INPUT = 2
EXIT_SIGINT = 130
EXIT_SIGTERM = 143
EXIT_CODES: dict[int, str] = {
    EXIT_OK: "done (dlovr run: the goal was reached)",
    EXIT_FAILED: "the work ran and failed: a run missed its goal, a simulation or a replay diverged",
    EXIT_BAD_INPUT: "bad input (one line on stderr naming the file and the problem), or failed outputs",
    EXIT_SIGINT: "interrupted by Ctrl-C (SIGINT); a recording in progress is kept, finished",
    EXIT_SIGTERM: "ended by SIGTERM; a recording in progress is kept, temporary files removed",
}

P = ParamSpec("P")
R = TypeVar("R")


class UserError(click.ClickException):
    """A problem with the user's input: printed as one line, exit code 2 (the only such class)."""

    exit_code = EXIT_BAD_INPUT


#: What a command may raise for a problem with the user's input: every reader's error
#: (``InputError`` and its subclasses: scene, script, facts, network, recording, ``--vary``,
#: ``--cluster``, ...) and an output path that cannot be written.
USER_ERRORS: tuple[type[Exception], ...] = (InputError, OutputError)


class Group(click.Group):
    """A click group that reports every :data:`USER_ERRORS` of its commands (their options'
    callbacks included) as one :class:`UserError` line: the one place where that happens.

    It also ends a command on SIGINT (Ctrl-C) or SIGTERM at any moment, start-up included, with one
    line and exit 130 or 143 (:mod:`dlovr.signals`): a signal that a dependency swallowed on its way
    is still pending when the command returns, and ends it then."""

    def main(self, *args: Any, **kwargs: Any) -> Any:
        from dlovr import cache

        cache.set_reporter(lambda line: click.echo(line, err=True))  # a large mesh's first load...
        with signals.installed():
            if signals.pending() is not None:  # it came while the program started
                interrupted(signals.pending())
            return super().main(*args, **kwargs)

    def invoke(self, ctx: click.Context) -> Any:
        try:
            rv = super().invoke(ctx)
        except USER_ERRORS as e:
            if signals.pending() is None:
                raise UserError(str(e)) from None
            interrupted(signals.pending())
        except KeyboardInterrupt:
            interrupted(signals.pending() or signal.SIGINT)
        except signals.SignalExit as e:
            interrupted(e.signum)
        except SystemExit:
            if signals.pending() is None:
                raise  # the command's own exit (after a signal: the status it chose, 130 or 143)
            interrupted(signals.pending())
        if signals.pending() is not None:
            interrupted(signals.pending())
        return rv


def interrupted(signum: int | None) -> NoReturn:
    """End the command after ``signum``: one line on stderr, exit 130 (SIGINT) or 143 (SIGTERM)."""
    signum = int(signum or signal.SIGINT)
    signals.clear()
    click.echo(f"interrupted ({signals.name(signum)})", err=True)
    raise SystemExit(signals.exit_code(signum))


class FiniteFloat(click.ParamType):
    """A finite number of at least ``minimum`` (``nan`` and ``inf`` are refused: one line, exit 2)."""

    name = "number"

    def __init__(self, minimum: float | None = None) -> None:
        self.minimum = minimum

    def convert(self, value: Any, param: click.Parameter | None, ctx: click.Context | None) -> float:
        try:
            x = float(value)
        except (TypeError, ValueError):
            self.fail(f"{value!r} is not a number", param, ctx)
        if not math.isfinite(x) or (self.minimum is not None and x < self.minimum):
            bound = f"a finite number >= {self.minimum:g}" if self.minimum is not None else "a finite number"
            self.fail(f"must be {bound}, got {value}", param, ctx)
        return x


def plural(n: int, word: str) -> str:
    """``1 macro``, ``2 macros``."""
    return f"{n} {word}{'' if n == 1 else 's'}"


def rounded_time(seconds: float) -> float:
    """A time (s) as printed and exported: rounded to the microsecond (a plain float, no numpy type);
    recordings keep the exact values."""
    return round(float(seconds), 6)


def load_scene_arg(ref: str, script: Any = None) -> Any:
    """Load and check a scene (name or path); one that a script names is reported with the script's
    file."""
    from dlovr.geometry.scene_checks import load_checked_scene
    from dlovr.scene import SceneError

    if script is None:
        return load_checked_scene(ref)
    try:
        return load_checked_scene(ref)
    except SceneError as e:
        raise UserError(f"{script.source}: scene: {e}") from None


def script_scene(script: Any, scene_ref: str | None = None) -> Any:
    """The scene a script runs in: ``scene_ref`` when given, else the one the script names, else
    the built-in table."""
    if scene_ref is not None:
        return load_scene_arg(scene_ref)
    return load_scene_arg(script.scene, script) if script.scene else load_scene_arg("table")


def builtin_script(scene_name: str) -> str:
    """The path of a built-in scene's demonstration script."""
    from dlovr.scene import scenes_dir

    p = scenes_dir() / f"{scene_name}.script.toml"
    if not p.is_file():
        raise UserError(
            f"scene {scene_name} has no built-in demonstration script ({p.name}); give --script FILE"
        )
    return str(p)


def progress_bar(total: int, label: str) -> Any:
    """A progress bar on stderr over ``total`` units."""
    return click.progressbar(length=total, label=label, file=sys.stderr, show_eta=True, show_percent=True)


def finishes_on_sigterm(fn: Callable[P, R]) -> Callable[P, R]:
    """SIGTERM ends the command as an exception (exit 143), so that its temporary files and folders
    are removed and a recording in progress is finished."""
    from dlovr.recording import finish_on_sigterm

    @functools.wraps(fn)
    def wrapper(*a: P.args, **kw: P.kwargs) -> R:
        with finish_on_sigterm():
            return fn(*a, **kw)

    return wrapper


def os_errors_as_user_errors(fn: Callable[P, R]) -> Callable[P, R]:
    """Report an ``OSError`` while writing outputs as one line naming the file (exit 2)."""
    from dlovr.outputs import describe_os_error

    @functools.wraps(fn)
    def wrapper(*a: P.args, **kw: P.kwargs) -> R:
        try:
            return fn(*a, **kw)
        except OSError as e:
            raise UserError(f"{e.filename or 'output'}: cannot write: {describe_os_error(e)}") from None

    return wrapper


def shown_dir(out: str) -> str:
    """An output folder as printed: ``DIR/`` with one slash whatever ``-o`` ended with (``demos//``
    and ``demos`` are both ``demos/``; ``/`` stays ``/``)."""
    trimmed = out.rstrip("/")
    return trimmed + "/" if trimmed else out


def refuse_existing(out: str, force: bool) -> None:
    """One line, exit 2, if ``out`` exists and may not be overwritten."""
    if os.path.lexists(out) and not force:
        raise UserError(f"{out}: exists; give --force to overwrite it")


def warm_up() -> None:
    """Compile the per-step kernels on the first run, saying so (on stderr)."""
    from dlovr.sim.warmup import warm_up as compile_kernels

    compile_kernels(lambda notice: click.echo(notice, err=True))


def freeze_setup() -> None:
    """Leave every object made so far out of the garbage collector's collections (``gc.freeze``):
    the modules, numba's and MuJoCo's objects, the scene, some 170,000 in all.

    A long simulation makes per-step objects (situations, contact states, records) that outlive the
    young generations, and each full collection then walks every object of the process: about
    190 ms each, some 50 µs a step over the drape case (docs/benchmarks.md); frozen, it walks only
    what the run made. The commands that simulate (``demo``, ``record``, ``replay``, ``run``,
    ``serve``) call it once their setup is done. Process-wide, so not in the library; what was
    frozen and later becomes cyclic garbage is never collected (setup leaves little)."""
    import gc

    gc.freeze()

