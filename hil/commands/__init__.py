"""One module a `hil` subcommand; each defines ``add_parser(subparsers, parents)``."""
