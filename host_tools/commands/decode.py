"""`pafp decode`: decode a raw byte capture (VESC, UART-RVC or telemetry) to JSON lines or CSV.

One JSON object per decoded message (``{"type": ..., <SI fields>}``), then one summary line
``{"summary": {...}}`` with the decoder's counters. With ``--csv OUT`` the messages go to a CSV table
(columns: the union of all fields, angles also in ``*_deg`` columns) and only the summary is printed
(``--csv -``: the table on stdout, the summary on stderr). Non-finite floats are written as JSON null;
bytes as hex strings.

At the end of the input the decoder gives up what it holds: a VESC candidate frame still pending (a false
header near the end would otherwise hide the frames after it) is skipped one start byte at a time, as the
firmware's rx timeout does, and the frames behind it are decoded. The summary's ``end_of_input`` says how
many bytes were held, how many candidates were given up, how many messages that recovered and how many
bytes were left over in no message (also counted in ``dropped_bytes``).

Memory does not grow with the capture: JSON lines are written as they are decoded; CSV rows go to a
temporary file first (pickled batches: the header needs every column), then to the table.
"""

from __future__ import annotations

import argparse
import contextlib
import csv
import dataclasses
import json
import math
import os
import pickle
import stat
import sys
import tempfile
from collections.abc import Callable, Iterator
from enum import IntEnum
from pathlib import Path
from typing import Any, BinaryIO, TextIO

from host_tools.outdir import EXIT_WRITE_FAILED
from protocol.rvc import RvcDecoder
from protocol.telemetry import TelemetryDecoder, TelemetryRecord, record_to_row

HELP = "decode a raw byte capture (vesc, rvc or telemetry) to JSON lines or CSV"
CHUNK_BYTES = 65536
PROTOCOLS = ("vesc", "rvc", "telemetry")
DIRECTIONS = ("to-motor", "from-motor")


class DecodeError(Exception):
    """A problem reported to the user as one line on stderr with exit code 2."""


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """Register the options of `pafp decode`."""
    parser.add_argument("--protocol", required=True, choices=PROTOCOLS, help="wire protocol of the capture")
    parser.add_argument(
        "--direction", choices=DIRECTIONS, default=None,
        help="vesc only: which side sent the bytes (default from-motor)",
    )
    parser.add_argument(
        "--csv", metavar="OUT", default=None,
        help="write a CSV table to OUT ('-' for stdout, the summary then on stderr) instead of JSON lines"
    )
    parser.add_argument("file", metavar="FILE", help="raw byte capture, or '-' for stdin")


def _make_decoder(protocol: str, direction: str) -> Any:
    """Build the streaming decoder for a protocol (each has feed(bytes) -> list and a stats dataclass)."""
    if protocol == "rvc":
        return RvcDecoder()
    if protocol == "telemetry":
        return TelemetryDecoder()
    try:
        from protocol import vesc
    except ImportError as exc:
        raise DecodeError(f"the VESC decoder is not available: {exc}") from None
    return vesc.Decoder(direction=direction)


def _jsonable(value: Any) -> Any:
    """Convert a field value to plain JSON: enums to int, bytes to hex, non-finite floats to None."""
    if isinstance(value, IntEnum):
        return int(value)
    if isinstance(value, float):
        return value if math.isfinite(value) else None
    if isinstance(value, bytes | bytearray):
        return bytes(value).hex()
    if isinstance(value, dict):
        return {str(k): _jsonable(v) for k, v in value.items()}
    if isinstance(value, list | tuple):
        return [_jsonable(v) for v in value]
    return value


def message_fields(msg: Any) -> dict[str, Any]:
    """SI fields of a decoded message, starting with its type name."""
    return {"type": type(msg).__name__, **dataclasses.asdict(msg)}


def _with_degrees(row: dict[str, Any]) -> dict[str, Any]:
    """Add a ``*_deg`` column after every ``*_rad`` one (``x_rad_s`` -> ``x_deg_s``)."""
    out: dict[str, Any] = {}
    for key, value in row.items():
        out[key] = value
        if "_rad" in key and isinstance(value, int | float) and not isinstance(value, bool):
            out[key.replace("_rad", "_deg", 1)] = math.degrees(value)
    return out


def message_row(msg: Any) -> dict[str, Any]:
    """Flat CSV row of a message: nested dicts flattened, bytes as hex, angles also in degrees."""
    if isinstance(msg, TelemetryRecord):
        return {"type": type(msg).__name__, **record_to_row(msg)}
    flat: dict[str, Any] = {}
    for key, value in message_fields(msg).items():
        if isinstance(value, dict):
            for sub, v in value.items():
                flat[sub if sub not in flat else f"{key}.{sub}"] = v
        else:
            flat[key] = value
    return {k: _csv_cell(v) for k, v in _with_degrees(flat).items()}


def _csv_cell(value: Any) -> Any:
    """CSV representation of one value (enums as int, bytes as hex, sequences as JSON)."""
    if isinstance(value, IntEnum):
        return int(value)
    if isinstance(value, bytes | bytearray):
        return bytes(value).hex()
    if isinstance(value, list | tuple):
        return json.dumps(_jsonable(value))
    return value


def _read_chunks(stream: BinaryIO) -> Iterator[bytes]:
    """Yield the capture in chunks of CHUNK_BYTES until EOF."""
    while chunk := stream.read(CHUNK_BYTES):
        yield chunk


@contextlib.contextmanager
def _open_input(path: str) -> Iterator[BinaryIO]:
    """Open FILE for binary reading ('-' = stdin), turning OS errors into DecodeError."""
    if path == "-":
        yield sys.stdin.buffer
        return
    try:
        handle = open(path, "rb")
    except OSError as exc:
        raise DecodeError(f"cannot read {path}: {exc.strerror or exc}") from None
    with handle:
        yield handle


def _decode(path: str, decoder: Any, emit: Callable[[Any], None]) -> dict[str, int]:
    """Feed the whole capture through the decoder, calling emit for each message; flush at the end.

    A failure to read names the file (DecodeError); a failure to write (a closed stdout) is not caught here.
    """
    with _open_input(path) as stream:
        chunks = _read_chunks(stream)
        while True:
            try:
                chunk = next(chunks, None)
            except OSError as exc:
                raise DecodeError(f"cannot read {path}: {exc.strerror or exc}") from None
            if chunk is None:
                break
            for msg in decoder.feed(chunk):
                emit(msg)
    return _flush(decoder, emit)


def _flush(decoder: Any, emit: Callable[[Any], None]) -> dict[str, int]:
    """End of input: give up what the decoder holds, emit the messages that recovers, count the rest."""
    held = decoder.buffered if hasattr(decoder, "buffered") else decoder.pending_bytes
    dropped_before = decoder.stats.dropped_bytes
    given_up = recovered = 0
    if hasattr(decoder, "skip_pending"):  # VESC: a pending candidate may hide whole frames behind it
        while decoder.buffered:
            given_up += 1
            for msg in decoder.skip_pending():
                recovered += 1
                emit(msg)
    else:  # RVC and telemetry frames cannot hide behind a shorter remainder: what is held is left over
        given_up = int(held > 0)
        decoder.reset()
    return {"held_bytes": held, "candidates_given_up": given_up, "messages_recovered": recovered,
            "leftover_bytes": decoder.stats.dropped_bytes - dropped_before}


class _CsvSpool:
    """CSV rows kept in a temporary file (pickled batches) with their columns, until the table can be written."""

    BATCH = 4096

    def __init__(self, directory: str | None) -> None:
        """Create the spool file in directory (the output's, so a full disk shows before decoding)."""
        self._f = tempfile.TemporaryFile("w+b", dir=directory)
        self._batch: list[dict[str, Any]] = []
        self.columns: dict[str, None] = {}

    def add(self, row: dict[str, Any]) -> None:
        """Keep one row."""
        self.columns.update(dict.fromkeys(row))
        self._batch.append(row)
        if len(self._batch) >= self.BATCH:
            pickle.dump(self._batch, self._f, protocol=pickle.HIGHEST_PROTOCOL)
            self._batch = []

    def write_to(self, out: TextIO) -> None:
        """Write the table: the header (every column, in order of first use), then the rows."""
        writer = csv.DictWriter(out, fieldnames=list(self.columns), restval="")
        writer.writeheader()
        self._f.seek(0)
        while True:
            try:
                writer.writerows(pickle.load(self._f))
            except EOFError:
                break
        writer.writerows(self._batch)
        self._f.close()


def _csv_target(out_path: str) -> tuple[str | None, str | None]:
    """(directory, temporary file name) for --csv OUT, checked writable now; (None, None) for stdout.

    A path that exists and is not a regular file (a device, a FIFO) is written in place: (directory, None)
    (renaming a temporary file over it would replace the device node itself)."""
    if out_path == "-":
        return None, None
    directory = os.path.dirname(os.path.abspath(out_path))
    try:
        if os.path.isdir(out_path):
            raise IsADirectoryError(21, "Is a directory")
        if os.path.exists(out_path) and not stat.S_ISREG(os.stat(out_path).st_mode):
            if not os.access(out_path, os.W_OK):
                raise PermissionError(13, "Permission denied")
            return directory, None
        fd, tmp = tempfile.mkstemp(prefix=f".{os.path.basename(out_path)}.", suffix=".tmp", dir=directory)
        os.close(fd)
    except OSError as exc:
        raise DecodeError(f"cannot write {out_path}: {exc.strerror or exc}") from None
    return directory, tmp


def _summary(protocol: str, decoder: Any, end: dict[str, int]) -> dict[str, Any]:
    """The final summary object: protocol, every counter of the decoder, what the end of input left."""
    return {"summary": {"protocol": protocol, **dataclasses.asdict(decoder.stats), "end_of_input": end}}


def run(args: argparse.Namespace) -> int:
    """Decode the capture and print JSON lines (or write CSV); 2 on a bad file or option."""
    tmp: str | None = None
    try:
        if args.direction is not None and args.protocol != "vesc":
            raise DecodeError(f"--direction {args.direction} applies only to --protocol vesc")
        decoder = _make_decoder(args.protocol, args.direction or "from-motor")
        out = sys.stdout
        summary_to = out
        if args.csv is None:
            def emit(msg: Any) -> None:
                out.write(json.dumps(_jsonable(message_fields(msg))) + "\n")

            end = _decode(args.file, decoder, emit)
        else:
            directory, tmp = _csv_target(args.csv)
            spool = _CsvSpool(directory)
            end = _decode(args.file, decoder, lambda msg: spool.add(message_row(msg)))
            if directory is None:  # --csv -: the table is the output, the summary goes aside
                spool.write_to(out)
                summary_to = sys.stderr
            else:
                try:
                    with open(tmp or args.csv, "w", newline="", encoding="utf-8") as handle:
                        spool.write_to(handle)
                    if tmp is not None:
                        os.replace(tmp, args.csv)
                except OSError as exc:
                    print(f"pafp decode: cannot write {args.csv}: {exc.strerror or exc} (exit {EXIT_WRITE_FAILED})",
                          file=sys.stderr)
                    return EXIT_WRITE_FAILED
                tmp = None
        summary_to.write(json.dumps(_jsonable(_summary(args.protocol, decoder, end))) + "\n")
        summary_to.flush()
    except DecodeError as exc:
        print(f"pafp decode: {exc}", file=sys.stderr)
        return 2
    finally:
        if tmp is not None:
            Path(tmp).unlink(missing_ok=True)
    return 0
