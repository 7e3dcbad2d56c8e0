"""``dlovr generate``: a program run in perturbed scenes, its successful runs written as a dataset."""

from __future__ import annotations

from typing import Any

import click

from dlovr.batch import cluster_option
from dlovr.cli.common import UserError
from dlovr.cli.export import dataset_options, export_options

_VARY_HELP = "Perturb the scene per episode, as `dlovr run --trials` (repeatable): dlo.length=10%, ..."


def _int(name: str, raw: str, minimum: int) -> int:
    try:
        x = int(raw)
    except ValueError:
        raise UserError(f"{name}: {raw!r} is not an integer") from None
    if x < minimum:
        raise UserError(f"{name}: must be >= {minimum}, got {raw}")
    return x


@click.command("generate", short_help="Program runs in perturbed scenes -> a dataset.")
@click.argument("program_path", metavar="PROGRAM.json")
@click.option("--episodes", "episodes_raw", metavar="N", required=True, help="Runs (perturbed scenes).")
@click.option("--seed", "seed_raw", metavar="S", default="0", show_default=True, help="Seed of the draws.")
@click.option("--vary", "varies", multiple=True, metavar="KEY=SPEC", help=_VARY_HELP)
@click.option("--detect", metavar="force|oracle", default="force", show_default=True,
              help="End macros by force detection, or by the contact tracker (oracle).")
@click.option("--path", "path_mode", metavar="auto|demo|program", default="auto", show_default=True,
              help="Follow the demonstration's motion (demo) or the program's poses (program).")
@click.option("--workers", "workers_raw", metavar="K", default="1", show_default=True,
              help="Processes (with --cluster: tasks in flight, and a local instance's CPUs).")
@cluster_option
@dataset_options
def generate_cmd(program_path: str, out: str, cluster: str | None, **given: Any) -> None:
    """Run PROGRAM.json (compiled or network) in N scenes perturbed by --vary, exactly as the trials
    of `dlovr run PROGRAM.json --trials N --seed S --vary ...` (the same runs, the same successes),
    each recorded; re-simulate the runs that reached the goal and write them as one dataset (see
    `dlovr export` and docs/datasets.md). Prints how many were kept and why the others failed.
    --cluster runs the trials and their re-simulation on Ray (local: a Ray instance here; auto or
    HOST:PORT: a running cluster, -o on storage every node sees): the same dataset as locally.
    Exit code 0 (also when no run succeeded: then nothing is written), 2 bad input.
    """
    from dlovr.datasets import check_output
    from dlovr.datasets.generate import generate, trial_setup

    episodes = _int("--episodes", given.pop("episodes_raw"), 1)
    seed = _int("--seed", given.pop("seed_raw"), 0)
    workers = _int("--workers", given.pop("workers_raw"), 1)
    detect, path_mode, varies = given.pop("detect"), given.pop("path_mode"), given.pop("varies")
    for name, value, allowed in (("--detect", detect, ("force", "oracle")),
                                 ("--path", path_mode, ("auto", "demo", "program"))):
        if value not in allowed:
            raise UserError(f"{name}: {value!r} is not one of {', '.join(allowed)}")
    opts = export_options(**given)
    check_output(out, opts.fmt, opts.force)
    try:
        setup = trial_setup(program_path, varies, seed, detect=detect, path_mode=path_mode,
                            note=lambda line: click.echo(f"note: {line}", err=True))
    except ValueError as e:  # a scene or program problem the readers report as ValueError
        raise UserError(str(e)) from None
    res = generate(setup, episodes, out, opts, workers=workers, cluster=cluster, progress=True)
    failed = episodes - len(res.kept)
    click.echo(f"kept {len(res.kept)} of {episodes} runs (reached the goal), {failed} failed")
    for why, n in sorted(res.failures.items(), key=lambda kv: -kv[1]):
        click.echo(f"  {n} x {why}")
    click.echo(f"wrote {out} ({opts.fmt})" if res.kept else "no run reached the goal: nothing written")
