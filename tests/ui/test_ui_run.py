"""Running a program in `dlovr serve` (in the browser) and the network view, in
headless chromium. Screenshots go to ``tests/artifacts/`` (ignored by git; or ``DLOVR_UI_ARTIFACTS``).
"""

from __future__ import annotations

import os
from pathlib import Path

from test_ui import open_page, wait_for

from dlovr.ui import DemoServer

ROOT = Path(__file__).resolve().parents[2]
ARTIFACTS = Path(os.environ.get("DLOVR_UI_ARTIFACTS", ROOT / "tests" / "artifacts"))
TABLE_PROGRAM = ROOT / "recordings" / "programs" / "table.program.json"


def shot(page, name: str) -> Path:
    ARTIFACTS.mkdir(parents=True, exist_ok=True)
    path = ARTIFACTS / f"{name}.png"
    close = page.locator(".mantine-Notification-closeButton")  # "software WebGL" notice over the view
    for i in range(close.count()):
        close.nth(i).click()
    page.screenshot(path=str(path), full_page=True)
    print(f"screenshot: {path}")
    return path


def test_the_run_panel_offers_the_programs_of_the_scene_only(server: DemoServer):
    choices = server.run_panel.choices
    assert list(choices) == ["sample: table"] and choices["sample: table"].resolve() == TABLE_PROGRAM
    server.load("peg_in_hole")
    server.run_panel.update()
    assert list(server.run_panel.choices) == ["sample: peg_in_hole"]


def test_the_last_recordings_program_is_offered_and_a_run_can_be_stopped(server: DemoServer):
    wait_for(lambda: server.status()["t"] > 0.2, what="the simulation to run")
    server.start_recording()
    server.jog(dz=-0.05)
    wait_for(lambda: server.status()["t"] > 1.0, what="some recorded time")
    rec = server.stop_recording()
    assert rec is not None and server.last_program is not None
    server.run_panel.update()
    label = f"last recording: {rec.stem}"
    assert next(iter(server.run_panel.choices)) == label
    assert server.run_panel.choices["sample: table"].resolve() == TABLE_PROGRAM
    runner = server.run_panel.run(TABLE_PROGRAM, detect="oracle")
    wait_for(lambda: runner.macro >= 1, what="the run to start")
    server.pause(True)  # the run cannot end before it is stopped
    server.run_panel.cancel()
    server.pause(False)
    assert runner.done and server.session.runner is None and server.run_panel.result == "run stopped"
    t = server.status()["t"]
    wait_for(lambda: server.status()["t"] > t + 0.1, what="the simulation to go on after the run")


def test_run_program_highlights_the_macro_and_shows_the_result(server: DemoServer, browser):
    page = open_page(browser, server.url)
    page.set_viewport_size({"width": 1100, "height": 1500})  # the whole panel in the screenshots
    page.get_by_role("button", name="Run program").wait_for(timeout=30_000)
    wait_for(lambda: server.status()["t"] > 0.2, what="the simulation to run")
    path = server.start_recording()  # the run is recorded like a demonstration
    page.get_by_role("button", name="Run program").click()
    wait_for(lambda: server.run_panel.runner is not None and server.run_panel.runner.macro >= 2,
             timeout=30, what="the run to reach its second macro")
    server.pause(True)  # hold the run on that macro to look at it
    runner = server.run_panel.runner
    macro = runner.macro
    row = page.locator(f'tr[data-current="1"][data-macro="{macro}"]')
    row.wait_for(timeout=30_000)  # a bound: a loaded machine (the suite's other worker busy) is slower
    assert page.locator('tr[data-current="1"]').count() == 1
    assert page.locator('tr[data-outcome="ok"][data-macro="1"]').count() == 1  # macro 1 was detected
    assert page.locator(".dlovr-outcome-key").first.is_visible()  # the marks explained
    wait_for(lambda: "detector of macro" in page.content(), timeout=30, what="the detector caption")
    shot(page, "run-program-running")
    server.pause(False)
    result = page.get_by_text("table (force):")
    result.wait_for(timeout=120_000)
    text = result.inner_text()
    assert "Goal reached" in text or ("Failed" in text and "macro" in text), text
    assert server.run_panel.runner is None and server.session.runner is None
    assert server.status()["recording"] is not None  # still recording after the run
    shot(page, "run-program-result")
    out = server.stop_recording()
    assert out is not None and out.is_file() and out != path  # the run's own recording
    page.close()


def test_the_network_view_shows_the_nodes_and_highlights_the_live_one(server: DemoServer, browser):
    net = server.network_panel.net
    assert net is not None and net.scene_name == "table" and len(net.nodes) >= 2  # from table.mcap
    page = open_page(browser, server.url)
    page.set_viewport_size({"width": 1100, "height": 1500})
    view = page.locator("div.dlovr-network")
    view.wait_for(timeout=30_000)
    assert page.locator("div.dlovr-network svg g.node[data-node]").count() == len(net.nodes)
    assert page.locator("div.dlovr-network svg g.edge[data-edge]").count() == len(net.edges)
    start = net.locate("V/G & E/N & V/N")
    assert start is not None
    page.locator(f'div.dlovr-network[data-live="{start}"]').wait_for(timeout=30_000)
    shot(page, "network-live-start")
    # demonstrate: lower the cable onto the table; the live node follows the kept situation
    p = server.status()["gripper_pos"].copy()
    p[2] = 0.3
    server.set_target(p)
    wait_for(lambda: server.network_panel.live not in (start, None), timeout=30, what="another live node")
    live = server.network_panel.live
    page.locator(f'div.dlovr-network[data-live="{live}"]').wait_for(timeout=30_000)
    assert live in {n.id for n in net.nodes}
    shot(page, "network-live-contact")
    page.close()


def test_the_program_file_is_written_before_the_program_is_announced(server: DemoServer, monkeypatch):
    """The run panel offers the last recording's program once ``last_program`` changes, reading its
    file: the file must be there by then (else the program was never offered: a race seen in CI)."""
    from dlovr.ui.panels import recording

    announced = []
    real = recording.write_output

    def spy(path, *args, **kwargs):
        announced.append(server.last_program is not None)
        return real(path, *args, **kwargs)

    monkeypatch.setattr(recording, "write_output", spy)
    wait_for(lambda: server.status()["t"] > 0.2, what="the simulation to run")
    server.start_recording()
    wait_for(lambda: server.status()["t"] > 0.5, what="some recorded time")
    assert server.stop_recording() is not None and server.last_program is not None
    assert announced == [False, False]
