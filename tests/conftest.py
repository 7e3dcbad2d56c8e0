"""Shared test setup: a private decomposition cache, so tests never touch the user's cache."""

from __future__ import annotations

import pytest


@pytest.fixture(autouse=True, scope="session")
def _private_cache(tmp_path_factory):
    mp = pytest.MonkeyPatch()
    mp.setenv("DLOVR_CACHE_DIR", str(tmp_path_factory.mktemp("dlovr-cache")))
    yield
    mp.undo()
