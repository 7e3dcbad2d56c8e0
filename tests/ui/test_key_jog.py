"""A person's key-jog demonstration in the browser UI (issue: programs from people's demonstrations):
laying the cable on the table, dragging it and lifting it again with the jog keys compiles to a
program of at most four transitions (``E, C, C, E``), not a chatter of ``C`` macros.

The keys go through the UI's own key handling: each press is the two reports the page's key follower
sends for a tap (the key down, then none held: ``KeysPanel.report``, what the hidden "Jog keys held"
input's update runs), one step each, at 30 presses per second of simulated time (the key-jog style of
issue 33: a person tapping, or an operating system's key repeat). No browser: the server simulates in
this process."""

from __future__ import annotations

import time

from dlovr.ui import DemoServer

#: Key presses per second of simulated time (an operating system's key repeat).
REPEAT_HZ = 30.0


def press(server: DemoServer, key: str, times: int) -> None:
    """Tap ``key`` ``times`` times, one tap every 1/REPEAT_HZ s of simulated time: each tap is the
    page's report of the key held down, then of no key held."""
    for _ in range(times):
        t0 = server.status()["t"]
        server.keys.report(key)
        server.keys.report("")
        end = time.monotonic() + 20.0
        while server.status()["t"] < t0 + 1.0 / REPEAT_HZ and time.monotonic() < end:
            time.sleep(0.005)


def settle(server: DemoServer, seconds: float) -> None:
    t0 = server.status()["t"]
    end = time.monotonic() + 60.0
    while server.status()["t"] < t0 + seconds and time.monotonic() < end:
        time.sleep(0.02)


def test_laying_dragging_and_lifting_with_the_keys_is_four_transitions(server: DemoServer):
    keys = {k: k for k in "IJLOU"}
    settle(server, 0.3)
    server.start_recording()
    press(server, keys["O"], 20)  # down 10 cm: the tip touches the table
    for _ in range(50):  # down and toward -x together: the cable lies down behind the gripper
        press(server, keys["J"], 1)
        press(server, keys["O"], 2)
    settle(server, 0.3)
    press(server, keys["I"], 30)  # drag it 15 cm along the table
    settle(server, 0.3)
    press(server, keys["U"], 140)  # lift it off again (the cable is 60 cm long)
    settle(server, 0.8)
    server.stop_recording()
    prog = server.last_program
    assert prog is not None, server.program_text
    labels = [m.label for m in prog.classed]
    # measured: the raw situations have 8 classed transitions (E C C C E E C E: the shallow tip and
    # the last segments flip as the keys step), the program E C C E
    assert len(labels) <= 4, (labels, server.program_text)
    assert labels[0] == "E" and "C" in labels and labels[-1] == "E", labels  # down, laid, lifted off
