"""Helpers of the contract tests (tests/test_contract_*.py): `pafp` in-process with its exit code and stderr, a
record whose header is rewritten (as a hand-edited or old record would hold it), the contract's one-line check."""

from __future__ import annotations

import json
import struct
from pathlib import Path

from hal.record.format import write_header
from host_tools.cli import main

ALLOWED_EXITS = {0, 1, 2, 74}
"""What any input may make a command exit with (3, an internal error, is a bug)."""


def pafp(capsys, *argv: object) -> tuple[int, str, str]:
    """Run `pafp argv` in this process: (exit code, stdout, stderr)."""
    try:
        code = main([str(a) for a in argv])
    except SystemExit as e:  # argparse's own refusals
        code = e.code if isinstance(e.code, int) else 2
    out, err = capsys.readouterr()
    return code, out, err


def one_line(err: str) -> str:
    """The single line a refused command printed on stderr (AssertionError when there are more, or a traceback)."""
    lines = [line for line in err.splitlines() if line.strip()]
    assert "Traceback" not in err, err
    assert len(lines) == 1, err
    return lines[0]


def split_record(data: bytes) -> tuple[int, dict, bytes]:
    """(format version, header, the bytes after the header) of a record's bytes."""
    version, n = struct.unpack("<HI", data[8:14])
    header = json.loads(data[14:14 + n])
    return version, header, data[14 + n + (4 if version >= 2 else 0):]


def with_header(src: Path, dst: Path, edit, version: int | None = None) -> Path:
    """Copy the record ``src`` to the run directory ``dst`` with ``edit(header)`` applied, written by this pafp's
    write_header (its checksum valid: the header is what a foreign or hand-edited record holds), or as format
    ``version`` 1 (no checksum: a record written before the checksum)."""
    _, header, rest = split_record(src.read_bytes())
    edit(header)
    dst.mkdir(parents=True, exist_ok=True)
    path = dst / "record.bin"
    with path.open("wb") as f:
        if version == 1:
            blob = json.dumps(header, sort_keys=True).encode("utf-8")
            f.write(b"PAFPREC\0" + struct.pack("<HI", 1, len(blob)) + blob)
        else:
            write_header(f, header)
        f.write(rest)
    return dst


def tree(directory: Path) -> dict[str, bytes]:
    """Every file under directory (relative name -> bytes): to show a command left its inputs intact."""
    return {str(p.relative_to(directory)): p.read_bytes() for p in sorted(directory.rglob("*")) if p.is_file()}
