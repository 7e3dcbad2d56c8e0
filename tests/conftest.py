"""Shared test setup: a private decomposition cache, so tests never touch the user's cache; the headless
chromium of the browser tests (tests/ui/); the slow mark of every test that drives the browser UI.

The fast tier, ``pytest -m "not slow"``, leaves out the tests marked ``@pytest.mark.slow`` (wheel builds,
trials, long simulations, whole recordings replayed) and, by the rule below, every test that uses a
fixture of :data:`SLOW_FIXTURES`. CI runs every test."""

from __future__ import annotations

import os
import shutil
from collections.abc import Iterator

import pytest

#: Fixtures that make a test slow: headless Chromium (``browser``), the browser UI's server simulating in
#: real time (``server``, tests/ui/conftest.py) and a local Ray instance (``ray_instance``,
#: tests/batch/test_batch.py).
SLOW_FIXTURES = frozenset({"browser", "server", "ray_instance"})


def pytest_collection_modifyitems(items: list[pytest.Item]) -> None:
    for item in items:
        if SLOW_FIXTURES & set(getattr(item, "fixturenames", ())):
            item.add_marker(pytest.mark.slow)


@pytest.fixture(autouse=True, scope="session")
def _private_cache(tmp_path_factory):
    mp = pytest.MonkeyPatch()
    mp.setenv("DLOVR_CACHE_DIR", str(tmp_path_factory.mktemp("dlovr-cache")))
    yield
    mp.undo()


def _chromium() -> str:
    path = shutil.which("chromium") or ("/usr/bin/chromium" if os.path.exists("/usr/bin/chromium") else None)
    if path is None:
        msg = (
            "chromium not found: install it with `sudo apt-get install -y chromium` (Debian/Ubuntu) "
            "to run the browser tests (never `playwright install`)"
        )
        if os.environ.get("CI"):
            pytest.fail(msg)
        pytest.skip(msg)
    return path


@pytest.fixture(scope="module")
def browser() -> Iterator[object]:
    """Headless chromium (Playwright) with software WebGL; skips without chromium (fails under CI)."""
    exe = _chromium()
    from playwright.sync_api import sync_playwright

    from dlovr.ui import HEADLESS_CHROMIUM_ARGS

    with sync_playwright() as pw:
        b = pw.chromium.launch(executable_path=exe, args=HEADLESS_CHROMIUM_ARGS)
        try:
            yield b
        finally:
            b.close()
