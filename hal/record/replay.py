"""The replay backend: a `Board` whose peripherals and clock serve back what a record says they returned.

A record (hal/record/format.py) is read one section (one job) at a time: its inputs go into one queue per
call kind and port, its outputs into the list the replayed job is compared with. Each call of the
replayed firmware takes the next recorded result of the same kind on the same port, so a firmware that
makes its calls in another order still gets the same bytes; a call beyond the record gets a neutral
answer (no bytes, the last CNT) and is counted (``starved``). What the firmware writes is kept for the
comparison (`ReplayBoard.finish`), never sent anywhere. The firmware does not know it is replayed.
"""

from __future__ import annotations

import struct
from collections import deque
from collections.abc import Iterator
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from hal.can import CanFrame, CanPort
from hal.errors import HalError
from hal.interfaces import Board, DigitalIn, DigitalOut, EncoderTimer, Uart, UartErrors, Watchdog
from hal.record.format import FIXED, VARIABLE, Kind, RecordError, read_chunks, read_header
from hal.record.recorder import PORTS

__all__ = ["OUTPUT_KINDS", "RecordReader", "ReplayBoard", "Section", "port_name"]

OUTPUT_KINDS = frozenset({Kind.WRITE, Kind.ENC_SET, Kind.LED, Kind.KICK, Kind.CAN_TX})
_PORT_NAMES = {v: k for k, v in PORTS.items()}
_OUTPUT_NAMES = {Kind.ENC_SET: "encoder", Kind.LED: "led", Kind.KICK: "watchdog", Kind.CAN_TX: "can"}


def port_name(key: int) -> str:
    """The name of an output key (``kind << 2 | port``): motor, imu, telemetry, can, encoder, led, watchdog."""
    kind, port = key >> 2, key & 3
    return _PORT_NAMES[port] if kind == Kind.WRITE else _OUTPUT_NAMES.get(kind, f"kind{kind}")


@dataclass
class Section:
    """One recorded job: its task, start and index, the results of its calls and what it sent."""

    task_id: int
    start: int
    index: int
    inputs: dict[int, deque] = field(default_factory=dict)
    outputs: dict[int, list] = field(default_factory=dict)


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
            self.header = read_header(self._file, path)
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

    def _parse(self, offset: int, raw: bytes) -> Iterator[Section]:
        """The sections a chunk holds (a chunk starts with a job: the recorder cuts chunks there)."""
        pos, n = 0, len(raw)
        section: Section | None = None
        layouts = _LAYOUTS
        try:
            while pos < n:
                tag = raw[pos]
                pos += 1
                layout = layouts.get(tag >> 2)
                if layout is None:
                    raise RecordError(f"record {self.path}: unknown event kind {tag >> 2} in the chunk at byte "
                                      f"offset {offset} (event byte {pos - 1})")
                kind, st, variable, output = layout
                vals = st.unpack_from(raw, pos)
                pos += st.size
                if variable:
                    length = raw[pos] | raw[pos + 1] << 8
                    pos += 2
                    if pos + length > n:
                        raise struct.error("short data")
                    data = raw[pos:pos + length]
                    pos += length
                if kind == Kind.JOB:
                    if section is not None:
                        yield section
                    section = Section(vals[0], vals[1], vals[2], {}, {})
                    continue
                if section is None:
                    raise RecordError(f"record {self.path}: the chunk at byte offset {offset} does not start "
                                      "with a job")
                key = tag
                value: Any
                if kind == Kind.READ:
                    value = data
                elif kind == Kind.WRITE:
                    value = (vals[0], data)
                elif kind == Kind.RAISE:
                    key, value = vals[0] << 2 | tag & 3, HalError(data.decode("utf-8", "replace"))
                elif kind == Kind.CAN_RX:
                    value = CanFrame(vals[1], data, bool(vals[0] & 2)) if vals[0] & 1 else None
                elif kind == Kind.CAN_TX:
                    value = (vals[0], CanFrame(vals[2], data, bool(vals[1])))
                elif kind == Kind.ERRORS or kind == Kind.HEALTH:
                    value = vals
                elif kind == Kind.KICK:
                    value = None
                else:
                    value = vals[0]
                if output:
                    out = section.outputs.get(key)
                    if out is None:
                        section.outputs[key] = [value]
                    else:
                        out.append(value)
                else:
                    q = section.inputs.get(key)
                    if q is None:
                        section.inputs[key] = deque((value,))
                    else:
                        q.append(value)
        except (struct.error, IndexError):
            raise RecordError(f"record {self.path}: the chunk at byte offset {offset} ends inside an event "
                              f"(event byte {pos})") from None
        if section is not None:
            yield section


# kind -> (kind, fixed part, followed by <H length + bytes, an output)
_LAYOUTS = {**{k: (k, st, False, k in OUTPUT_KINDS) for k, st in FIXED.items()},
            **{k: (k, st, True, k in OUTPUT_KINDS) for k, st in VARIABLE.items()}}


class ReplayBoard:
    """The replayed peripherals: `board` for the firmware, `begin(section)` before each job, `finish()` after."""

    def __init__(self, header: dict) -> None:
        """Peripherals shaped like the recorded ones (bauds, encoder width, CAN) from the record's header."""
        ports = header["ports"]
        self.section = Section(-1, 0, 0)
        self.produced: dict[int, list] = {}
        self.starved = 0  # calls the record had no answer for (a changed firmware asking more)
        self.unused = 0  # recorded answers no call took (a changed firmware asking less)
        self.last: dict[int, Any] = {}
        self.f_cpu_hz = int(header["f_cpu_hz"])
        can = ReplayCan(self, int(header["can_bitrate"])) if header.get("can_bitrate") else None
        self.board = Board(
            motor_uart=ReplayUart(self, PORTS["motor"], int(ports["motor"]["baud"]), ports["motor"]["name"]),
            imu_uart=ReplayUart(self, PORTS["imu"], int(ports["imu"]["baud"]), ports["imu"]["name"]),
            telemetry_uart=ReplayUart(self, PORTS["telemetry"], int(ports["telemetry"]["baud"]),
                                      ports["telemetry"]["name"]),
            encoder=ReplayEncoder(self, int(header["encoder"]["bits"]), int(header["encoder"]["arr"])),
            estop=ReplayPin(self), led=ReplayLed(self, bool(header.get("led", False))), watchdog=ReplayWatchdog(self),
            now_cycles=self.now_cycles, f_cpu_hz=self.f_cpu_hz, can=can)

    def begin(self, section: Section) -> None:
        """Serve this section's recorded results to the calls of the job about to run."""
        self.section = section
        self.produced = {}

    def finish(self) -> dict[int, tuple[list, list]]:
        """After the job: the outputs that differ from the record, by key: (expected, produced)."""
        s = self.section
        for q in s.inputs.values():
            if q:
                self.unused += len(q)
        if s.outputs == self.produced:
            return {}
        diff = {}
        for key in s.outputs.keys() | self.produced.keys():
            expected, produced = s.outputs.get(key, []), self.produced.get(key, [])
            if expected != produced:
                diff[key] = (expected, produced)
        return diff

    def take(self, key: int, default: Any) -> Any:
        """The next recorded result of this call (key: kind << 2 | port); a HalError recorded there is raised."""
        q = self.section.inputs.get(key)
        if not q:
            self.starved += 1
            return self.last.get(key, default)
        value = q.popleft()
        if isinstance(value, HalError):
            raise HalError(str(value))
        self.last[key] = value
        return value

    def put(self, key: int, value: Any) -> None:
        """Keep an output of the replayed firmware."""
        out = self.produced.get(key)
        if out is None:
            out = self.produced[key] = []
        out.append(value)

    def expected_accept(self, key: int, data: bytes) -> int:
        """How many bytes the recorded port accepted for this write (all, when the record has no such write)."""
        recorded = self.section.outputs.get(key, [])
        i = len(self.produced.get(key, []))
        if i < len(recorded):
            accepted, was = recorded[i]
            if was == data or accepted < len(was):
                return min(accepted, len(data))
        return len(data)

    def now_cycles(self) -> int:
        """A recorded clock reading (the job's start when the record has none left)."""
        return int(self.take(Kind.CLOCK << 2, self.section.start))

    def health(self) -> tuple[int, int]:
        """The recorded kernel deadline health."""
        return tuple(self.take(Kind.HEALTH << 2, (0, 0)))  # type: ignore[return-value]


class ReplayUart(Uart):
    """A UART that answers from the record and keeps what is written."""

    def __init__(self, replay: ReplayBoard, port: int, baud: int, name: str) -> None:
        """The recorded port's baud and name."""
        super().__init__(baud, name)
        self.replay, self.port = replay, port

    def _send(self, data: bytes) -> int:
        key = Kind.WRITE << 2 | self.port
        q = self.replay.section.inputs.get(key)
        if q and isinstance(q[0], HalError):  # the recorded write raised
            raise HalError(str(q.popleft()))
        accepted = self.replay.expected_accept(key, data)
        self.replay.put(key, (accepted, data))
        return accepted

    def _receive(self, max_bytes: int) -> bytes:
        data = self.replay.take(Kind.READ << 2 | self.port, b"")
        self.replay.last.pop(Kind.READ << 2 | self.port, None)  # a starved read returns nothing, not the last bytes
        return data

    def _rx_count(self) -> int:
        return int(self.replay.take(Kind.IN_WAITING << 2 | self.port, 0))

    def _tx_space(self) -> int:
        return int(self.replay.take(Kind.TX_FREE << 2 | self.port, 1 << 12))

    def _drain(self, timeout_s: float) -> bool:
        return bool(self.replay.take(Kind.FLUSH << 2 | self.port, True))

    def _refresh_errors(self) -> None:
        e = self.replay.take(Kind.ERRORS << 2 | self.port, (0, 0, 0, 0, 0))
        self._errors = UartErrors(*e)


class ReplayEncoder(EncoderTimer):
    """The encoder timer: recorded CNT and DIR readings; CNT writes kept."""

    def __init__(self, replay: ReplayBoard, bits: int, arr: int) -> None:
        """The recorded timer's width and auto-reload."""
        super().__init__(bits, arr)
        self.replay = replay

    def cnt(self) -> int:
        """The recorded CNT."""
        return int(self.replay.take(Kind.ENC_CNT << 2, 0))

    def counting_down(self) -> bool:
        """The recorded DIR bit."""
        return bool(self.replay.take(Kind.ENC_DIR << 2, False))

    def _write_cnt(self, value: int) -> None:
        self.replay.put(Kind.ENC_SET << 2, value)


class ReplayPin(DigitalIn):
    """The e-stop input: the recorded levels."""

    def __init__(self, replay: ReplayBoard) -> None:
        """Read from `replay`."""
        self.replay = replay

    def read(self) -> bool:
        """The recorded level."""
        return bool(self.replay.take(Kind.ESTOP << 2, False))


class ReplayLed(DigitalOut):
    """The status LED: levels kept for the comparison."""

    def __init__(self, replay: ReplayBoard, initial: bool) -> None:
        """Start at the recorded initial level."""
        super().__init__(initial)
        self.replay = replay

    def _drive(self, level: bool) -> None:
        self.replay.put(Kind.LED << 2, int(level))


class ReplayWatchdog(Watchdog):
    """The watchdog: kicks kept for the comparison."""

    def __init__(self, replay: ReplayBoard) -> None:
        """Kicks go to `replay`."""
        self.replay = replay

    def kick(self) -> None:
        """Keep the kick."""
        self.replay.put(Kind.KICK << 2, None)


class ReplayCan(CanPort):
    """The CAN port: recorded received frames; sent frames kept."""

    def __init__(self, replay: ReplayBoard, bitrate: int) -> None:
        """The recorded bus's bit rate."""
        super().__init__(bitrate, "can (replay)")
        self.replay = replay
        self._key = PORTS["can"]

    def _send(self, frame: CanFrame) -> bool:
        key = Kind.CAN_TX << 2 | self._key
        recorded = self.replay.section.outputs.get(key, [])
        i = len(self.replay.produced.get(key, []))
        ok = bool(recorded[i][0]) if i < len(recorded) else True
        self.replay.put(key, (int(ok), frame))
        return ok

    def _receive(self) -> CanFrame | None:
        frame = self.replay.take(Kind.CAN_RX << 2 | self._key, None)
        self.replay.last.pop(Kind.CAN_RX << 2 | self._key, None)
        return frame

    def _tx_pending(self) -> int:
        return int(self.replay.take(Kind.CAN_PENDING << 2 | self._key, 0))

    def _drain(self, timeout_s: float) -> bool:
        return bool(self.replay.take(Kind.CAN_FLUSH << 2 | self._key, True))
