"""Command line for transition networks (paper §VI, §VII): ``dlovr network REC... -o NET.json
[--html NET.html]`` and ``dlovr compile --network NET.json -o PROGRAM.json`` (registered by
:mod:`dlovr.cli`). Bad input is one line on stderr with exit code 2, never a traceback."""

from __future__ import annotations

import io
import sys
from pathlib import Path

import click

from dlovr.batch import cluster_option
from dlovr.cli.common import UserError, refuse_existing
from dlovr.outputs import write_output  # atomic: a full disk leaves the previous file whole


@click.command("network", short_help="Merge recordings of one scene into a transition network.")
@click.argument("recordings", nargs=-1, required=True, type=click.Path())
@click.option(
    "-o", "--output", "out", required=True, type=click.Path(dir_okay=False), help="Network JSON to write."
)
@click.option(
    "--html", "html_out", type=click.Path(dir_okay=False), help="Also write a self-contained HTML view."
)
@click.option(
    "--workers",
    type=click.IntRange(1, 64),
    help="Read the recordings on this many worker processes (default: one after the other here).",
)
@click.option(
    "--keep-chatter",
    "chatter",
    flag_value="keep",
    help="Keep every recording's situations as they happened (default: each recording a hand made "
    "merged as its path to its goal, its chatter removed first as `compile` removes it).",
)
@click.option(
    "--without-chatter",
    "chatter",
    flag_value="all",
    help="Remove the chatter from every recording, a script's too.",
)
@click.option("-f", "--force", is_flag=True, help="Overwrite the output files if they exist.")
@cluster_option
def network_cmd(
    recordings: tuple[str, ...],
    out: str,
    html_out: str | None,
    workers: int | None,
    chatter: str | None,
    force: bool,
    cluster: str | None,
) -> None:
    """Merge recordings of one scene (files or directories of *.mcap) into a transition network:
    situations, transitions with class, count, probability, durations, gripper motions and risk.
    The chatter of each recording a hand made (a situation left and re-entered within a moment,
    docs/model.md section 6) is removed first, unless --keep-chatter; a script's recordings keep
    theirs (their flips are the scene's), unless --without-chatter.

    Existing output files are refused unless --force."""
    from dlovr.model.planning import NetworkProgram
    from dlovr.model.program import ChatterRules
    from dlovr.recording import find_recordings
    from dlovr.recording.demonstrations import network_from_recordings
    from dlovr.recording.network_html import network_html

    for path in (out, html_out):
        if path is not None:
            refuse_existing(path, force)
    paths = find_recordings(recordings, in_order=True)  # the first is the reference if it reached the goal
    if not paths:
        raise UserError(f"no recordings found in {', '.join(recordings)}")
    if cluster is not None:  # workers elsewhere: absolute paths (on storage every node sees)
        paths = [p.resolve() for p in paths]
    # a progress bar on a terminal only: elsewhere an error stays the one line on stderr
    stream = sys.stderr if sys.stderr.isatty() else io.StringIO()
    bar = click.progressbar(length=len(paths), label="reading recordings", file=stream, show_eta=True)
    with bar:
        done = [0]

        def progress(k: int) -> None:
            bar.update(k - done[0])
            done[0] = k

        rules = None if chatter == "keep" else ChatterRules()
        net = network_from_recordings(
            paths, progress=progress, workers=workers, cluster=cluster, chatter=rules,
            hands_only=chatter is None,
        )
    write_output(out, net.dumps(), force=force)
    if html_out:
        write_output(html_out, network_html(net, NetworkProgram(net)), force=force)
    risky = sum(e.risk == "risky" for e in net.edges)
    click.echo(
        f"wrote {out}: {len(net.nodes)} situations, {len(net.edges)} transitions ({risky} risky) "
        f"from {len(paths)} recordings of {net.scene_name}; start {net.start}, goal {net.goal}"
        + (f"; view {html_out}" if html_out else "")
    )


def compile_network(network_path: str, inputs: tuple[str, ...], out: str | None, force: bool = False) -> None:
    """``dlovr compile --network NET.json -o PROGRAM.json``: write the network program (an existing
    file only with ``force``)."""
    from dlovr.model.network import load_network
    from dlovr.model.planning import NetworkProgram

    if inputs:
        raise UserError("--network compiles a network file; give no recordings with it")
    if out is None:
        raise UserError("--network needs -o PROGRAM.json")
    refuse_existing(out, force)
    prog = NetworkProgram(load_network(network_path), name=Path(out).stem, source=Path(network_path).name)
    write_output(out, prog.dumps(), force=force)
    plan = prog.plan_from_start()
    reach = plan[0].reach_probability if plan else 0.0
    click.echo(
        f"wrote {out}: network program over {len(prog.network.nodes)} situations; from the start "
        f"{len(plan)} macros, {sum(c.macro.risk == 'risky' for c in plan)} risky, P(goal)={reach:.3f}"
    )
