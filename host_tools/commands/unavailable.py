"""Shared helper for subcommands whose issue has not landed yet: fail loudly, never pretend."""

from __future__ import annotations

import sys


def not_yet(command: str, issue: str) -> int:
    """Print why `command` cannot run yet and return a non-zero exit code."""
    print(f"pafp {command}: not implemented yet ({issue}); nothing was run.", file=sys.stderr)
    return 3
