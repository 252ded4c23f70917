"""One module per `pafp` subcommand, each with `register(subparsers)`."""
