"""Contact tracking on a thread of its own (dlovr.sim.behind)."""

from __future__ import annotations

import threading
import time
from types import SimpleNamespace

import pytest

from dlovr.scene import load_scene
from dlovr.script import parse_script
from dlovr.sim import Simulator
from dlovr.sim.behind import TrackingThread, tracking_behind

#: Down onto the table, along it and up again: a few contact changes in 1.6 s (800 steps).
SCRIPT = {"waypoints": [
    {"pos": [0.0, 0.0, 0.57], "duration": 0.6},
    {"pos": [0.05, 0.0, 0.57], "duration": 0.5},
    {"pos": [0.05, 0.0, 0.7], "duration": 0.5},
]}


def _payloads(tracker) -> list[dict]:
    return [s.payload() for s in tracker.changes]


def test_tracked_behind_gives_every_state_bit_for_bit_as_inline():
    scene, script = load_scene("table"), parse_script(SCRIPT)
    inline = Simulator(scene, track=True)
    list(inline.run(script))
    behind = Simulator(scene, track=True, pieces=inline.pieces)
    with tracking_behind(behind) as thread:
        records = list(behind.run(script))
        assert thread.tracker is behind.tracker
    assert all(r.state is None for r in records)  # the states are the tracker's, not the records'
    assert len(inline.tracker.changes) >= 3
    assert _payloads(behind.tracker) == _payloads(inline.tracker)
    assert behind.tracker.kept == inline.tracker.kept
    assert behind.tracker.current.payload() == inline.tracker.current.payload()
    assert behind.step().state is not None  # tracked inline again after the block


def test_tracking_behind_needs_a_tracker_and_is_not_nested():
    sim = Simulator(load_scene("table"))
    with pytest.raises(ValueError, match="track=True"):
        with tracking_behind(sim):
            pass
    sim = Simulator(load_scene("table"), track=True)
    with tracking_behind(sim):
        with pytest.raises(RuntimeError, match="already"):
            with tracking_behind(sim):
                pass


class _Failing:
    """A tracker that fails at its ``at``-th step (counted from 0), and counts the steps it got."""

    def __init__(self, at: int) -> None:
        self.at, self.seen = at, 0

    def _state(self, rec, *args) -> None:
        if self.seen == self.at:
            raise KeyError("the geometry has no piece 7 of object 'x'")
        self.seen += 1


class _Gated(_Failing):
    """A tracker whose steps wait for ``gate``."""

    def __init__(self) -> None:
        super().__init__(at=-1)
        self.gate = threading.Event()

    def _state(self, rec, *args) -> None:
        self.gate.wait(5)
        self.seen += 1


def _record(k: int) -> SimpleNamespace:
    return SimpleNamespace(step=k, time=0.002 * k, points=None, contact_arrays=SimpleNamespace(table=None))


def test_a_tracker_error_fails_a_later_push_and_close():
    thread = TrackingThread(_Failing(at=3), batch=2)
    with pytest.raises(KeyError, match="no piece 7"):
        for k in range(1000):
            thread.push(_record(k), ((), (), ()))
            time.sleep(0.001)  # let the thread get there
    with pytest.raises(KeyError, match="no piece 7"):
        thread.close()
    assert thread.tracker.seen == 3


def test_close_waits_for_every_step_and_stop_drops_the_rest():
    thread = TrackingThread(_Failing(at=-1), batch=4)
    for k in range(10):  # two batches and two steps not yet handed over
        thread.push(_record(k), ((), (), ()))
    thread.close()
    assert thread.tracker.seen == 10 and not thread._thread.is_alive()
    slow = _Gated()
    thread = TrackingThread(slow, batch=1)
    for k in range(5):
        thread.push(_record(k), ((), (), ()))
    threading.Timer(0.05, slow.gate.set).start()
    thread.stop()
    assert slow.seen < 5 and not thread._thread.is_alive()
    with pytest.raises(ValueError, match="batch"):
        TrackingThread(slow, batch=0)


def test_an_error_in_the_block_stops_the_thread_and_is_raised():
    sim = Simulator(load_scene("table"), track=True)
    with pytest.raises(ZeroDivisionError):
        with tracking_behind(sim) as thread:
            sim.step(10)
            raise ZeroDivisionError
    assert not thread._thread.is_alive() and sim.behind is None
    assert sim.step().state is not None
