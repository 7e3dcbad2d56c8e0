from dlovr import signals

signals.defer()  # a signal while the command line is imported ends the command once it is ready

from dlovr.cli import main  # noqa: E402

main()
