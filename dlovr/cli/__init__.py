"""Command-line interface: ``dlovr …`` (click), one module a command or command group.

Each command validates its input and reports a problem as one line naming the file and the problem,
with exit code 2 and no traceback: every reader's :class:`dlovr.inputs.InputError` becomes the one
:class:`dlovr.cli.common.UserError` in :class:`dlovr.cli.common.Group` (exit codes:
:data:`dlovr.cli.common.EXIT_CODES`).
"""

from __future__ import annotations

import click  # SIGINT/SIGTERM were taken over before (dlovr/__init__.py: signals.defer())

from dlovr import __version__
from dlovr.cli.common import Group
from dlovr.cli.compile import compile_cmd
from dlovr.cli.export import export_cmd
from dlovr.cli.generate import generate_cmd
from dlovr.cli.network import network_cmd
from dlovr.cli.record import demo_cmd, record_cmd, recover_cmd, replay_cmd, states_cmd
from dlovr.cli.run import run_cmd
from dlovr.cli.scene import scene_group, scenes_cmd
from dlovr.cli.serve import serve_cmd
from dlovr.cli.transitions import transitions_cmd


@click.group(cls=Group, context_settings={"help_option_names": ["-h", "--help"]})
@click.version_option(__version__, prog_name="dlovr")
def main() -> None:
    """dlovr: demonstrate DLO (cable) manipulation, extract contact states, compile programs."""


for _command in (
    transitions_cmd,
    scenes_cmd,
    scene_group,
    compile_cmd,
    serve_cmd,
    demo_cmd,
    record_cmd,
    replay_cmd,
    states_cmd,
    recover_cmd,
    network_cmd,
    run_cmd,
    export_cmd,
    generate_cmd,
):
    main.add_command(_command)

__all__ = ["main"]
