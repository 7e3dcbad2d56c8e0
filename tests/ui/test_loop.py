"""The real-time loop of ``dlovr serve`` as a unit (no viser, no simulator): it is given its session,
its target and its callbacks, steps paced to the wall clock, hands a new target over once and survives
a publish that fails."""

from __future__ import annotations

import threading
import time
from collections.abc import Callable
from types import SimpleNamespace
from typing import Any

import numpy as np

from dlovr.ui.loop import RealtimeLoop, TargetCommand


class FakeSession:
    """What the loop uses of a :class:`dlovr.ui.session.Session`: ``dt``, ``record.time``, ``advance``."""

    dt = 0.002

    def __init__(self, diverge: bool = False) -> None:
        self.lock = threading.RLock()
        self.record = SimpleNamespace(time=0.0)
        self.steps = 0
        self.targets: list[Any] = []
        self.diverge = diverge

    def advance(self, n: int, target: Any, deadline: float | None = None) -> int | None:
        if target is not None:
            self.targets.append(target)
        if self.diverge:
            return None
        self.steps += n
        self.record.time += n * self.dt
        return n


def wait_for(cond: Callable[[], bool], timeout: float = 10.0) -> bool:
    end = time.perf_counter() + timeout
    while time.perf_counter() < end:
        if cond():
            return True
        time.sleep(0.01)
    return cond()


def make_loop(session: Any, target: TargetCommand, **kw: Any) -> tuple[RealtimeLoop, dict[str, int]]:
    counts = {"publish": 0, "diverged": 0}

    def publish() -> None:
        counts["publish"] += 1

    def diverged() -> None:
        counts["diverged"] += 1

    args: dict[str, Any] = dict(paused=lambda: False, publish=publish, diverged=diverged, publish_hz=60.0)
    args.update(kw)
    return RealtimeLoop(lambda: session, target, **args), counts


def test_the_loop_steps_publishes_and_takes_a_new_target_once():
    session, target = FakeSession(), TargetCommand()
    loop, counts = make_loop(session, target)
    loop.start()
    try:
        assert wait_for(lambda: session.steps >= 50 and counts["publish"] >= 3)
        pose = (np.array([0.1, 0.2, 0.3]), np.array([1.0, 0.0, 0.0, 0.0]))
        target.set(*pose)
        assert wait_for(lambda: len(session.targets) == 1)
        (p, q), kept = session.targets[0], target.pose
        assert p is pose[0] and q is pose[1] and not target.fresh and kept is not None and kept[0] is p
        time.sleep(0.05)
        assert len(session.targets) == 1  # handed over once
    finally:
        loop.stop()
        loop.join(timeout=5)
    assert loop.stopping and counts["diverged"] == 0
    n = session.steps
    time.sleep(0.05)
    assert session.steps == n  # the thread ended


def test_paused_takes_no_step_and_a_divergence_calls_back():
    paused = threading.Event()
    paused.set()
    session, target = FakeSession(diverge=True), TargetCommand()
    loop, counts = make_loop(session, target, paused=paused.is_set)
    loop.start()
    try:
        assert wait_for(lambda: counts["publish"] >= 3)
        assert session.steps == 0 and counts["diverged"] == 0
        paused.clear()
        assert wait_for(lambda: counts["diverged"] >= 1)
    finally:
        loop.stop()
        loop.join(timeout=5)


def test_a_failing_publish_keeps_the_loop_alive_and_another_session_is_followed():
    first, second, target = FakeSession(), FakeSession(), TargetCommand()
    current: list[Any] = [first]  # a FakeSession stands in for dlovr.ui.session.Session
    calls = [0]

    def publish() -> None:
        calls[0] += 1
        raise RuntimeError("a browser went away")

    loop = RealtimeLoop(
        lambda: current[0],
        target,
        paused=lambda: False,
        publish=publish,
        diverged=lambda: None,
        publish_hz=60.0,
    )
    loop.start()
    try:
        assert wait_for(lambda: calls[0] >= 3 and first.steps > 0)
        current[0] = second
        assert wait_for(lambda: second.steps >= 20)
        n = first.steps
        time.sleep(0.05)
        assert first.steps == n
    finally:
        loop.stop()
        loop.join(timeout=5)


def test_a_cleared_target_is_not_handed_over():
    target = TargetCommand()
    assert target.take() == (False, None)
    target.set(np.zeros(3), np.array([1.0, 0, 0, 0]))
    assert target.wake.is_set()
    target.clear()
    assert target.take() == (False, None) and target.pose is None


def test_a_jog_report_with_a_time_that_is_not_finite_moves_no_nan():
    """The page's key report is untrusted input: a NaN or infinite time stamp is ignored, so a release
    corrects nothing by it (no NaN motion reaches the gripper)."""
    from dlovr.ui.jog import HeldKeys

    held = HeldKeys()
    held.report("J#0@nan", 1.0)
    _, fix = held.report("#1@inf", 2.0)
    assert all(v == v and abs(v) != float("inf") for v in fix.values())
    held.report("J#2@1000", 3.0)
    _, fix = held.report("#3@nan", 4.0)
    assert fix == {}
