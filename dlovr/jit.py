"""Compiled kernels: numba's setup for dlovr, in one place.

The per-step pipeline (the simulator's checks and contact arrays, the tracker's labelling) runs in
numba kernels (``dlovr.geometry.kernels``, ``dlovr.sim.kernels``). They are compiled on first use and
cached on disk (``cache=True``): in ``__pycache__`` beside the sources, or, when the package directory
is read-only, in ``<cache dir>/numba`` (:func:`dlovr.cache.cache_dir`; ``$NUMBA_CACHE_DIR`` wins when
set). Without ``fastmath`` LLVM neither fuses multiply-adds nor reorders sums, so the kernels round
the same on every x86-64 processor (their labels go into recordings that replay bit for bit);
:func:`fma` is the one explicit fused multiply-add, correctly rounded everywhere.

:func:`kernels_warm` tells whether this installation has compiled them already (a marker file keyed
by the versions of Python, numba and dlovr and the kernels' sources, beside numba's cache), so that
commands can say "compiling kernels (first run only)" while :func:`dlovr.sim.warm_up` compiles them;
:func:`check_cache` drops cached kernels compiled from other sources.

The kernel store (``<cache dir>/kernels/<key>-<processor>``, :func:`store_dir`) keeps one copy of
the compiled kernels per key for the whole machine: :func:`keep_in_store` copies an installation's
compiled kernels there, and :func:`check_cache` copies them from there into an installation that
has none (a new virtual environment, an upgrade with the same kernels, another checkout). numba's cache is
keyed by the sources' content (not their path or time) and by the processor, so the copied kernels
are the ones this installation would compile (the store is kept per processor too).
``DLOVR_KERNEL_STORE=0`` turns the store off.
"""

from __future__ import annotations

import hashlib
import os
import shutil
import sys
import tempfile
from collections.abc import Callable
from pathlib import Path
from typing import Any, Protocol, cast

from dlovr import __version__
from dlovr.cache import cache_dir

_PACKAGE = Path(__file__).resolve().parent


def _writable(directory: Path) -> bool:
    cache = directory / "__pycache__"
    return os.access(cache if cache.is_dir() else directory, os.W_OK)


if "NUMBA_CACHE_DIR" not in os.environ and not (
    _writable(_PACKAGE / "geometry") and _writable(_PACKAGE / "sim")
):
    os.environ["NUMBA_CACHE_DIR"] = str(cache_dir() / "numba")

import numba  # noqa: E402  (after the cache directory is chosen)
from llvmlite import ir  # noqa: E402
from numba.core import cgutils, config, types  # noqa: E402
from numba.core.registry import CPUDispatcher  # noqa: E402
from numba.extending import intrinsic  # noqa: E402


class _NumbaSettings(Protocol):
    """The settings of ``numba.core.config`` that dlovr reads and sets: numba makes them at import
    time from the environment (through ``globals()``), so a type checker sees no such names."""

    CACHE_DIR: str
    DISABLE_JIT: int


_numba_config = cast(_NumbaSettings, config)

if os.environ.get("NUMBA_CACHE_DIR") and _numba_config.CACHE_DIR != os.environ["NUMBA_CACHE_DIR"]:
    _numba_config.CACHE_DIR = os.environ["NUMBA_CACHE_DIR"]  # numba was imported before dlovr


_KERNELS: dict[str, list[Any]] = {}  # the kernels of each module

# numba's options for every kernel: nopython, no fastmath, the GIL released; no C-callable wrapper
# (``cfunc``: no kernel is called through one); division by zero gives inf or nan instead of raising
# (no kernel divides by zero; the checks are code to compile and run for nothing)
_OPTIONS = {"nogil": True, "no_cfunc_wrapper": True, "error_model": "numpy"}


class _InnerKernel(CPUDispatcher):
    """A kernel called only from other kernels: compiled without numba's CPython wrapper (the code
    that unboxes its arguments from Python objects and boxes its results, compiled and cached for
    nothing when only kernels call it). Called from Python it raises: it has nothing to run."""

    def __call__(self, *args: Any, **kwargs: Any) -> Any:
        raise TypeError(f"{self.py_func.__qualname__}: an inner kernel, called only from kernels")


def njit(fn: Callable[..., Any] | None = None, *, inner: bool = False, inline: bool = False) -> Any:
    """``numba.njit`` as dlovr's kernels use it: cached on disk, no fastmath, no Python fallback
    (see ``_OPTIONS``). ``@njit(inner=True)``: a kernel that only other kernels call
    (:class:`_InnerKernel`); ``inline=True`` (inner kernels only): numba inlines its code into its
    callers' before typing them instead of compiling it alone, for a kernel with one caller and
    callees of its own, whose code would otherwise be optimised and compiled to machine code once
    more in its own module."""
    if fn is None:
        return lambda f: njit(f, inner=inner, inline=inline)
    if _numba_config.DISABLE_JIT:
        return fn
    if inner:
        options = {**_OPTIONS, "nopython": True, "no_cpython_wrapper": True}
        if inline:
            options["inline"] = "always"
        kernel = _InnerKernel(py_func=fn, targetoptions=options)
        kernel.enable_caching()
    else:
        kernel = numba.njit(cache=True, **_OPTIONS)(fn)
    _KERNELS.setdefault(fn.__module__, []).append(kernel)
    return kernel


@intrinsic
def fma(typingctx: Any, a: Any, b: Any, c: Any) -> Any:
    """``a * b + c`` rounded once (LLVM's ``llvm.fma.f64``): the rounding of BLAS kernels that fuse,
    reproduced exactly on every processor."""
    sig = types.float64(types.float64, types.float64, types.float64)

    def codegen(context: Any, builder: Any, signature: Any, args: Any) -> Any:
        d = ir.DoubleType()
        fn = cgutils.get_or_insert_function(builder.module, ir.FunctionType(d, [d, d, d]), "llvm.fma.f64")
        return builder.call(fn, args)

    return sig, codegen


KERNEL_SOURCES = ("geometry/kernels.py", "sim/kernels.py", "sim/track_kernels.py", "jit.py")


def _key() -> str:
    """The versions and the kernels' sources, hashed: compiled kernels are valid for one key."""
    h = hashlib.sha256(f"{sys.version}|{numba.__version__}|{__version__}".encode())
    for rel in KERNEL_SOURCES:
        h.update((_PACKAGE / rel).read_bytes())
    return h.hexdigest()[:24]


def _cache_path(module: str) -> Path | None:
    """Where numba caches ``module``'s kernels (None if it cannot tell)."""
    kernels = _KERNELS.get(module)
    try:
        return Path(kernels[0]._cache._cache_path) if kernels else None
    except AttributeError:
        return None


def check_cache(module: str) -> None:
    """Drop ``module``'s cached kernels if they were compiled from other kernel sources.

    numba checks a cached kernel against its own source file only, while kernels call kernels of
    other modules (compiled into them): after any kernel source changes, every module's cache is
    flushed once, so nothing stale runs. Called at the end of each kernel module."""
    path = _cache_path(module)
    if path is None:
        return
    stamp = path / f"dlovr-{module.rpartition('.')[2]}.key"
    key = _key()
    try:
        if stamp.is_file() and stamp.read_text() == key:
            return
        for kernel in _KERNELS[module]:
            kernel._cache.flush()
        path.mkdir(parents=True, exist_ok=True)
        _take_from_store(module, path)
        stamp.write_text(key)
    except (OSError, AttributeError):
        pass


def _marker() -> Path:
    path = _cache_path("dlovr.sim.track_kernels") or cache_dir() / "numba"
    return path / "dlovr-kernels.warm"


def kernels_warm() -> bool:
    """Whether this installation has compiled the current kernels already (see the module docstring;
    import the kernel modules first)."""
    try:
        return _marker().read_text() == _key()
    except OSError:
        return False


def mark_kernels_warm() -> None:
    """Record that the current kernels are compiled (a failure to write only repeats the notice)."""
    path = _marker()
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
        path.write_text(_key())
    except OSError:
        pass


_CACHE_FILES = (".nbi", ".nbc")  # numba's index and data files


def store_dir() -> Path | None:
    """This key's folder in the kernel store, for this processor (numba's target: triple, processor
    name and features, which its cache keys kernels by too); None when ``DLOVR_KERNEL_STORE=0``."""
    if os.environ.get("DLOVR_KERNEL_STORE", "1") == "0":
        return None
    from numba.core.registry import cpu_target

    context: Any = cpu_target.target_context
    target = hashlib.sha256(repr(context.codegen().magic_tuple()).encode()).hexdigest()
    return cache_dir() / "kernels" / f"{_key()}-{target[:12]}"


def _module_files(module: str, path: Path) -> list[Path]:
    """``module``'s compiled kernels in numba's cache folder ``path`` (which other modules share):
    numba names them ``<file name>.<kernel>-<line>.py<version>.nb[ic]``; the warm marker with them."""
    prefix = module.rpartition(".")[2] + "."
    files = [p for p in path.iterdir() if p.name.startswith(prefix) and p.suffix in _CACHE_FILES]
    if _marker().parent == path and _marker().is_file() and module == "dlovr.sim.track_kernels":
        files.append(_marker())
    return files


def _take_from_store(module: str, path: Path) -> None:
    """Copy ``module``'s compiled kernels from the store into its cache folder ``path`` (nothing when
    the store has none for this key); each file is written aside and renamed into place."""
    store = store_dir()
    if store is None or not (store / module).is_dir():
        return
    for src in (store / module).iterdir():
        tmp = path / f".{src.name}.{os.getpid()}.tmp"
        shutil.copyfile(src, tmp)
        tmp.replace(path / src.name)


def keep_in_store() -> None:
    """Copy this installation's compiled kernels (every kernel module imported, the kernels warm)
    into the store, unless it has them for this key already: written aside and renamed, so a
    reader finds all or nothing. The store keeps the four most recent keys. Failures are ignored
    (the store only saves compiling)."""
    store = store_dir()
    if store is None or store.is_dir() or not kernels_warm():
        return
    try:
        store.parent.mkdir(parents=True, exist_ok=True)
        with tempfile.TemporaryDirectory(prefix=".new-", dir=store.parent) as tmp:
            for module in _KERNELS:
                path = _cache_path(module)
                if path is None or not path.is_dir():
                    return
                (Path(tmp) / module).mkdir()
                for f in _module_files(module, path):
                    shutil.copyfile(f, Path(tmp) / module / f.name)
            os.rename(tmp, store)
            os.mkdir(tmp)  # for TemporaryDirectory's clean-up
        old = sorted((p for p in store.parent.iterdir() if not p.name.startswith(".")), key=os.path.getmtime)
        for p in old[:-4]:
            shutil.rmtree(p, ignore_errors=True)
    except OSError:
        pass
