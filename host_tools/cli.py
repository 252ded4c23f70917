"""The `pafp` command line: one subcommand per module of host_tools.commands (or of a package's entry point), each
run under the contract of host_tools/contract.py (inputs protected, one exit-code table, no traceback)."""

from __future__ import annotations

import argparse
import logging
import sys
from typing import NoReturn

from hal.registry import Registry
from host_tools.build_info import ROOT, describe, stale_sources, version

COMMANDS = Registry("command", {
    "run": "host_tools.commands.run",
    "bench": "host_tools.commands.bench",
    "emulate": "host_tools.commands.emulate",
    "monitor": "host_tools.commands.monitor",
    "decode": "host_tools.commands.decode",
    "rta": "host_tools.commands.rta",
    "tune": "host_tools.commands.tune",
    "sweep": "host_tools.commands.sweep",
    "replay": "host_tools.commands.replay",
    "fit": "host_tools.commands.fit",
    "faults": "host_tools.commands.faults",
    "design": "host_tools.commands.design",
}, group="pafp.commands")
"""Subcommand name -> its module, which defines HELP, add_arguments(parser) and run(args) -> int."""


class _Parser(argparse.ArgumentParser):
    """An argument parser whose errors are one line (the option, the value, the range), not the usage first."""

    def error(self, message: str) -> NoReturn:
        """Print `prog: message (prog --help: the options)` and exit 2."""
        self.exit(2, f"{self.prog}: {message} (`{self.prog} --help` lists the options)\n")


def build_parser(only: str | None = None) -> argparse.ArgumentParser:
    """Build the argument parser with every subcommand registered (or only the subcommand `only`).

    Registering a subcommand imports its module: `pafp run` need not import what `pafp bench` does.
    """
    parser = _Parser(
        prog="pafp",
        description="Emulator of the firmware of a powered ankle-foot prosthesis.",
    )
    parser.add_argument("-v", "--verbose", action="store_true", help="log debug messages to stderr")
    parser.add_argument("--version", action="version", version=f"pafp {version()} ({describe()})")
    sub = parser.add_subparsers(dest="command", metavar="COMMAND")
    for name in COMMANDS:
        if only is not None and name != only:
            continue
        module = COMMANDS.load(name)
        p = sub.add_parser(name, help=module.HELP, description=module.HELP)
        module.add_arguments(p)
        p.set_defaults(_run=module.run)
    return parser


def main(argv: list[str] | None = None) -> int:
    """Entry point of the `pafp` console script; returns the exit code."""
    words = sys.argv[1:] if argv is None else argv
    command = next((w for w in words if not w.startswith("-")), None)  # the options before it take no value
    parser = build_parser(command if command in COMMANDS else None)
    args = parser.parse_args(argv)
    logging.basicConfig(
        level=logging.DEBUG if args.verbose else logging.WARNING,
        format="%(levelname)s %(name)s: %(message)s",
    )
    if not getattr(args, "_run", None):
        parser.print_help()
        return 2
    stale = stale_sources()
    if stale:  # Python imports the extension, not the edited source
        print(f"pafp: warning: {len(stale)} compiled modules are older than their source (e.g. "
              f"{stale[0].relative_to(ROOT)}): run `make install` to rebuild", file=sys.stderr)
    from host_tools.contract import run_command  # every command under the one contract (docs/commands.md)

    return run_command(args.command, args._run, args)


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
