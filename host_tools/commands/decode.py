"""`pafp decode`: decode a raw byte capture (VESC, UART-RVC or telemetry) to JSON lines or CSV.

One JSON object per decoded message (``{"type": ..., <SI fields>}``), then one summary line
``{"summary": {...}}`` with the decoder's counters. With ``--csv OUT`` the messages go to a CSV table
(columns: the union of all fields, angles also in ``*_deg`` columns) and only the summary is printed.
Non-finite floats are written as JSON null; bytes as hex strings.
"""

from __future__ import annotations

import argparse
import contextlib
import csv
import dataclasses
import json
import math
import sys
from collections.abc import Callable, Iterator
from enum import IntEnum
from typing import Any, BinaryIO

from firmware.protocol.rvc import RvcDecoder
from firmware.protocol.telemetry import TelemetryDecoder, TelemetryRecord, record_to_row

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
        "--csv", metavar="OUT", default=None, help="write a CSV table to OUT instead of JSON lines"
    )
    parser.add_argument("file", metavar="FILE", help="raw byte capture, or '-' for stdin")


def _make_decoder(protocol: str, direction: str) -> Any:
    """Build the streaming decoder for a protocol (each has feed(bytes) -> list and a stats dataclass)."""
    if protocol == "rvc":
        return RvcDecoder()
    if protocol == "telemetry":
        return TelemetryDecoder()
    try:
        from firmware.protocol import vesc
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


def _decode(path: str, decoder: Any, emit: Callable[[Any], None]) -> None:
    """Feed the whole capture through the decoder, calling emit for each message."""
    with _open_input(path) as stream:
        try:
            for chunk in _read_chunks(stream):
                for msg in decoder.feed(chunk):
                    emit(msg)
        except OSError as exc:
            raise DecodeError(f"cannot read {path}: {exc.strerror or exc}") from None


def _write_csv(out_path: str, rows: list[dict[str, Any]]) -> None:
    """Write rows to a CSV file whose columns are the union of all keys, in order of first use."""
    columns: dict[str, None] = {}
    for row in rows:
        columns.update(dict.fromkeys(row))
    try:
        with open(out_path, "w", newline="", encoding="utf-8") as handle:
            writer = csv.DictWriter(handle, fieldnames=list(columns), restval="")
            writer.writeheader()
            writer.writerows(rows)
    except OSError as exc:
        raise DecodeError(f"cannot write {out_path}: {exc.strerror or exc}") from None


def _summary(protocol: str, decoder: Any) -> dict[str, Any]:
    """The final summary object: protocol and every counter of the decoder."""
    return {"summary": {"protocol": protocol, **dataclasses.asdict(decoder.stats)}}


def run(args: argparse.Namespace) -> int:
    """Decode the capture and print JSON lines (or write CSV); 2 on a bad file or option."""
    try:
        if args.direction is not None and args.protocol != "vesc":
            raise DecodeError(f"--direction {args.direction} applies only to --protocol vesc")
        decoder = _make_decoder(args.protocol, args.direction or "from-motor")
        out = sys.stdout
        if args.csv is None:
            def emit(msg: Any) -> None:
                out.write(json.dumps(_jsonable(message_fields(msg))) + "\n")

            _decode(args.file, decoder, emit)
        else:
            rows: list[dict[str, Any]] = []
            _decode(args.file, decoder, lambda msg: rows.append(message_row(msg)))
            _write_csv(args.csv, rows)
        out.write(json.dumps(_jsonable(_summary(args.protocol, decoder))) + "\n")
        out.flush()
    except DecodeError as exc:
        print(f"pafp decode: {exc}", file=sys.stderr)
        return 2
    return 0
