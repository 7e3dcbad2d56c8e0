"""Shared test setup: a private decomposition cache, so tests never touch the user's cache; the headless
chromium of the browser tests (tests/ui/); the slow mark of every test that drives the browser UI.

The fast tier, ``pytest -m "not slow"``, leaves out the tests marked ``@pytest.mark.slow`` (wheel builds,
trials, long simulations, whole recordings replayed) and, by the rule below, every test that uses a
fixture of :data:`SLOW_FIXTURES`. CI runs every test."""

from __future__ import annotations

import os
import shutil
import subprocess
import time
from collections import deque
from collections.abc import Generator, Iterator
from typing import Any

import pytest
from hypothesis import settings

#: Property tests are judged on what they find, never on how long one example took: these machines are
#: shared, and a 200 ms per-example deadline (hypothesis's default) fails a correct test under load.
settings.register_profile("dlovr", deadline=None)
settings.load_profile("dlovr")

#: Fixtures that make a test slow: headless Chromium (``browser``), the browser UI's server simulating in
#: real time (``server``, tests/ui/conftest.py) and a local Ray instance (``ray_instance``,
#: tests/batch/test_batch.py).
SLOW_FIXTURES = frozenset({"browser", "server", "ray_instance"})


#: The xdist group of the browser UI's tests: they run one after another on one worker, so two
#: real-time servers and two headless browsers never compete for the CPU.
UI_GROUP = "ui"


@pytest.hookimpl(tryfirst=True)
def pytest_collection_modifyitems(items: list[pytest.Item]) -> None:
    """Mark the tests that use a slow fixture ``slow``, give every test its xdist group, and put the
    browser UI's tests first.

    Under ``pytest -n auto`` (the README's test command; ``--dist loadgroup`` is in pyproject.toml's
    addopts) a group runs on one worker: a test file is one group, so its module-scoped fixtures
    (recordings, simulations, servers) are made once; every test of the browser UI is in
    :data:`UI_GROUP`, which is handed out first: it is the longest group (its tests wait on real
    time), and the other worker runs the rest meanwhile. ``tryfirst``: xdist reads the groups in its
    own hook of this name, which must run after this one (without it, no test had a group)."""
    ui_items, other = [], []
    for item in items:
        fixtures = set(getattr(item, "fixturenames", ()))
        if SLOW_FIXTURES & fixtures:
            item.add_marker(pytest.mark.slow)
        ui = bool({"browser", "server"} & fixtures) or "tests/ui/" in item.nodeid
        item.add_marker(pytest.mark.xdist_group(UI_GROUP if ui else item.nodeid.split("::")[0]))
        (ui_items if ui else other).append(item)
    items[:] = ui_items + other


#: How much a worker running the other tests yields the CPU (``os.nice``) to the browser UI's tests.
OTHERS_NICE = 10
_niced = False  # this worker yielded already


def pytest_runtest_setup(item: pytest.Item) -> None:
    """Under ``pytest -n``, a worker about to run a test outside :data:`UI_GROUP` lowers its priority
    (once, for good: its subprocesses and Ray workers inherit it). The browser UI's tests wait on real
    time (a server simulating at real time, headless chromium drawing in software) while the other
    worker's simulations, recordings and batch runs only take longer: on CI's 2-core machine, browser
    waits of 10 s were missed while the other worker kept both cores busy."""
    global _niced
    if _niced or not os.environ.get("PYTEST_XDIST_WORKER"):
        return
    group = item.get_closest_marker("xdist_group")
    if group is not None and group.args and group.args[0] != UI_GROUP:
        os.nice(OTHERS_NICE)
        _niced = True


@pytest.hookimpl(optionalhook=True)
def pytest_xdist_node_collection_finished(node: object, ids: list[str]) -> None:
    """Under ``--dist loadgroup``, stop at once if a worker's tests carry no ``@group``: every test
    would then be handed out alone, the browser tests to both workers at once."""
    config = getattr(node, "config", None)
    if config is None or config.getvalue("dist") != "loadgroup":
        return
    ungrouped = [i for i in ids if "@" not in i]
    if ungrouped:
        pytest.exit(
            f"xdist groups not applied ({ungrouped[0]}): pytest {pytest.__version__} with this "
            "pytest-xdist names tests otherwise (pyproject.toml pins pytest below 9)",
            returncode=4,
        )


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
        watch_pages(b)
        try:
            yield b
        finally:
            b.close()


# -- What a failed browser test reports besides its assertion ------------------------------------

#: A page's console lines kept for the report: uncaught errors, console errors and warnings, and
#: viser's connection lines (a dropped websocket reads "Disconnected! ... code=...").
PAGE_LOG_KEPT = 30
_CONNECTION_LINES = ("Connected!", "Disconnected!", "Order lock")


def watch_pages(browser: Any) -> None:
    """Every page ``browser.new_page`` opens logs what it prints of trouble (its ``dlovr_log``)."""
    new_page = browser.new_page

    def watched(*args: Any, **kwargs: Any) -> Any:
        page = new_page(*args, **kwargs)
        log: deque[str] = deque(maxlen=PAGE_LOG_KEPT)
        setattr(page, "dlovr_log", log)  # noqa: B010
        page.on("pageerror", lambda e: log.append(f"uncaught: {e}"))

        def console(m: Any) -> None:
            if m.type in ("error", "warning") or m.text.startswith(_CONNECTION_LINES):
                log.append(f"console.{m.type}: {m.text}")

        page.on("console", console)
        return page

    setattr(browser, "new_page", watched)  # noqa: B010


def page_state(page: Any) -> str:
    """What the page is doing: viser's queue of received messages not yet applied (they are applied
    at a drawn frame), the animation frames it gets a second, whether it is hidden. Bounded waits
    (a page that stopped answering is said so, never waited on)."""
    try:
        state = page.wait_for_function(
            "() => { window.__dlovrFrames = 0; const m = window.__viserMutable; "
            "return JSON.stringify({queued: m ? m.messageQueue.length : null, "
            "render_request: m ? m.getRenderRequestState : null, "
            "hidden: document.hidden}); }",
            timeout=5_000,
        ).json_value()
    except Exception as e:  # a report: whatever went wrong is the finding
        return f"no answer in 5 s ({type(e).__name__})"
    t0 = time.monotonic()
    try:
        page.wait_for_function("() => (window.__dlovrFrames = (window.__dlovrFrames || 0) + 1) > 20",
                               polling="raf", timeout=5_000)
        fps = f"{20 / (time.monotonic() - t0):.1f}"
    except Exception:
        fps = "under 4"
    return f"{state}, animation frames/s {fps}"


def failure_report(item: pytest.Item) -> str:
    """The machine's load and busiest processes, each open page's state and log, and the state of the
    test's UI server (``server`` or ``demo``): the real-time factor, its clients, its problem lines."""
    out = [f"load average (1, 5, 15 min): {os.getloadavg()}"]
    try:
        ps = subprocess.run(["ps", "-eo", "pcpu,ni,rss,args", "--sort=-pcpu"], capture_output=True,
                            text=True, timeout=5).stdout.splitlines()
        out += [line[:160] for line in ps[:8]]
    except (OSError, subprocess.SubprocessError) as e:
        out.append(f"ps: {e}")
    funcargs = getattr(item, "funcargs", {})
    for ctx in funcargs["browser"].contexts:
        for page in ctx.pages:
            out.append(f"page {page.url}: {page_state(page)}")
            out += [f"  {line}" for line in getattr(page, "dlovr_log", ())]
    for name in ("server", "demo"):
        srv = funcargs.get(name)
        if srv is not None and getattr(srv, "server", None) is not None:
            out.append(f"{name}: real-time factor {srv.loop.rtf:.2f}, "
                       f"{len(srv.server.get_clients())} client(s), problems {srv.reporter.lines[-10:]}")
            out.append(f"  {_server_recording(srv)}")
            out.append(f"  {_server_timeline(srv)}")
    return "\n".join(out)


def _server_recording(srv: Any) -> str:
    """What the server's recording panel shows and does: a recording in progress, its message, its
    compile thread (a program after a recording comes from that thread)."""
    try:
        panel = srv.recording_panel
        thread = panel.compile_thread
        compiling = "none" if thread is None else ("running" if thread.is_alive() else "done")
        return (f"recording {srv.status()['recording']}, compile thread {compiling}, message "
                f"{panel.rec_md.content[:300]!r}, last program {getattr(srv.last_program, 'name', None)}")
    except Exception as e:  # the report must not fail: say what could not be read
        return f"recording state: {type(e).__name__}: {e}"


def _server_timeline(srv: Any) -> str:
    """What the server's timeline panel shows: the live timeline or another (scrubbed or opened), the
    slider's value and range, and whether *Back to live* is shown (a scrub shows it)."""
    try:
        panel, tl = srv.timeline_panel, srv.view.timeline
        scrubbed = tl is not None and tl is srv.session.timeline
        viewed = "live" if tl is None else ("the live one, scrubbed" if scrubbed else tl.source)
        s = panel.slider
        return (f"timeline viewed: {viewed}, slider {s.value} in [{s.min}, {s.max}], "
                f"'Back to live' visible {panel.live_btn.visible}")
    except Exception as e:  # the report must not fail: say what could not be read
        return f"timeline state: {type(e).__name__}: {e}"


@pytest.hookimpl(wrapper=True)
def pytest_runtest_makereport(item: pytest.Item, call: pytest.CallInfo) -> Generator[None, Any, Any]:
    """A failed test that used the browser carries :func:`failure_report` (CI prints it): a wait
    that ran out says what the page and the machine were doing. Every test's item says whether its
    call failed (``call_failed``: a module's shared page is loaded again after one)."""
    rep = yield
    if rep.when == "call":
        setattr(item, "call_failed", rep.failed)  # noqa: B010
    if rep.failed and "browser" in getattr(item, "funcargs", {}):
        try:
            rep.sections.append(("browser and machine at the failure", failure_report(item)))
        except Exception as e:  # never hide the test's own failure
            rep.sections.append(("browser and machine at the failure", f"no report: {e!r}"))
    return rep
