"""``dlovr serve``: the browser teleoperation UI (registered on the main group by :mod:`dlovr.cli`)."""

from __future__ import annotations

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
    scene = load_scene_arg(scene_ref)
    warm_up()
    from dlovr.ui import serve

    try:
        serve(scene, host=host, port=port, recordings_dir=recordings_dir)
    except ValueError as e:
        raise UserError(f"{scene.path}: {e}") from None
    except OSError as e:
        raise UserError(f"cannot serve on {host}:{port}: {e.strerror or e}") from None
