"""One module a `hil bench` target; each defines ``add_parser(subparsers, parents)``."""
