"""``dlovr scenes`` and ``dlovr scene show|export``: list, inspect and export scenes (registered on
the main group by :mod:`dlovr.cli`)."""

from __future__ import annotations

import click

from dlovr.cli.common import UserError, finishes_on_sigterm, load_scene_arg


@click.command("scenes", short_help="List the built-in scenes.")
def scenes_cmd() -> None:
    """List the built-in scenes (use them by name, e.g. ``dlovr scene show peg_in_hole``)."""
    from dlovr.scene import builtin_scenes

    rows = builtin_scenes()
    width = max((len(n) for n, _ in rows), default=4)
    for name, desc in rows:
        click.echo(f"{name:<{width}}  {desc}")


@click.group("scene", short_help="Inspect scenes: show one, export its MuJoCo model.")
def scene_group() -> None:
    """Inspect scenes: built-in ones by name, others by the path of their TOML file."""


@scene_group.command("show", short_help="Print a scene's objects, pieces, faces and edges.")
@click.argument("ref", metavar="NAME|PATH")
@click.option("--json", "as_json", is_flag=True, help="Print JSON instead of text.")
def scene_show_cmd(ref: str, as_json: bool) -> None:
    """Print a scene: cable, gripper, objects, convex pieces, named faces and the edge table."""
    import json

    from dlovr.scene import describe_scene, format_scene

    desc = describe_scene(load_scene_arg(ref))
    click.echo(json.dumps(desc, indent=2, ensure_ascii=False) if as_json else format_scene(desc))


@scene_group.command("export", short_help="Write a scene's compiled MuJoCo model (MJCF).")
@click.argument("ref", metavar="NAME|PATH")
@click.option(
    "-o", "--output", "out", required=True, type=click.Path(dir_okay=False), help="MJCF file to write."
)
@finishes_on_sigterm
def scene_export_cmd(ref: str, out: str) -> None:
    """Write the scene's compiled MuJoCo model (MJCF, meshes inline), loadable by plain MuJoCo."""
    from dlovr.outputs import atomic_output
    from dlovr.sim import Simulator, export_xml

    scene = load_scene_arg(ref)
    try:
        sim = Simulator(scene)
    except ValueError as e:
        raise UserError(f"{scene.path}: {e}") from None
    with atomic_output(out) as tmp:  # no partial file at ``out`` if writing fails
        export_xml(sim.built, tmp)
    click.echo(f"wrote {out}")
