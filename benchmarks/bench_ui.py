"""`dlovr serve` as a browser sees it: cable updates per second, gizmo-to-cable and key-to-motion
latency, page load to the first frame with the cable.

Run: ``.venv/bin/python benchmarks/bench_ui.py [--scene table] [--seconds 5] [--trials 20] [--publish-hz HZ]``

Starts a :class:`dlovr.ui.DemoServer` in-process and opens it in headless Debian chromium
(``/usr/bin/chromium``, software WebGL) through Playwright. Every websocket frame the page receives is
decoded (viser's wire format: zstd-compressed msgpack) and timestamped as it arrives.

- *updates/s*: the gizmo is dragged in a circle through its own message path (20 updates/s, as the
  browser sends them); frames carrying an update of the cable tube are counted over ``--seconds``.
- *latency*: with the gripper at rest, one gizmo update moves the target 2 cm; the latency is the time
  from sending it until the first frame carrying both the cable and a moved gripper (they are
  published together). Median and 90th percentile over ``--trials``.

- *key to motion*: with the gripper at rest, a jog key goes down (Playwright's keyboard, the real key
  path: the page's key follower reports it to the server, which moves the target one step); the
  latency is the time until the first frame with a moved gripper. Median and 90th percentile.
- *page load*: from ``page.goto`` until the first frame carrying the cable.

Targets: at least 60 updates/s, at most 50 ms median latency, key to motion at most 100 ms median.
The server's own publish rate is printed beside the count that reaches the page: on a loaded machine
the two differ when the server's send loop runs late and sends two publishes in one frame.
"""

from __future__ import annotations

import argparse
import math
import shutil
import statistics
import sys
import threading
import time
from pathlib import Path

import msgspec
import numpy as np
import zstandard

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))

from dlovr.ui import HEADLESS_CHROMIUM_ARGS as ARGS  # noqa: E402
from dlovr.ui import DemoServer  # noqa: E402


class FrameLog:
    """Decoded websocket frames: (arrival time, has cable update, gripper body position or None)."""

    def __init__(self) -> None:
        self.frames: list[tuple[float, bool, tuple[float, ...] | None]] = []
        self.sent: list[tuple[float, tuple[float, ...]]] = []
        self._dz = zstandard.ZstdDecompressor()
        self._lock = threading.Lock()

    def on_frame(self, payload: bytes | str) -> None:
        t = time.perf_counter()
        if isinstance(payload, str):
            return
        n = int.from_bytes(payload[:8], "little")
        c = int.from_bytes(payload[8:16], "little")
        inner = msgspec.msgpack.decode(self._dz.decompress(payload[16 : 16 + c], max_output_size=n))
        cable = False
        body = None
        for m in inner.get("messages", []):
            name = m.get("name", "")
            if name == "/cable/tube":
                cable = True
            elif name == "/gripper_body" and m.get("type") == "SetPositionMessage":
                body = tuple(m["position"])
        with self._lock:
            self.frames.append((t, cable, body))

    def on_sent(self, payload: bytes | str) -> None:
        t = time.perf_counter()
        if isinstance(payload, str):
            return
        try:
            msg = msgspec.msgpack.decode(payload)
        except msgspec.DecodeError:
            return
        if isinstance(msg, dict) and msg.get("type") == "TransformControlsUpdateMessage":
            with self._lock:
                self.sent.append((t, tuple(msg.get("position", ()))))

    def since(self, t0: float) -> list[tuple[float, bool, tuple[float, ...] | None]]:
        with self._lock:
            return [f for f in self.frames if f[0] >= t0]


def send(page, kind: str, **fields) -> None:
    page.evaluate(
        "(m) => window.__viserMutable.sendMessage(m)",
        {"type": kind, "name": "/gripper", "owner": "", **fields},
    )


def main() -> None:
    ap = argparse.ArgumentParser(description=(__doc__ or "").split("\n")[0])
    ap.add_argument("--scene", default="table")
    ap.add_argument("--seconds", type=float, default=5.0)
    ap.add_argument("--trials", type=int, default=20)
    ap.add_argument("--publish-hz", type=float, default=None, help="override the server's publish rate")
    args = ap.parse_args()
    exe = shutil.which("chromium") or "/usr/bin/chromium"
    if not Path(exe).exists():
        sys.exit("chromium not found: apt-get install -y chromium")
    from playwright.sync_api import sync_playwright

    kw = {} if args.publish_hz is None else {"publish_hz": args.publish_hz}
    srv = DemoServer(args.scene, port=None, recordings_dir="/tmp/dlovr-bench-recordings", **kw).start()
    log = FrameLog()
    # server-side marks: when the gizmo target arrives, and each publish with the gripper position
    srv_marks: list[tuple[str, float, np.ndarray]] = []
    orig_set_target, orig_publish = srv.set_target, srv.loop.publish

    def set_target(pos, quat=None, *, move_gizmo: bool = True) -> None:
        srv_marks.append(("target", time.perf_counter(), np.asarray(pos, dtype=float)))
        orig_set_target(pos, quat, move_gizmo=move_gizmo)

    def publish() -> None:
        orig_publish()
        srv_marks.append(("publish", time.perf_counter(), srv.session.record.gripper_pos.copy()))

    srv.set_target, srv.loop.publish = set_target, publish
    try:
        with sync_playwright() as pw:
            browser = pw.chromium.launch(executable_path=exe, args=ARGS)
            page = browser.new_page(viewport={"width": 960, "height": 600})

            def hook(ws) -> None:
                ws.on("framereceived", log.on_frame)
                ws.on("framesent", log.on_sent)

            page.on("websocket", hook)
            t_load = time.perf_counter()
            page.goto(srv.url)
            page.get_by_role("button", name="Start recording").wait_for(timeout=30_000)
            page.wait_for_function("() => window.__viserMutable !== undefined", timeout=30_000)
            page.wait_for_timeout(1000)
            first_cable = min((t for t, cable, _ in log.since(t_load) if cable), default=math.nan) - t_load
            p0 = np.asarray(srv.status()["gripper_pos"], dtype=float)

            # -- updates per second while dragging in a circle (20 gizmo updates/s) --
            send(page, "TransformControlsDragStartMessage")
            pubs0 = srv.publish_count
            t_start = time.perf_counter()
            k = 0
            while time.perf_counter() - t_start < args.seconds:
                a = 2 * math.pi * 0.5 * (time.perf_counter() - t_start)
                p = p0 + 0.05 * np.array([math.cos(a) - 1.0, math.sin(a), 0.0])
                send(page, "TransformControlsUpdateMessage", wxyz=[1.0, 0, 0, 0], position=p.tolist())
                k += 1
                page.wait_for_timeout(max(0.0, (t_start + k / 20.0 - time.perf_counter()) * 1000))
            t_end = time.perf_counter()
            send(page, "TransformControlsDragEndMessage")
            cable_frames = [f for f in log.since(t_start) if f[1] and f[0] <= t_end]
            rate = len(cable_frames) / (t_end - t_start)
            server_rate = (srv.publish_count - pubs0) / (t_end - t_start)
            rtf = srv.status()["rtf"]

            # -- latency: one 2 cm step of the gizmo, from rest --
            lat: dict[str, list[float]] = {"browser": [], "server": [], "python": []}
            pos = p0.copy()
            for i in range(args.trials):
                send(page, "TransformControlsDragStartMessage")
                send(page, "TransformControlsUpdateMessage", wxyz=[1.0, 0, 0, 0], position=pos.tolist())
                page.wait_for_timeout(400)  # let the gripper reach it and stop
                rest = np.asarray(srv.status()["gripper_pos"], dtype=float)
                pos = pos + np.array([0.02 if i % 2 == 0 else -0.02, 0.0, 0.0])
                srv_marks.clear()
                t0 = time.perf_counter()
                send(page, "TransformControlsUpdateMessage", wxyz=[1.0, 0, 0, 0], position=pos.tolist())
                hit = None
                while hit is None and time.perf_counter() - t0 < 2.0:
                    page.wait_for_timeout(2)
                    for t, cable, body in log.since(t0):
                        if cable and body is not None and np.linalg.norm(np.asarray(body) - rest) > 2e-4:
                            hit = t
                            break
                send(page, "TransformControlsDragEndMessage")
                if hit is None:
                    continue
                sent = [t for t, p in log.sent if t >= t0 and np.allclose(p, pos)]
                lat["python"].append(1000.0 * (hit - t0))
                if sent:
                    lat["browser"].append(1000.0 * (hit - sent[0]))
                got = [t for kind, t, p in srv_marks if kind == "target" and np.allclose(p, pos)]
                pubs = [
                    t for kind, t, p in srv_marks if kind == "publish" and np.linalg.norm(p - rest) > 2e-4
                ]
                if got and pubs:
                    lat["server"].append(1000.0 * (pubs[0] - got[0]))
            keys = key_latency(page, srv, log, args.trials)
            browser.close()
    finally:
        srv.stop()
    print(f"scene {args.scene}: headless chromium (software WebGL), publish rate {srv.publish_hz:.0f} Hz")
    print(
        f"cable updates reaching the browser while dragging: {rate:.1f} /s "
        f"(published by the server: {server_rate:.1f} /s), sim at {rtf:.2f}x real time"
    )
    labels = {
        "browser": "gizmo frame sent by the page -> cable frame received by the page",
        "server": "gizmo message handled by the server -> cable flushed",
        "python": "sendMessage called from Python -> cable frame seen in Python",
    }
    for key, label in labels.items():
        v = sorted(lat[key])
        if not v:
            print(f"latency ({label}): no cable update observed")
            continue
        p90 = v[min(len(v) - 1, int(0.9 * len(v)))]
        print(
            f"latency, {label}: median {statistics.median(v):.1f} ms, p90 {p90:.1f} ms "
            f"({len(v)}/{args.trials} trials)"
        )
    report("key down -> moved gripper frame received by the page", keys, args.trials)
    print(f"page load -> first frame with the cable: {1000.0 * first_cable:.0f} ms")
    print(
        "targets: >= 60 cable updates/s, <= 50 ms median gizmo-to-cable latency (the 'browser' line), "
        "<= 100 ms median key to motion"
    )


def report(label: str, values: list[float], trials: int) -> None:
    v = sorted(values)
    if not v:
        print(f"latency ({label}): no motion observed")
        return
    p90 = v[min(len(v) - 1, int(0.9 * len(v)))]
    med = statistics.median(v)
    print(f"latency, {label}: median {med:.1f} ms, p90 {p90:.1f} ms ({len(v)}/{trials} trials)")


def key_latency(page, srv: DemoServer, log: FrameLog, trials: int) -> list[float]:
    """Milliseconds from a jog key going down (L and J in turn) to the first frame with the gripper
    moved, the gripper at rest before each press."""
    page.evaluate("() => document.activeElement && document.activeElement.blur()")
    out = []
    for i in range(trials):
        page.wait_for_timeout(400)  # at rest
        rest = np.asarray(srv.status()["gripper_pos"], dtype=float)
        key = "l" if i % 2 == 0 else "j"
        t0 = time.perf_counter()
        page.keyboard.down(key)
        hit = None
        while hit is None and time.perf_counter() - t0 < 2.0:
            page.wait_for_timeout(2)
            for t, _, body in log.since(t0):
                if body is not None and np.linalg.norm(np.asarray(body) - rest) > 2e-4:
                    hit = t
                    break
        page.keyboard.up(key)
        if hit is not None:
            out.append(1000.0 * (hit - t0))
        end = time.perf_counter() + 3.0
        while not srv.keys.held.idle and time.perf_counter() < end:
            page.wait_for_timeout(20)
    return out


if __name__ == "__main__":
    main()
