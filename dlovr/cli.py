"""Command-line interface: ``dlovr …`` (click).

Each command validates its input and reports a problem as one line naming the file and the problem,
with exit code 2 and no traceback.
"""

from __future__ import annotations

import click

from dlovr import __version__


class UserError(click.ClickException):
    """A problem with the user's input: printed as one line, exit code 2."""

    exit_code = 2


@click.group(context_settings={"help_option_names": ["-h", "--help"]})
@click.version_option(__version__, prog_name="dlovr")
def main() -> None:
    """dlovr: demonstrate DLO (cable) manipulation, extract contact states, compile programs."""
