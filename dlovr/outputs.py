"""Output files of the CLI: parent directories created, a failure reported as one line, no partial
file left behind.

- :func:`prepare_output` creates an output file's parent directories (every command that writes a
  file does, so ``-o new/dir/file`` works the same everywhere);
- :func:`atomic_output` writes through a temporary file beside the target, renamed over it only when
  complete, and removed when writing fails or is interrupted; without ``force`` it never replaces a
  file (one that appears meanwhile, another writer's, is kept: the rename is a link that fails);
- :func:`write_output`: a whole small file (JSON, text) that way;
- :class:`StreamOutput`: a file written as a stream (a recording), created exclusively, so that two
  writers never share one file, and locked while written (:func:`being_written` tells);
- :func:`check_writable_dir`: before a batch, that its output folder takes files;
- :func:`remove_partial` removes a file left half-written by a failed write (never a device);
- :class:`OutputError`: the one-line message naming the path and the operating system's error.
"""

from __future__ import annotations

import contextlib
import errno
import os
import secrets
import stat
from collections.abc import Iterator
from pathlib import Path
from typing import Any, BinaryIO

try:
    import fcntl
except ImportError:  # not on POSIX: no locks (being_written is always False)
    fcntl = None  # type: ignore[assignment]


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


def exists_error(path: str | Path) -> OutputError:
    """The one line for an output that exists and may not be replaced."""
    return OutputError(f"{path}: exists; give --force to overwrite it")


def _temporary(p: Path) -> Path:
    """A temporary file beside ``p``, created (empty, with the usual permissions: umask)."""
    tmp = p.with_name(f".{p.name}.{secrets.token_hex(4)}.part")
    try:
        with open(tmp, "xb"):  # created with the usual permissions (umask), unlike mkstemp's 0600
            pass
    except OSError as e:
        raise output_error(p, e) from None
    return tmp


def _put_in_place(tmp: Path, p: Path, force: bool) -> None:
    """Rename the finished ``tmp`` to ``p``: over an existing file only with ``force``; without, a
    hard link that fails if ``p`` exists (so a file another writer made meanwhile is kept)."""
    if force:
        os.replace(tmp, p)
        return
    try:
        os.link(tmp, p)
    except FileExistsError:
        raise exists_error(p) from None
    except OSError as e:
        if e.errno not in (errno.EPERM, errno.EOPNOTSUPP, errno.ENOTSUP, errno.EXDEV, errno.EMLINK):
            raise
        if os.path.lexists(p):  # a file system without hard links: checked, then renamed
            raise exists_error(p) from None
        os.replace(tmp, p)


@contextlib.contextmanager
def atomic_output(path: str | Path, *, force: bool = True) -> Iterator[Path]:
    """Yield a temporary path beside ``path`` to write; on success it is renamed to ``path``.

    On any exception (an OS error, KeyboardInterrupt, ``SystemExit`` from a signal) the temporary
    file is removed and ``path`` is left as it was. An ``OSError`` is re-raised as
    :class:`OutputError` naming ``path``. Without ``force`` an existing ``path`` is refused, before
    and after writing (:func:`exists_error`). A ``path`` that exists and is not a regular file (a
    device, a FIFO) is written directly (with ``force``): it cannot be replaced by a rename.
    """
    p = prepare_output(path)
    if not force and os.path.lexists(p):
        raise exists_error(p)
    if _is_special(p):
        try:
            yield p
        except OSError as e:
            raise output_error(p, e) from None
        return
    tmp = _temporary(p)
    try:
        yield tmp
        _put_in_place(tmp, p, force)
    except OSError as e:
        raise output_error(p, e) from None
    finally:
        with contextlib.suppress(OSError):
            tmp.unlink()  # gone already after a successful rename


def write_output(path: str | Path, data: str | bytes, *, force: bool = True) -> None:
    """Write a whole file atomically (:func:`atomic_output`); text is UTF-8."""
    with atomic_output(path, force=force) as tmp:
        if isinstance(data, str):
            tmp.write_text(data, encoding="utf-8")
        else:
            tmp.write_bytes(data)


def check_writable_dir(path: str | Path) -> Path:
    """Create the folder ``path`` and check that it takes a file (a probe written and removed), so
    that a batch fails before its work, not after; raise :class:`OutputError`."""
    d = prepare_output_dir(path)
    probe = d / f".dlovr-probe-{secrets.token_hex(4)}"
    try:
        with open(probe, "xb") as fh:
            fh.write(b"\0" * 4096)
            fh.flush()
            os.fsync(fh.fileno())
    except OSError as e:
        raise output_error(d, e) from None
    finally:
        with contextlib.suppress(OSError):
            probe.unlink()
    return d


def _lock(fh: BinaryIO) -> None:
    if fcntl is not None:
        with contextlib.suppress(OSError):
            fcntl.flock(fh.fileno(), fcntl.LOCK_EX | fcntl.LOCK_NB)


def being_written(path: str | Path) -> bool:
    """Whether a :class:`StreamOutput` of another process (a recording in progress) holds ``path``."""
    if fcntl is None:
        return False
    try:
        with open(path, "rb") as fh:
            try:
                fcntl.flock(fh.fileno(), fcntl.LOCK_SH | fcntl.LOCK_NB)
            except BlockingIOError:
                return True
            except OSError:
                return False
            fcntl.flock(fh.fileno(), fcntl.LOCK_UN)
            return False
    except OSError:
        return False


class StreamOutput:
    """A file written as a stream (a recording): ``fh`` to write, then :meth:`commit` (or
    :meth:`abandon` when writing failed).

    A new ``path`` is created exclusively and written in place (a killed writer leaves what it wrote,
    for ``dlovr recover``). An existing one is refused without ``overwrite``; with it, the new file is
    written beside it and renamed over it by :meth:`commit` (the old file stays whole until then), and
    a device (``/dev/null``) is written directly. So two writers never write into one file. The file
    is locked while written (:func:`being_written`). Errors are :class:`OutputError` naming ``path``.
    """

    def __init__(self, path: str | Path, *, overwrite: bool = False) -> None:
        self.path = prepare_output(path)
        self.tmp: Path | None = None
        try:
            fd = os.open(self.path, os.O_WRONLY | os.O_CREAT | os.O_EXCL, 0o666)
        except FileExistsError:
            if not overwrite:
                raise exists_error(self.path) from None
            fd = self._beside() if not _is_special(self.path) else self._device()
        except OSError as e:
            raise output_error(self.path, e) from None
        self.fh: BinaryIO = os.fdopen(fd, "wb")
        _lock(self.fh)

    def _beside(self) -> int:
        self.tmp = _temporary(self.path)
        try:
            return os.open(self.tmp, os.O_WRONLY | os.O_TRUNC)
        except OSError as e:
            raise output_error(self.path, e) from None

    def _device(self) -> int:
        try:
            return os.open(self.path, os.O_WRONLY | os.O_TRUNC)
        except OSError as e:
            raise output_error(self.path, e) from None

    def commit(self) -> Path:
        """Close the file; a file written beside the target replaces it now. Returns ``path``."""
        self.fh.close()
        if self.tmp is not None:
            tmp, self.tmp = self.tmp, None
            try:
                os.replace(tmp, self.path)
            except OSError as e:
                with contextlib.suppress(OSError):
                    tmp.unlink()
                raise output_error(self.path, e) from None
        return self.path

    def discard(self) -> None:
        """Close the file and remove what was written (the file made here, or the one beside the
        target); an existing target stays as it was. For a writer that failed before writing
        anything worth keeping."""
        created = self.path if self.tmp is None and not _is_special(self.path) else None
        self.abandon()
        if created is not None:
            with contextlib.suppress(OSError):
                created.unlink()

    def abandon(self) -> None:
        """Close the file; one written beside the target is removed (the target stays as it was)."""
        with contextlib.suppress(OSError):
            self.fh.close()
        if self.tmp is not None:
            with contextlib.suppress(OSError):
                self.tmp.unlink()
            self.tmp = None


__all__ = [
    "OutputError",
    "StreamOutput",
    "atomic_output",
    "being_written",
    "check_writable_dir",
    "describe_os_error",
    "exists_error",
    "output_error",
    "prepare_output",
    "prepare_output_dir",
    "remove_partial",
    "write_output",
]


#: Significant digits of every float a result file or ``--json`` output carries (a time in s to a
#: microsecond, a force in N to a micronewton): ``0.43``, never ``0.4300000000000003``.
RESULT_DIGITS = 6


def rounded(value: Any, digits: int = RESULT_DIGITS) -> Any:
    """``value`` (JSON-like: dicts, lists, tuples, numbers, strings) with every float rounded to
    ``digits`` decimals; other values as they are. Integers and booleans stay exact."""
    if isinstance(value, float):
        return round(value, digits)
    if isinstance(value, dict):
        return {k: rounded(v, digits) for k, v in value.items()}
    if isinstance(value, list | tuple):
        return [rounded(v, digits) for v in value]
    return value
