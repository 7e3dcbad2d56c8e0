from dlovr.cli import main

main()
