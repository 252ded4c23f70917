"""The record reader: a record (hal/record/format.py) read one section (one job) at a time.

Each `Section` holds its inputs in recorded order (each with its key: call kind and port) and its outputs
(the kinds of `OUTPUT_KINDS`) by key. `RecordReader._parse` decodes the common kinds byte by byte and the
others by their struct. The module is compiled (setup.py's COMPILED): the decoding is what reading a record
costs.
"""

from __future__ import annotations

import struct
from collections import deque
from collections.abc import Iterator
from pathlib import Path
from typing import Any, Final

from hal.can import CanFrame
from hal.errors import HalError
from hal.record.format import FIXED, VARIABLE, Kind, RecordError, read_chunks, read_header

__all__ = ["OUTPUT_KINDS", "RecordReader", "Section"]

OUTPUT_KINDS: Final = frozenset({Kind.WRITE, Kind.ENC_SET, Kind.LED, Kind.KICK, Kind.CAN_TX})
_RAISE: Final = Kind.RAISE
_CAN_RX: Final = Kind.CAN_RX
_CAN_TX: Final = Kind.CAN_TX


class Section:
    """One recorded job: its task, start and index, the results of its calls and what it sent.

    The results are `keys` and `values` in recorded order; a result taken by the replay has its key set to -1.
    """

    def __init__(self, task_id: int, start: int, index: int) -> None:
        """A section with no call results yet."""
        self.task_id = task_id
        self.start = start
        self.index = index
        self.keys: list[int] = []
        self.values: list[Any] = []
        self.outputs: dict[int, list] = {}

    @property
    def inputs(self) -> dict[int, deque]:
        """The results not taken yet, by key, in order (for reading a record; the replay uses `take`)."""
        out: dict[int, deque] = {}
        for key, value in zip(self.keys, self.values, strict=True):
            if key >= 0:
                out.setdefault(key, deque()).append(value)
        return out

    def find(self, key: int) -> int:
        """The index of the first result of `key` not taken yet, -1 when there is none."""
        keys = self.keys
        for i in range(len(keys)):
            if keys[i] == key:
                return i
        return -1

    def untaken(self) -> int:
        """How many results were not taken."""
        n = 0
        for key in self.keys:
            if key >= 0:
                n += 1
        return n


class RecordReader:
    """Reads a record: `header` at once, then `sections()` in time order; `footer` once they are all read."""

    def __init__(self, path: Path) -> None:
        """Open `path` and read its header (RecordError naming the offset when it is not a readable record)."""
        self.path = path
        try:
            self._file = path.open("rb")
        except OSError as e:
            raise RecordError(f"record {path}: cannot be read ({e.strerror})") from None
        try:
            self.header: dict = read_header(self._file, path)
        except BaseException:
            self._file.close()
            raise
        self.footer: dict = {}

    def close(self) -> None:
        """Close the file."""
        self._file.close()

    def sections(self) -> Iterator[Section]:
        """Every section in order (the events before the first job, if any, are dropped: there are none)."""
        section: Section | None = None
        try:
            for offset, raw in read_chunks(self._file, self.path, self.footer):
                for s in self._parse(offset, raw):
                    if section is not None:
                        yield section
                    section = s
        finally:
            self._file.close()
        if section is not None:
            yield section

    def _parse(self, offset: int, raw: bytes) -> list[Section]:
        """The sections a chunk holds (a chunk starts with a job: the recorder cuts chunks there).

        The common kinds are decoded here byte by byte (compiled: no call, no tuple); the others by their
        struct (format.FIXED, format.VARIABLE).
        """
        pos, start, n = 0, 0, len(raw)
        out: list[Section] = []
        section: Section | None = None
        try:
            while pos < n:
                start = pos
                tag = raw[pos]
                kind = tag >> 2
                shape = _SHAPES[kind]
                if shape < 0:
                    raise RecordError(f"record {self.path}: unknown event kind {kind} in the chunk at byte "
                                      f"offset {offset} (event byte {start})")
                pos += 1
                if shape == _S_JOB:
                    section = Section(raw[pos], _u64(raw, pos + 1), _u32(raw, pos + 9))
                    pos += 13
                    out.append(section)
                    continue
                if section is None:
                    raise RecordError(f"record {self.path}: the chunk at byte offset {offset} does not start "
                                      "with a job")
                key = tag
                value: Any
                if shape == _S_U8:
                    value = raw[pos]
                    pos += 1
                elif shape == _S_U32:
                    value = _u32(raw, pos)
                    pos += 4
                elif shape == _S_U64:
                    value = _u64(raw, pos)
                    pos += 8
                elif shape == _S_PAIR:
                    value = (_u32(raw, pos), _u32(raw, pos + 4))
                    pos += 8
                elif shape == _S_NONE:
                    value = None
                else:
                    vals: tuple = ()
                    if shape == _S_WRITE:
                        vals = (raw[pos] | raw[pos + 1] << 8,)
                        pos += 2
                    elif shape != _S_READ:
                        st = _STRUCTS[kind]
                        vals = st.unpack_from(raw, pos)
                        pos += st.size
                    data = b""
                    if shape != _S_FIXED:
                        length = raw[pos] | raw[pos + 1] << 8
                        pos += 2
                        if pos + length > n:
                            raise IndexError("short data")
                        data = raw[pos:pos + length]
                        pos += length
                    if shape == _S_READ:
                        value = data
                    elif shape == _S_WRITE:
                        value = (vals[0], data)
                    elif kind == _RAISE:
                        key, value = vals[0] << 2 | tag & 3, HalError(data.decode("utf-8", "replace"))
                    elif kind == _CAN_RX:
                        value = CanFrame(vals[1], data, bool(vals[0] & 2)) if vals[0] & 1 else None
                    elif kind == _CAN_TX:
                        value = (vals[0], CanFrame(vals[2], data, bool(vals[1])))
                    elif len(vals) == 1:
                        value = vals[0]
                    else:
                        value = vals
                if _OUTPUTS[kind]:
                    outs = section.outputs
                    out_list = outs.get(key)
                    if out_list is None:
                        outs[key] = [value]
                    else:
                        out_list.append(value)
                else:
                    section.keys.append(key)
                    section.values.append(value)
        except (struct.error, IndexError):
            raise RecordError(f"record {self.path}: the chunk at byte offset {offset} ends inside an event "
                              f"(the event at byte {start} of the chunk)") from None
        return out


def _u32(raw: bytes, p: int) -> int:
    return raw[p] | raw[p + 1] << 8 | raw[p + 2] << 16 | raw[p + 3] << 24


def _u64(raw: bytes, p: int) -> int:
    return _u32(raw, p) | _u32(raw, p + 4) << 32


# How _parse decodes each kind: its shape (-1: no such kind), its struct, whether it is an output
_S_JOB: Final = 0
_S_U8: Final = 1
_S_U32: Final = 2
_S_U64: Final = 3
_S_PAIR: Final = 4  # two u32
_S_NONE: Final = 5
_S_READ: Final = 6  # <H length + bytes
_S_WRITE: Final = 7  # <H accepted, <H length + bytes
_S_FIXED: Final = 8  # another fixed layout (its struct)
_S_VARIABLE: Final = 9  # another fixed part + <H length + bytes (its struct)
_BY_FORMAT: Final = {"<BQI": _S_JOB, "<B": _S_U8, "<I": _S_U32, "<Q": _S_U64, "<II": _S_PAIR, "": _S_NONE}


def _shapes() -> tuple[list[int], list[Any], list[bool]]:
    shapes: list[int] = [-1] * 64
    structs: list[Any] = [None] * 64
    outputs: list[bool] = [False] * 64
    for k, st in FIXED.items():
        shapes[k], structs[k] = _BY_FORMAT.get(st.format, _S_FIXED), st
    for k, st in VARIABLE.items():
        shapes[k], structs[k] = _S_VARIABLE, st
    shapes[Kind.READ], shapes[Kind.WRITE] = _S_READ, _S_WRITE
    assert VARIABLE[Kind.READ].format == "" and VARIABLE[Kind.WRITE].format == "<H"
    for k in OUTPUT_KINDS:
        outputs[k] = True
    return shapes, structs, outputs


_TABLES: Final = _shapes()
_SHAPES: Final[list[int]] = _TABLES[0]
_STRUCTS: Final[list[Any]] = _TABLES[1]
_OUTPUTS: Final[list[bool]] = _TABLES[2]
