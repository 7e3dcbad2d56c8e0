"""Every message from a browser tab is untrusted input: a websocket client sending hostile messages
(a NaN or inf gizmo position, a zero quaternion, text for numbers, a position far away, NaN in a GUI
update) does not stop the simulation for every tab; each is refused and reported (stderr and a
notification on the page), and the next valid message still moves the gripper."""

from __future__ import annotations

import math
import time
from collections.abc import Iterator
from pathlib import Path
from typing import Any, cast

import msgspec
import numpy as np
import pytest
import viser
from websockets.sync.client import connect
from websockets.typing import Subprotocol

from dlovr.ui import DemoServer
from dlovr.ui.guard import checked_pose, message_problem
from dlovr.ui.loop import RealtimeLoop

#: viser's websocket subprotocol: what its own page asks for.
PROTOCOLS = [Subprotocol(f"viser-v{viser.__version__}")]

NAN, INF = float("nan"), float("inf")


def gizmo(position, wxyz=(1.0, 0.0, 0.0, 0.0)) -> dict:
    return {"type": "TransformControlsUpdateMessage", "name": "/gripper", "wxyz": list(wxyz),
            "position": list(position), "owner": ""}


HOSTILE = [
    gizmo([NAN, 0.0, 0.6]),  # the message of issue 31
    gizmo([0.0, 0.0, 0.6], [0.0, 0.0, 0.0, 0.0]),  # a zero quaternion
    gizmo([INF, 0.0, 0.6]),
    gizmo([0.0, 0.0, 1e308]),
    gizmo([0.0, 0.6]),
    gizmo([0.0, 0.0, 0.6], [NAN, 0.0, 0.0, 1.0]),
]


def wait_for(pred, timeout: float = 20.0) -> bool:
    end = time.monotonic() + timeout
    while time.monotonic() < end:
        if pred():
            return True
        time.sleep(0.05)
    return pred()


@pytest.fixture(scope="module")
def hostile_server(tmp_path_factory) -> Iterator[DemoServer]:
    srv = DemoServer("table", port=None, recordings_dir=tmp_path_factory.mktemp("recs")).start()
    try:
        yield srv
    finally:
        srv.stop()


@pytest.mark.slow
def test_hostile_messages_are_refused_and_the_simulation_goes_on(hostile_server: DemoServer):
    srv = hostile_server
    assert wait_for(lambda: srv.status()["t"] > 0.1)
    with connect(f"ws://127.0.0.1:{srv.port}", subprotocols=PROTOCOLS) as ws:
        for msg in HOSTILE:
            ws.send(msgspec.msgpack.encode(msg))
        time.sleep(0.5)
        t = srv.status()["t"]
        assert wait_for(lambda: srv.status()["t"] > t + 0.2), "the simulation stopped"
        assert not srv.paused
        pos, quat = srv.target()
        assert np.isfinite(pos).all() and abs(np.linalg.norm(quat) - 1) < 1e-9
        assert srv.reporter.lines, "nothing was reported"
        assert all(line.count("\n") == 0 for line in srv.reporter.lines)
        ws.send(msgspec.msgpack.encode(gizmo([0.05, 0.02, 0.6])))  # a valid one still moves it
        assert wait_for(lambda: np.allclose(srv.target()[0], [0.05, 0.02, 0.6]))
    # a message viser cannot even decode closes that tab's connection (only that one)
    with connect(f"ws://127.0.0.1:{srv.port}", subprotocols=PROTOCOLS) as ws:
        ws.send(msgspec.msgpack.encode(gizmo(["a", 0.0, 0.6])))
        time.sleep(0.3)
    with connect(f"ws://127.0.0.1:{srv.port}", subprotocols=PROTOCOLS) as ws:
        ws.send(msgspec.msgpack.encode({"type": "NoSuchMessage", "x": 1}))
        time.sleep(0.3)
    t = srv.status()["t"]
    assert wait_for(lambda: srv.status()["t"] > t + 0.2), "the simulation stopped"
    with connect(f"ws://127.0.0.1:{srv.port}", subprotocols=PROTOCOLS) as ws:
        ws.send(msgspec.msgpack.encode(gizmo([0.04, 0.0, 0.6])))
        assert wait_for(lambda: np.allclose(srv.target()[0], [0.04, 0.0, 0.6]))


def test_a_failing_step_is_reported_and_the_loop_lives_on():
    """The simulation thread survives an error in a step: reported (the server then pauses)."""
    failures: list[Exception] = []

    class Broken:
        lock = __import__("threading").RLock()
        dt = 0.002

        class record:  # what the loop reads of a session
            time = 0.0

        def advance(self, *a, **k):
            raise FloatingPointError("boom")

    session = cast(Any, Broken())  # a stand-in for a Session
    loop = RealtimeLoop(lambda: session, __import__("dlovr.ui.loop", fromlist=["x"]).TargetCommand(),
                        paused=lambda: False, publish=lambda: None, diverged=lambda: None,
                        publish_hz=60.0, failed=failures.append)
    loop.start()
    try:
        assert wait_for(lambda: len(failures) >= 2, timeout=5.0)
        assert loop._thread is not None and loop._thread.is_alive()
    finally:
        loop.stop()
        loop.join(5.0)
    assert isinstance(failures[0], FloatingPointError)


@pytest.mark.parametrize(
    ("pos", "quat"),
    [([NAN, 0, 0.6], [1, 0, 0, 0]), ([0, 0, 0.6], [0, 0, 0, 0]), ([0, 0], [1, 0, 0, 0]),
     (["x", 0, 0], [1, 0, 0, 0]), ([0, 0, 1e308], [1, 0, 0, 0]), ([0, 0, 0.6], [1, 0, INF, 0])],
)
def test_a_pose_that_is_not_one_is_refused_in_one_line(pos, quat):
    with pytest.raises(ValueError, match=r"^gripper target: [^\n]*$"):
        checked_pose(pos, quat)


def test_a_pose_is_normalised():
    p, q = checked_pose([0.0, 0.0, 0.6], [2.0, 0.0, 0.0, 0.0])
    assert q.tolist() == [1.0, 0.0, 0.0, 0.0] and p.tolist() == [0.0, 0.0, 0.6]


def test_message_problem_finds_non_finite_numbers_anywhere():
    from viser import _messages as m

    def update(position, wxyz=(1.0, 0.0, 0.0, 0.0)):
        return m.TransformControlsUpdateMessage(name="/gripper", wxyz=wxyz, position=position)

    assert message_problem(update((0.0, 0.0, 0.6))) is None
    assert "position must be 3 finite numbers" in (message_problem(update((0, math.nan, 0))) or "")
    assert "orientation must be a quaternion" in (message_problem(update((0, 0, 0), (0, 0, 0, 0))) or "")
    assert "not a finite number" in (message_problem({"updates": {"value": [1.0, {"x": math.inf}]}}) or "")


def test_unwritable_recordings_folder_is_said_on_the_page(tmp_path: Path):
    """Item 9: *Start recording* with a folder that cannot be written says why (not only a traceback on
    the server's stderr)."""
    blocker = tmp_path / "file"
    blocker.write_text("")
    srv = DemoServer("table", port=None, recordings_dir=blocker / "recs")  # not started: no GUI
    srv.recording_panel.start_safely()
    assert srv.session.recorder is None
    assert srv.reporter.lines and "recs" in srv.reporter.lines[-1] and "cannot" in srv.reporter.lines[-1]
