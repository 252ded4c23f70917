"""`pafp bench`: reproduce the report's bench-top tests (not implemented yet: issue 7)."""

from __future__ import annotations

import argparse

from host_tools.commands.unavailable import not_yet

HELP = "reproduce the report's bench-top tests [not implemented yet]"


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """Accept any arguments until the real command lands."""
    parser.add_argument("rest", nargs=argparse.REMAINDER, help=argparse.SUPPRESS)


def run(args: argparse.Namespace) -> int:
    """Refuse to run, naming the issue that will provide this command."""
    return not_yet("bench", "issue 7")
