"""The contract every `pafp` command runs under, enforced here once (host_tools/cli.py calls :func:`run_command`
around every command, so none can bypass it; docs/commands.md, "The contract"):

- every input path a command is given is resolved before its work, and an output (``--out``, ``--capture``,
  ``--csv``) that is an input, holds one or lies inside an input file is refused in one line (exit 2);
- an existing ``--out`` is replaced only when it is provably a previous output of pafp (host_tools/outdir.py);
- every exit is one of :data:`EXIT_CODES`, and an exception of any type that a command let through becomes one
  line on stderr, never a traceback (``pafp -v`` logs it).

>>> exit_line("replay", ValueError("record r.bin: header damaged"))
('pafp replay: record r.bin: header damaged', 2)
>>> exit_line("fit", OSError(28, "No space left on device", "out/fit.json"))
('pafp fit: out/fit.json: No space left on device (exit 74)', 74)
>>> exit_line("run", KeyError("firmware"))[1]
3
>>> shell_command("pafp", "faults", "my specs/a.toml", "--point", 3)
"pafp faults 'my specs/a.toml' --point 3"
"""

from __future__ import annotations

import argparse
import logging
import os
import shlex
import sys
from collections.abc import Callable
from pathlib import Path

from host_tools.outdir import EXIT_WRITE_FAILED, protect_inputs

__all__ = ["EXIT_CODES", "EXIT_FAILED", "EXIT_INPUT", "EXIT_INTERNAL", "EXIT_INTERRUPTED", "EXIT_OK",
           "EXIT_WRITE_FAILED", "OUTPUT_OPTIONS", "exit_line", "input_paths", "run_command", "shell_command"]

EXIT_OK = 0
EXIT_FAILED = 1
"""The command ran and its verdict is negative: a replay diverged, a criterion or deadline failed, a fault latched."""
EXIT_INPUT = 2
"""Bad input (a file, a value, an option, an --out): refused in one line before the work."""
EXIT_INTERNAL = 3
"""A bug of pafp: an exception no check foresaw (one line; `pafp -v` logs the traceback)."""
EXIT_INTERRUPTED = 130
"""Interrupted by Ctrl-C (KeyboardInterrupt) outside a command's own signal handling (128 + SIGINT)."""
EXIT_CODES = {EXIT_OK: "ok", EXIT_FAILED: "ran, verdict failed (diverged, criterion not met, fault latched)",
              EXIT_INPUT: "bad input, refused before the work", EXIT_INTERNAL: "internal error (a bug of pafp)",
              EXIT_WRITE_FAILED: "an output could not be written (I/O error) once the work had begun"}
"""The exit codes every command shares (plus 128 + N after signal N, which ends a long command early)."""

OUTPUT_OPTIONS = ("out", "capture", "csv")
"""The options (argparse destinations) that name what a command writes; every other path it is given is an input."""

logger = logging.getLogger(__name__)


def _candidates(value: object) -> list[str | Path]:
    if isinstance(value, (list, tuple)):
        return [v for item in value for v in _candidates(item)]
    if isinstance(value, Path):
        return [value]
    if isinstance(value, str) and value and value != "-" and "://" not in value:
        file_part, _, _ = value.rpartition(":") if value.count(":") == 1 and ".py:" in value else (value, "", "")
        return [file_part]
    return []


def input_paths(args: argparse.Namespace) -> list[Path]:
    """The existing files and directories named by ``args`` outside :data:`OUTPUT_OPTIONS` (a Path option, or a text
    one that names an existing path: ``--battery FILE``, ``--controller FILE.py:CLASS``), resolved."""
    found: list[Path] = []
    for name, value in vars(args).items():
        if name.startswith("_") or name in OUTPUT_OPTIONS or name == "command":
            continue
        for c in _candidates(value):
            try:
                if os.path.exists(c):
                    found.append(Path(c).resolve())
            except (OSError, ValueError):  # a name too long, a NUL byte: not a path of ours
                continue
    return found


def _outputs(args: argparse.Namespace) -> list[tuple[str, Path]]:
    out = []
    for name in OUTPUT_OPTIONS:
        value = getattr(args, name, None)
        if isinstance(value, (str, Path)) and str(value) not in ("", "-"):
            out.append((f"--{name}", Path(value)))
    return out


def exit_line(command: str, e: BaseException) -> tuple[str, int]:
    """(the one line, the exit code) for an exception a command let through: ValueError (a bad input, its message
    names it) 2, OSError 74, KeyboardInterrupt 130, anything else an internal error 3."""
    text = " ".join(str(e).split()) or type(e).__name__
    if isinstance(e, KeyboardInterrupt):
        return f"pafp {command}: interrupted", EXIT_INTERRUPTED
    if isinstance(e, OSError):
        where = f"{e.filename}: " if e.filename else ""
        return f"pafp {command}: {where}{e.strerror or text} (exit {EXIT_WRITE_FAILED})", EXIT_WRITE_FAILED
    if isinstance(e, ValueError):
        return f"pafp {command}: {text}", EXIT_INPUT
    return (f"pafp {command}: internal error: {type(e).__name__}: {text} (a bug of pafp: please report it with the "
            "command; `pafp -v` prints the traceback)"), EXIT_INTERNAL


def run_command(command: str, body: Callable[[argparse.Namespace], int | None], args: argparse.Namespace) -> int:
    """Run one command's ``body`` under the contract: its inputs resolved and protected, its outputs checked against
    them (exit 2 before the work), and whatever it raises turned into one line and an exit code."""
    try:
        inputs = protect_inputs(input_paths(args))
        for option, path in _outputs(args):
            _check_output(option, path, inputs)
        code = body(args)
        return int(code or 0)
    except BrokenPipeError:  # output piped into e.g. `head`, which has gone: not an error of ours
        os.dup2(os.open(os.devnull, os.O_WRONLY), sys.stdout.fileno())
        return EXIT_OK
    except SystemExit as e:  # sys.exit() inside a command: its code, its message in one line
        if e.code is None or isinstance(e.code, int):
            return int(e.code or 0)
        print(f"pafp {command}: {' '.join(str(e.code).split())}", file=sys.stderr)
        return EXIT_FAILED
    except BaseException as e:  # noqa: BLE001 - the contract: no traceback reaches the user
        line, code = exit_line(command, e)
        logger.debug("pafp %s raised", command, exc_info=True)
        print(line, file=sys.stderr)
        return code


def _check_output(option: str, out: Path, inputs: list[Path]) -> None:
    from host_tools.outdir import check_holds_no_input

    check_holds_no_input(out, option, inputs)


def shell_command(*words: object) -> str:
    """A command line a user can paste into a shell, whatever the paths hold (spaces, quotes): shlex-quoted."""
    return shlex.join(str(w) for w in words)
