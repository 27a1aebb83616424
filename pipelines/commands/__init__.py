"""One module per CLI subcommand. Each defines ``register(subparsers)``; heavy imports happen inside ``run``
so that ``crowdmpc --help`` stays fast."""
