"""The real-time thread of :class:`dlovr.ui.server.DemoServer`: steps the simulation paced to the wall
clock, applies a new gripper target at once, and publishes at ``publish_hz``.

What bounded the publish rate before: the simulation was stepped in chunks of 5 steps and
the publish time was only checked between chunks, so on a loaded machine (a step taking a few ms of
wall time) publishes came late and the schedule slipped; the schedule itself was 40 Hz. Now the
stepping stops at the next publish time (:meth:`dlovr.ui.session.Session.advance` takes a deadline),
the schedule is 60 Hz, and a new gizmo target re-phases it: the cable is published right after the
first step toward the target (at most ``MIN_GAP`` after the previous publish), then every period.
"""

from __future__ import annotations

import contextlib
import time
from typing import TYPE_CHECKING

if TYPE_CHECKING:
    from dlovr.ui.server import DemoServer

MIN_GAP = 1.0 / 120.0
"""Shortest time (s) between two publishes (a new target is shown early, but not sooner than this)."""

MAX_CHUNK = 25
"""Most steps taken under the lock in one go (GUI callbacks wait for it)."""


def realtime_loop(app: DemoServer) -> None:
    """Run until ``app._stop`` is set; a diverged step pauses the server and holds the gripper."""
    period = 1.0 / app.publish_hz
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
            if session is not app.session:  # another scene: its clock starts again
                rtf_t, rtf_sim = now, app.session.record.time
            session = app.session
            anchor_wall, anchor_steps, done = now, 0, 0
        dt = session.dt
        pub_at = min(next_pub, last_pub + MIN_GAP) if kicked else next_pub
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
                kicked = True
                pub_at = min(next_pub, last_pub + MIN_GAP)
            if due > 0:
                n = session.advance(min(due, MAX_CHUNK), target, deadline=pub_at)
                if n is None:
                    app.pause(True)
                    with contextlib.suppress(Exception):
                        app.hold()
                    n = 1
                done += n
        now = time.perf_counter()
        if now >= pub_at:
            if now - rtf_t >= 1.0:
                app._rtf = (session.record.time - rtf_sim) / (now - rtf_t)
                rtf_t, rtf_sim = now, session.record.time
            try:
                app._publish()
            except Exception as e:  # keep the simulation alive whatever a publish does
                if app.verbose:
                    print(f"dlovr serve: publish failed: {e!r}")
            if kicked or next_pub + period <= now:
                next_pub = now + period  # re-phase on a new target, or when more than a period late
            else:
                next_pub += period  # on schedule: no drift
            last_pub = now
            kicked = False
        pub_at = min(next_pub, last_pub + MIN_GAP) if kicked else next_pub
        next_step = anchor_wall + (done - anchor_steps + 4) * dt
        wait = min(pub_at, next_step) - time.perf_counter()
        if wait > 0:
            app._wake.wait(wait)
            app._wake.clear()
