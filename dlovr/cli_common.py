"""Shared pieces of the ``dlovr`` commands: the one-line error, loading scenes and scripts, progress
bars, and the decorators that turn bad recordings and unwritable outputs into one line (exit 2)."""

from __future__ import annotations

import click


class UserError(click.ClickException):
    """A problem with the user's input: printed as one line, exit code 2."""

    exit_code = 2


def _plural(n: int, word: str) -> str:
    """``1 macro``, ``2 macros``."""
    return f"{n} {word}{'' if n == 1 else 's'}"


def _t(seconds: float) -> float:
    """A time (s) as printed and exported: rounded to the microsecond (a plain float, no numpy type);
    recordings keep the exact values."""
    return round(float(seconds), 6)


def _scene(ref: str, script=None):
    """Load a scene; one that a script names is reported with the script's file."""
    from dlovr.scene import SceneError, load_scene

    try:
        return load_scene(ref)
    except SceneError as e:
        raise UserError(f"{script.source}: scene: {e}" if script is not None else str(e)) from None


def _script_scene(script, scene_ref: str | None = None):
    """The scene a script runs in: ``scene_ref`` when given, else the one the script names, else
    the built-in table."""
    if scene_ref is not None:
        return _scene(scene_ref)
    return _scene(script.scene, script) if script.scene else _scene("table")


def _script(path: str):
    from dlovr.script import ScriptError, load_script

    try:
        return load_script(path)
    except ScriptError as e:
        raise UserError(str(e)) from None


def _builtin_script(scene_name: str) -> str:
    from dlovr.scene import scenes_dir

    p = scenes_dir() / f"{scene_name}.script.toml"
    if not p.is_file():
        raise UserError(
            f"scene {scene_name} has no built-in demonstration script ({p.name}); give --script FILE"
        )
    return str(p)


def _progress(total: int, label: str):
    import sys

    return click.progressbar(length=total, label=label, file=sys.stderr, show_eta=True, show_percent=True)


def _one_line(fn):
    """Report a bad recording or an output path that cannot be written as one line (exit 2). SIGTERM
    ends the command as an exception (exit 143), so that its temporary files and folders are removed."""
    import functools

    from dlovr.outputs import OutputError
    from dlovr.recording import RecordingError, finish_on_sigterm

    @functools.wraps(fn)
    def wrapper(*a, **kw):
        try:
            with finish_on_sigterm():
                return fn(*a, **kw)
        except (RecordingError, OutputError) as e:
            raise UserError(str(e)) from None

    return wrapper


def _os_errors(fn):
    """Report an ``OSError`` while writing outputs as one line naming the file (exit 2)."""
    import functools

    from dlovr.outputs import describe_os_error

    @functools.wraps(fn)
    def wrapper(*a, **kw):
        try:
            return fn(*a, **kw)
        except OSError as e:
            raise UserError(f"{e.filename or 'output'}: cannot write: {describe_os_error(e)}") from None

    return wrapper


def _refuse_existing(out: str, force: bool) -> None:
    """One line, exit 2, if ``out`` exists and may not be overwritten."""
    import os

    if os.path.lexists(out) and not force:
        raise UserError(f"{out}: exists; give --force to overwrite it")




def _warm_up() -> None:
    """Compile the per-step kernels on the first run, saying so (on stderr)."""
    from dlovr.sim.warmup import warm_up

    warm_up(lambda notice: click.echo(notice, err=True))
