"""The project's on-disk cache directory (convex decompositions, compiled kernels when the package
directory is read-only): ``$DLOVR_CACHE_DIR``, else ``$XDG_CACHE_HOME/dlovr``, else ``~/.cache/dlovr``."""

from __future__ import annotations

import os
from pathlib import Path


def cache_dir() -> Path:
    """The cache directory (not created here)."""
    env = os.environ.get("DLOVR_CACHE_DIR")
    if env:
        return Path(env)
    xdg = os.environ.get("XDG_CACHE_HOME")
    return (Path(xdg) if xdg else Path.home() / ".cache") / "dlovr"
