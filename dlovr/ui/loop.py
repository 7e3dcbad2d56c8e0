"""The real-time thread of :class:`dlovr.ui.server.DemoServer`: steps the simulation paced to the wall
clock in small chunks, applies a new gripper target at once, and publishes at ``publish_hz`` (early,
within viser's ~60 frames/s, when a new target arrived)."""

from __future__ import annotations

import contextlib
import time
from typing import TYPE_CHECKING

if TYPE_CHECKING:
    from dlovr.ui.server import DemoServer


def realtime_loop(app: DemoServer) -> None:
    """Run until ``app._stop`` is set; a diverged step pauses the server and holds the gripper."""
    period = 1.0 / app.publish_hz
    min_period = 1.0 / 60.0  # viser coalesces to ~60 frames/s anyway
    next_pub = last_pub = time.perf_counter()
    anchor_wall = time.perf_counter()
    anchor_steps = 0
    done = 0
    rtf_t, rtf_sim = time.perf_counter(), app.session.record.time
    session = app.session
    kicked = False  # a new target was applied and has not been published yet
    while not app._stop.is_set():
        now = time.perf_counter()
        if session is not app.session or app._paused:
            session = app.session
            anchor_wall, anchor_steps, done = now, 0, 0
        dt = session.dt
        if not app._paused:
            due = int((now - anchor_wall) / dt) - (done - anchor_steps)
            if due > 50:  # more than 0.1 s behind: give up catching up (slower than real time)
                anchor_wall, anchor_steps = now, done
                due = 50
            target = None
            if app._target_dirty:
                app._target_dirty = False
                target = app._target
                due = max(due, 1)  # show a new target at once
            # small chunks: publishing and new targets are never held up by a long batch
            n = min(due, 5)
            if n > 0:
                if not session.advance(n, target):
                    app.pause(True)
                    with contextlib.suppress(Exception):
                        app.hold()
                done += n
                kicked = kicked or target is not None
        now = time.perf_counter()
        if now >= next_pub or (kicked and now - last_pub >= min_period):
            if now - rtf_t >= 1.0:
                app._rtf = (session.record.time - rtf_sim) / (now - rtf_t)
                rtf_t, rtf_sim = now, session.record.time
            try:
                app._publish()
            except Exception as e:  # keep the simulation alive whatever a publish does
                if app.verbose:
                    print(f"dlovr serve: publish failed: {e!r}")
            last_pub = now
            kicked = False
            if now >= next_pub:  # on schedule
                next_pub = next_pub + period if next_pub + period > now else now + period
            else:  # early, for a new target: keep the schedule
                next_pub = max(next_pub, now + min_period)
        next_step = anchor_wall + (done - anchor_steps + 4) * dt
        pub_at = min(next_pub, last_pub + min_period) if kicked else next_pub
        wait = min(pub_at, next_step) - time.perf_counter()
        if wait > 0:
            app._wake.wait(wait)
            app._wake.clear()
