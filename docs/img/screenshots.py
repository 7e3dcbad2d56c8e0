"""Screenshots of `dlovr serve` for the README and docs/ui.md, made from the real page so that they
stay current.

Run: ``.venv/bin/python docs/img/screenshots.py [--out docs/img]`` (needs chromium at
/usr/bin/chromium, as the browser tests do). It starts a :class:`dlovr.ui.DemoServer` on the
peg_in_hole scene, opens it in headless chromium at 1400x900 and writes:

- ``serve.png``: demonstrating, recording: the cable's tip lowered onto the block;
- ``run.png``: the sample program running (the current macro highlighted, the detector signal);
- ``network.png``: the scene's transition network with the live node ringed.
"""

from __future__ import annotations

import argparse
import shutil
import sys
import tempfile
import time
from collections.abc import Callable
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(REPO))

from dlovr.ui import HEADLESS_CHROMIUM_ARGS, DemoServer  # noqa: E402


def wait_for(pred: Callable[[], bool], timeout: float = 30.0, what: str = "condition") -> None:
    end = time.monotonic() + timeout
    while time.monotonic() < end:
        if pred():
            return
        time.sleep(0.05)
    raise SystemExit(f"timed out waiting for {what}")


def shot(page, path: Path) -> None:
    close = page.locator(".mantine-Notification-closeButton")  # the "software WebGL" notice
    for i in range(close.count()):
        close.nth(i).click()
    time.sleep(0.5)
    page.screenshot(path=str(path))
    print(f"wrote {path}")


def demonstrating(srv: DemoServer, page, out: Path) -> None:
    """Recording, the tip lowered until it touches the block."""
    srv.start_recording()
    p = np.asarray(srv.status()["gripper_pos"], dtype=float)
    for _ in range(80):
        if "block" in srv.status()["discrete"]:
            break
        p = p + np.array([0.0, 0.0, -0.005])
        srv.set_target(p)
        time.sleep(0.1)
    time.sleep(1.5)
    shot(page, out / "serve.png")
    srv.stop_recording()


def running(srv: DemoServer, page, out: Path) -> None:
    """The sample program at its third macro, paused there."""
    path = srv.run_panel.choices.get("sample: peg_in_hole")
    if path is None:
        raise SystemExit("no sample program for peg_in_hole")
    runner = srv.run_panel.run(path, detect="force")
    wait_for(lambda: runner.macro >= 3 or runner.done, timeout=90, what="the run's third macro")
    srv.pause(True)
    page.locator('tr[data-current="1"]').first.wait_for(timeout=10_000)
    page.locator('tr[data-current="1"]').first.scroll_into_view_if_needed()
    shot(page, out / "run.png")
    srv.run_panel.cancel()
    srv.pause(False)


def network(srv: DemoServer, page, out: Path) -> None:
    view = page.locator("div.dlovr-network")
    view.wait_for(timeout=60_000)
    view.scroll_into_view_if_needed()
    shot(page, out / "network.png")


def main() -> None:
    ap = argparse.ArgumentParser(description=(__doc__ or "").split("\n")[0])
    ap.add_argument("--out", type=Path, default=REPO / "docs" / "img")
    args = ap.parse_args()
    exe = shutil.which("chromium") or "/usr/bin/chromium"
    from playwright.sync_api import sync_playwright

    args.out.mkdir(parents=True, exist_ok=True)
    with tempfile.TemporaryDirectory() as rec:
        srv = DemoServer("peg_in_hole", port=None, recordings_dir=rec).start()
        try:
            with sync_playwright() as pw:
                browser = pw.chromium.launch(executable_path=exe, args=HEADLESS_CHROMIUM_ARGS)
                page = browser.new_page(viewport={"width": 1400, "height": 900})
                page.goto(srv.url)
                page.get_by_role("button", name="Start recording").wait_for(timeout=60_000)
                wait_for(lambda: srv.status()["t"] > 1.0, what="the simulation to run")
                demonstrating(srv, page, args.out)
                running(srv, page, args.out)
                network(srv, page, args.out)
                browser.close()
        finally:
            srv.stop()


if __name__ == "__main__":
    main()
