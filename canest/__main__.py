from canest.cli import main

main()
