"""``dlovr export``: recordings as a learning dataset (LeRobot v3.0 or robomimic HDF5)."""

from __future__ import annotations

import math
import re
from collections.abc import Callable
from typing import Any

import click

from dlovr.cli.common import UserError

_FORMAT_HELP = "lerobot: a LeRobot v3.0 folder; robomimic: one HDF5 file (.hdf5)."
_CAMERAS_HELP = "Render these cameras into the dataset: scene, gripper (comma-separated; default none)."


def dataset_options(fn: Callable[..., Any]) -> Callable[..., Any]:
    """The options ``export`` and ``generate`` share: format, output, fps, cameras, size, force."""
    for option in reversed((
        click.option("--format", "fmt", metavar="lerobot|robomimic", default="lerobot", show_default=True,
                     help=_FORMAT_HELP),
        click.option("-o", "--output", "out", metavar="OUT", required=True, help="The dataset to write."),
        click.option("--fps", "fps_raw", metavar="F", default="30", show_default=True,
                     help="Frames per second (at most 500, the simulation's rate)."),
        click.option("--cameras", "cameras_raw", metavar="NAME,...", default="", help=_CAMERAS_HELP),
        click.option("--size", "size_raw", metavar="WxH", default="320x240", show_default=True,
                     help="Camera image size in pixels (even numbers)."),
        click.option("--force", is_flag=True, help="Replace an existing dataset at OUT."),
    )):
        fn = option(fn)
    return fn


def export_options(fmt: str, fps_raw: str, cameras_raw: str, size_raw: str, force: bool) -> Any:
    """The :class:`dlovr.datasets.ExportOptions` of the options as given, each checked (one line)."""
    from dlovr.datasets import FORMATS, ExportOptions
    from dlovr.datasets.cameras import CAMERAS, CameraError, check_size
    from dlovr.inputs import LIMITS

    if fmt not in FORMATS:
        raise UserError(f"--format: {fmt!r} is not one of {', '.join(FORMATS)}")
    try:
        fps = float(fps_raw)
    except ValueError:
        raise UserError(f"--fps: {fps_raw!r} is not a number") from None
    top = LIMITS["dataset_fps"]
    if not math.isfinite(fps) or not 0 < fps <= top:
        raise UserError(f"--fps: must be > 0 and at most {top:g}, got {fps_raw}")
    cameras = tuple(c.strip() for c in cameras_raw.split(",") if c.strip())
    for c in cameras:
        if c not in CAMERAS:
            raise UserError(f"--cameras: unknown camera {c!r}: one of {', '.join(CAMERAS)}")
    if len(set(cameras)) != len(cameras):
        raise UserError(f"--cameras: a camera named twice in {cameras_raw!r}")
    m = re.fullmatch(r"(\d{1,5})x(\d{1,5})", size_raw.strip())
    if m is None:
        raise UserError(f"--size: {size_raw!r} is not WIDTHxHEIGHT (e.g. 320x240)")
    size = (int(m[1]), int(m[2]))
    try:
        check_size(size)
    except CameraError as e:
        raise UserError(f"--size: {e}") from None
    return ExportOptions(fmt=fmt, fps=fps, cameras=cameras, size=size, force=force)


@click.command("export", short_help="Recordings -> a LeRobot or robomimic dataset.")
@click.argument("recordings", nargs=-1, required=True, metavar="RECORDING...")
@dataset_options
def export_cmd(recordings: tuple[str, ...], out: str, **given: Any) -> None:
    """Re-simulate each RECORDING (a file, or a folder of *.mcap) and write it as one episode of a
    dataset: per frame the gripper pose and wrench, the cable's points, the objects' poses, the
    commanded pose and its change, the contact labels (situation, principal contacts, stability,
    transition, macro) and the camera images; per episode the scene, success and where it came from.
    See docs/datasets.md. An existing OUT is replaced only with --force. Exit code 0, 2 bad input.
    """
    from dlovr.datasets import check_output, export
    from dlovr.recording.compile import find_recordings

    opts = export_options(**given)
    paths = find_recordings(recordings, in_order=True)
    if not paths:
        raise UserError(f"{', '.join(recordings)}: no recordings (*.mcap) found")
    for p in paths:
        if not p.is_file():
            raise UserError(f"{p}: no such recording")
    check_output(out, opts.fmt, opts.force)  # before the work
    episodes = export(paths, out, opts)
    frames = sum(ep.length for ep in episodes)
    click.echo(f"wrote {len(episodes)} episodes, {frames} frames at {opts.fps:g} fps to {out} ({opts.fmt})")
