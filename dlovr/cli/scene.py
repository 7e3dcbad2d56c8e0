"""``dlovr scenes`` and ``dlovr scene show|export``: list, inspect and export scenes (registered on
the main group by :mod:`dlovr.cli`)."""

from __future__ import annotations

from typing import Any

import click

from dlovr.cli.common import UserError, finishes_on_sigterm, load_scene_arg, refuse_existing
from dlovr.scene import Scene


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

    desc = describe_scene(load_scene_arg(ref))
    click.echo(json.dumps(desc, indent=2, ensure_ascii=False) if as_json else format_scene(desc))


@scene_group.command("export", short_help="Write a scene's compiled MuJoCo model (MJCF).")
@click.argument("ref", metavar="NAME|PATH")
@click.option(
    "-o", "--output", "out", required=True, type=click.Path(dir_okay=False), help="MJCF file to write."
)
@click.option("-f", "--force", is_flag=True, help="Overwrite the output file if it exists.")
@finishes_on_sigterm
def scene_export_cmd(ref: str, out: str, force: bool) -> None:
    """Write the scene's compiled MuJoCo model (MJCF, meshes inline), loadable by plain MuJoCo.

    An existing output file is refused unless --force."""
    from dlovr.outputs import atomic_output
    from dlovr.sim import Simulator, export_xml

    refuse_existing(out, force)
    scene = load_scene_arg(ref)
    try:
        sim = Simulator(scene)
    except ValueError as e:
        raise UserError(f"{scene.path}: {e}") from None
    with atomic_output(out, force=force) as tmp:  # no partial file at ``out`` if writing fails
        export_xml(sim.built, tmp)
    click.echo(f"wrote {out}")


def describe_scene(scene: Scene) -> dict:
    """JSON-able description of a scene and its geometry (objects, pieces, faces, edge table)."""
    from dataclasses import asdict

    from dlovr.geometry import SceneGeometry

    g = SceneGeometry.from_scene(scene).describe()["objects"]
    objs = []
    for o, go in zip(scene.objects, g, strict=True):
        d = {
            "name": o.name,
            "kind": o.kind,
            "pos": list(o.pos),
            "quat": list(o.quat),
            "size": list(o.size) if o.size is not None else None,
            "mesh": str(o.mesh_path) if o.mesh_path is not None else None,
        }
        d.update({k: v for k, v in go.items() if k != "name"})
        objs.append(d)
    return {
        "name": scene.name,
        "description": scene.description,
        "path": str(scene.path),
        "dlo": asdict(scene.dlo),
        "gripper": {"pos": list(scene.gripper.pos), "quat": list(scene.gripper.quat)},
        "model": asdict(scene.params),
        "objects": objs,
    }


def format_scene(desc: dict) -> str:
    """Human-readable text of :func:`describe_scene`'s output."""

    def v(x: Any) -> str:
        return "[" + ", ".join(f"{float(c):.4g}" for c in x) + "]"

    d = desc["dlo"]
    lines = [
        f"scene {desc['name']}: {desc['description']}",
        f"  file: {desc['path']}",
        f"  cable: length {d['length']:g} m, radius {d['radius']:g} m, {d['segments']} segments, "
        f"E {d['young']:g} Pa, mass {d['mass']:g} kg",
        f"  gripper: pos {v(desc['gripper']['pos'])}, quat {v(desc['gripper']['quat'])}",
        "  model: " + ", ".join(f"{k} {val:g}" for k, val in desc["model"].items()),
    ]
    for o in desc["objects"]:
        what = f"box {v(o['size'])}" if o["kind"] == "box" else f"mesh {o['mesh']}"
        kinds = sorted({p["kind"] for p in o["pieces"]})
        lines.append(
            f"object {o['name']}: {what} at {v(o['pos'])}, "
            f"{len(o['pieces'])} piece(s) ({', '.join(kinds)}), {len(o['faces'])} faces"
        )
        for f in o["faces"]:
            lines.append(f"  face {f['name']:<16} normal {v(f['normal'])}  area {f['area']:.4g} m^2")
        for p in o["pieces"]:
            fl = ", ".join(f"{x['face'] or '-'}:{x['kind']}" for x in p["faces"])
            lines.append(f"  piece {p['index']} ({p['kind']}, volume {p['volume']:.4g} m^3): {fl}")
        for e in o["edges"]:
            lines.append(
                f"  edge {e['faces'][0]} / {e['faces'][1]}: {e['kind']}, opening {e['opening_deg']:.4g} deg, "
                f"length {e['length']:.4g} m"
            )
    return "\n".join(lines)
