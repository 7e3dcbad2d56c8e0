"""``dlovr serve``: the browser teleoperation UI (registered on the main group by :mod:`dlovr.cli`)."""

from __future__ import annotations

import errno
import socket

import click

from dlovr.cli.common import UserError, load_scene_arg, warm_up


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
    scene = load_scene_arg(scene_ref)
    warm_up()
    from dlovr.ui import serve

    try:
        serve(scene, host=host, port=port, recordings_dir=recordings_dir)
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
