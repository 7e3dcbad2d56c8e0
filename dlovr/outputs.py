"""Output files of the CLI: parent directories created, a failure reported as one line, no partial
file left behind.

- :func:`prepare_output` creates an output file's parent directories (every command that writes a
  file does, so ``-o new/dir/file`` works the same everywhere);
- :func:`atomic_output` writes through a temporary file beside the target, renamed over it only when
  complete, and removed when writing fails or is interrupted;
- :func:`remove_partial` removes a file left half-written by a failed write (never a device);
- :class:`OutputError`: the one-line message naming the path and the operating system's error.
"""

from __future__ import annotations

import contextlib
import os
import secrets
import stat
from collections.abc import Iterator
from pathlib import Path


class OutputError(ValueError):
    """An output path cannot be written: one line, ``PATH: cannot write: <OS error>``."""


def describe_os_error(e: OSError) -> str:
    """The operating system's words for ``e`` (``No space left on device``), without the errno."""
    return e.strerror or str(e) or type(e).__name__


def output_error(path: str | Path, e: OSError, what: str = "cannot write") -> OutputError:
    """An :class:`OutputError` naming ``path`` (the path the user gave, not a temporary one)."""
    return OutputError(f"{path}: {what}: {describe_os_error(e)}")


def prepare_output(path: str | Path) -> Path:
    """Create the parent directories of the output file ``path``; raise :class:`OutputError`."""
    p = Path(path)
    try:
        p.parent.mkdir(parents=True, exist_ok=True)
    except OSError as e:
        raise output_error(p.parent, e, "cannot create directory") from None
    return p


def prepare_output_dir(path: str | Path) -> Path:
    """Create the output directory ``path`` (and its parents); raise :class:`OutputError`."""
    p = Path(path)
    try:
        p.mkdir(parents=True, exist_ok=True)
    except OSError as e:
        raise output_error(p, e, "cannot create directory") from None
    return p


def _is_special(p: Path) -> bool:
    """An existing path that is not a regular file (a device such as ``/dev/full``, a FIFO)."""
    try:
        return not stat.S_ISREG(p.stat().st_mode)
    except OSError:
        return False


def remove_partial(path: str | Path) -> bool:
    """Remove a regular file left half-written at ``path``; True if one was removed."""
    p = Path(path)
    if _is_special(p) or not p.is_file():
        return False
    with contextlib.suppress(OSError):
        p.unlink()
        return True
    return False


@contextlib.contextmanager
def atomic_output(path: str | Path) -> Iterator[Path]:
    """Yield a temporary path beside ``path`` to write; on success it is renamed to ``path``.

    On any exception (an OS error, KeyboardInterrupt, ``SystemExit`` from a signal) the temporary
    file is removed and ``path`` is left as it was. An ``OSError`` is re-raised as
    :class:`OutputError` naming ``path``. A ``path`` that exists and is not a regular file (a device,
    a FIFO) is written directly: it cannot be replaced by a rename.
    """
    p = prepare_output(path)
    if _is_special(p):
        try:
            yield p
        except OSError as e:
            raise output_error(p, e) from None
        return
    tmp = p.with_name(f".{p.name}.{secrets.token_hex(4)}.part")
    try:
        with open(tmp, "xb"):  # created with the usual permissions (umask), unlike mkstemp's 0600
            pass
    except OSError as e:
        raise output_error(p, e) from None
    try:
        yield tmp
        os.replace(tmp, p)
    except OSError as e:
        raise output_error(p, e) from None
    finally:
        with contextlib.suppress(OSError):
            tmp.unlink()  # gone already after a successful rename


__all__ = [
    "OutputError",
    "atomic_output",
    "describe_os_error",
    "output_error",
    "prepare_output",
    "prepare_output_dir",
    "remove_partial",
]
