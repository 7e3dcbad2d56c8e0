"""``python -m dlovr``: the command line. SIGINT and SIGTERM were taken over already, by
``dlovr/__init__.py`` (the package is imported first), before the command line's heavy imports."""

from dlovr.cli import main

main()
