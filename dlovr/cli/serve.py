"""``dlovr serve``: the browser teleoperation UI (registered on the main group by :mod:`dlovr.cli`).

The page is up, and its URL printed, before anything slow: the kernels compile (a fresh install) and
the scene loads while the page says so (:mod:`dlovr.ui.starting`)."""

from __future__ import annotations

import errno
import socket
import sys
from typing import TYPE_CHECKING

import click

from dlovr import signals
from dlovr.cli.common import UserError, freeze_setup

if TYPE_CHECKING:
    from dlovr.ui.starting import StartingServer


@click.command("serve", short_help="Serve the browser teleoperation UI.")
@click.option("--scene", "scene_ref", default="table", show_default=True, help="Built-in scene name or path.")
@click.option("--host", default="127.0.0.1", show_default=True, help="Address to listen on.")
@click.option(
    "--port",
    type=click.IntRange(1, 65535),
    default=8080,
    show_default=True,
    help="Port (the next free one if taken).",
)
@click.option(
    "--recordings",
    "recordings_dir",
    default="recordings",
    show_default=True,
    type=click.Path(file_okay=False),
    help="Directory for recordings made in the browser.",
)
def serve_cmd(scene_ref: str, host: str, port: int, recordings_dir: str) -> None:
    """Serve the browser teleoperation UI (viser) with the simulation running in real time."""
    check_address(host, port)
    from dlovr.ui.starting import StartingServer

    try:
        early = StartingServer(host, port)
    except OSError as e:
        raise UserError(f"cannot serve on {host}:{port}: {e.strerror or e}") from None
    try:
        _serve(early, scene_ref, host, recordings_dir)
    except BaseException:
        early.stop()  # a bad scene or the like: no server left behind (stopping twice is harmless)
        raise


def _serve(early: StartingServer, scene_ref: str, host: str, recordings_dir: str) -> None:
    """Warn (off loopback), print the URL, then check the scene and compile the kernels while the page
    says so, and serve."""
    from dlovr.cli.common import load_scene_arg
    from dlovr.ui.starting import exposure_warning

    port = early.server.get_port()
    warning = exposure_warning(host, port)
    if warning is not None:
        print(warning, file=sys.stderr, flush=True)
    url = f"http://{'127.0.0.1' if host in ('0.0.0.0', '::', '') else host}:{port}"
    print(f"dlovr serve: starting at {url} (the page says what it waits for)", flush=True)
    early.say("checking the scene")
    scene = load_scene_arg(scene_ref)
    from dlovr.sim.warmup import warm_up

    def notice(text: str) -> None:
        click.echo(text, err=True)
        early.say(f"{text}: about 30-40 s after a fresh install")

    warm_up(notice)
    signals.check()  # SIGINT/SIGTERM while the kernels compiled is only noted (dlovr.signals): end now
    from dlovr.ui import serve

    freeze_setup()
    try:
        serve(scene, host=host, port=port, recordings_dir=recordings_dir, early=early)
    except ValueError as e:
        raise UserError(f"{scene.path}: {e}") from None
    except OSError as e:
        raise UserError(f"cannot serve on {host}:{port}: {e.strerror or e}") from None


def check_address(host: str, port: int) -> None:
    """That the server can listen on ``host``: a name that does not resolve, or an address that is not
    this machine's (``192.0.2.1``), is one line, exit 2 (viser would wait silently). A taken port is
    fine: the server takes the next free one."""
    try:
        infos = socket.getaddrinfo(host or None, port, type=socket.SOCK_STREAM, flags=socket.AI_PASSIVE)
    except (OSError, UnicodeError) as e:
        why = getattr(e, "strerror", None) or str(e)
        raise UserError(f"--host {host}: not an address of this machine: {why}") from None
    for family, kind, proto, _, addr in infos[:1]:
        with socket.socket(family, kind, proto) as s:
            try:
                s.bind(addr)
            except OSError as e:
                if e.errno != errno.EADDRINUSE:
                    why = e.strerror or str(e)
                    raise UserError(f"--host {host}: cannot serve on {host}:{port}: {why}") from None
