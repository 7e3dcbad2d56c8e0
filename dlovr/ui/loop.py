"""The real-time thread of ``dlovr serve`` (:class:`RealtimeLoop`): steps the simulation paced to the
wall clock, applies a new gripper target (:class:`TargetCommand`) at once, and publishes at
``publish_hz``. It is given its collaborators (the session, the pause flag, the publish and the
divergence callbacks); :class:`dlovr.ui.server.DemoServer` wires them.

What bounded the publish rate before: the simulation was stepped in chunks of 5 steps and
the publish time was only checked between chunks, so on a loaded machine (a step taking a few ms of
wall time) publishes came late and the schedule slipped; the schedule itself was 40 Hz. Now the
stepping stops at the next publish time (:meth:`dlovr.ui.session.Session.advance` takes a deadline),
the schedule is 60 Hz, and a new gizmo target re-phases it: the cable is published right after the
first step toward the target (at most ``MIN_GAP`` after the previous publish), then every period.
"""

from __future__ import annotations

import threading
import time
from collections.abc import Callable

import numpy as np

from dlovr.ui.session import Session

MIN_GAP = 1.0 / 120.0
"""Shortest time (s) between two publishes (a new target is shown early, but not sooner than this)."""

MAX_CHUNK = 25
"""Most steps taken under the lock in one go (GUI callbacks wait for it)."""

Pose = tuple[np.ndarray, np.ndarray]
"""A gripper pose: position (m, world) and quaternion (wxyz)."""


class TargetCommand:
    """The gripper target last commanded (the gizmo, a jog), handed to the real-time loop once.

    :meth:`set` also sets ``wake``, so that the loop, sleeping until its next step or publish,
    applies the new target at once.
    """

    def __init__(self) -> None:
        self.pose: Pose | None = None  # the last target commanded (None: none since the scene loaded)
        self.fresh = False  # set, and not yet taken by the loop
        self.wake = threading.Event()

    def set(self, pos: np.ndarray, quat: np.ndarray) -> None:
        self.pose = (pos, quat)
        self.fresh = True
        self.wake.set()

    def clear(self) -> None:
        """Forget the target (another scene: its gripper starts where the scene puts it)."""
        self.pose = None
        self.fresh = False

    def take(self) -> tuple[bool, Pose | None]:
        """(True, the target) if one was set since the last take, else (False, None)."""
        if not self.fresh:
            return False, None
        self.fresh = False
        return True, self.pose


class RealtimeLoop:
    """The real-time thread: :meth:`start`, then :meth:`stop` and :meth:`join`.

    ``session`` gives the current session (a scene load replaces it; its clock starts again),
    ``paused`` whether to step; ``publish`` draws one frame (called at ``publish_hz``, a new target
    shown early), ``diverged`` is called after a step that diverged (the session restored its state).
    :attr:`rtf` is the real-time factor measured over the last second or so.
    """

    def __init__(
        self,
        session: Callable[[], Session],
        target: TargetCommand,
        *,
        paused: Callable[[], bool],
        publish: Callable[[], None],
        diverged: Callable[[], None],
        publish_hz: float,
        verbose: bool = False,
        failed: Callable[[Exception], None] | None = None,
    ) -> None:
        self.session = session
        self.target = target
        self.paused = paused
        self.publish = publish
        self.diverged = diverged
        self.failed = failed
        self.publish_hz = publish_hz
        self.verbose = verbose
        self.rtf = 1.0
        self._stop = threading.Event()
        self._thread: threading.Thread | None = None

    @property
    def stopping(self) -> bool:
        """Whether :meth:`stop` was called (and the loop not started again)."""
        return self._stop.is_set()

    def start(self) -> None:
        self._stop.clear()
        self._thread = threading.Thread(target=self.run, name="dlovr-sim", daemon=True)
        self._thread.start()

    def stop(self) -> None:
        """Ask the thread to end (after the steps or the publish it is doing); see :meth:`join`."""
        self._stop.set()

    def join(self, timeout: float) -> None:
        if self._thread is not None:
            self._thread.join(timeout=timeout)
            self._thread = None

    def run(self) -> None:
        """Step and publish until :meth:`stop`."""
        self._period = 1.0 / self.publish_hz
        self._next_pub = self._last_pub = time.perf_counter()
        self._anchor_wall = time.perf_counter()  # wall time (s) at which ...
        self._anchor_steps = 0  # ... this many steps had been taken: the pacing's origin
        self._done = 0  # steps taken in the current session
        self._rtf_t, self._rtf_sim = time.perf_counter(), self.session().record.time
        self._session = self.session()
        self._kicked = False  # a new target was applied and has not been published yet
        while not self._stop.is_set():
            try:
                self._iterate()
            except Exception as e:  # the thread lives on: reported (the server pauses), then onwards
                if self.failed is None:
                    raise
                self.failed(e)
                self._stop.wait(0.05)

    def _iterate(self) -> None:
        """One turn of the loop: the steps due, a publish when due, a sleep until the next."""
        now = time.perf_counter()
        self._follow_session(now)
        pub_at = self._publish_at()
        if not self.paused():
            pub_at = self._step(now, pub_at)
        now = time.perf_counter()
        if now >= pub_at:
            self._publish(now)
        self._sleep()

    def _follow_session(self, now: float) -> None:
        """Restart the pacing on another session (and its clock) or while paused."""
        current = self.session()
        if self._session is not current or self.paused():
            if self._session is not current:  # another scene: its clock starts again
                self._rtf_t, self._rtf_sim = now, current.record.time
            self._session = current
            self._anchor_wall, self._anchor_steps, self._done = now, 0, 0

    def _publish_at(self) -> float:
        """When the next publish is due (early after a new target)."""
        return min(self._next_pub, self._last_pub + MIN_GAP) if self._kicked else self._next_pub

    def _step(self, now: float, pub_at: float) -> float:
        """Take the steps due by ``now`` (toward a new target if one came), stopping at ``pub_at``;
        the publish time, moved earlier by a new target.

        The pause flag is read again under the session's lock, which the server's ``pause`` takes
        too: once ``pause`` returned, no step is taken (a step waiting for the lock while a GUI
        callback held it could otherwise follow it)."""
        session = self._session
        with session.lock:
            if self.paused():
                return pub_at
            due = int((now - self._anchor_wall) / session.dt) - (self._done - self._anchor_steps)
            if due > 50:  # more than 0.1 s behind: give up catching up (slower than real time)
                self._anchor_wall, self._anchor_steps = now, self._done
                due = 50
            fresh, target = self.target.take()
            if fresh:
                due = max(due, 1)  # show a new target at once
                self._kicked = True
                pub_at = min(self._next_pub, self._last_pub + MIN_GAP)
            if due <= 0:
                return pub_at
            n = session.advance(min(due, MAX_CHUNK), target, deadline=pub_at)
        if n is None:  # called outside the lock: it pauses and holds the gripper
            self.diverged()
            n = 1
        self._done += n
        return pub_at

    def _publish(self, now: float) -> None:
        """Publish a frame (measuring the real-time factor once a second) and schedule the next."""
        session = self._session
        if now - self._rtf_t >= 1.0:
            self.rtf = (session.record.time - self._rtf_sim) / (now - self._rtf_t)
            self._rtf_t, self._rtf_sim = now, session.record.time
        try:
            self.publish()
        except Exception as e:  # keep the simulation alive whatever a publish does
            if self.verbose:
                print(f"dlovr serve: publish failed: {e!r}")
        if self._kicked or self._next_pub + self._period <= now:
            self._next_pub = now + self._period  # re-phase on a new target, or when more than a period late
        else:
            self._next_pub += self._period  # on schedule: no drift
        self._last_pub = now
        self._kicked = False

    def _sleep(self) -> None:
        """Wait for the next step or publish, or for a new target."""
        pub_at = self._publish_at()
        next_step = self._anchor_wall + (self._done - self._anchor_steps + 4) * self._session.dt
        wait = min(pub_at, next_step) - time.perf_counter()
        if wait > 0:
            self.target.wake.wait(wait)
            self.target.wake.clear()
