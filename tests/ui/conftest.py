"""Shared fixtures of the browser UI tests (the headless ``browser`` is in tests/conftest.py)."""

from __future__ import annotations

from collections.abc import Iterator
from pathlib import Path

import pytest

from dlovr.ui import DemoServer


@pytest.fixture
def server(tmp_path: Path) -> Iterator[DemoServer]:
    srv = DemoServer("table", port=None, recordings_dir=tmp_path / "recordings").start()
    try:
        yield srv
    finally:
        srv.stop()
