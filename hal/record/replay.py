"""The replay backend: a `Board` whose peripherals and clock serve back what a record says they returned.

A record (hal/record/format.py) is read one section (one job) at a time: its inputs in recorded order
(each with its key: call kind and port), its outputs into the list the replayed job is compared with. Each
call of the replayed firmware takes the next recorded result of the same kind on the same port (the first
not yet taken: a job makes a handful of calls, a scan is cheaper than a queue per key), so a firmware that
makes its calls in another order still gets the same bytes; a call beyond the record gets a neutral
answer (no bytes, the last CNT) and is counted (``starved``). What the firmware writes is kept for the
comparison (`ReplayBoard.finish`), never sent anywhere. The firmware does not know it is replayed.

`replay_sections` is the replay loop: each section's job run at its recorded time, its outputs compared
and added to each port's stream (`Stream`: counts and SHA-256 of the bytes recorded and replayed). The
module is compiled (setup.py's COMPILED): the loop, the decoding and the calls the firmware makes are
what a replay costs beyond the firmware's own work.
"""

from __future__ import annotations

import hashlib
import struct
from collections import deque
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import Any, BinaryIO, Final

from hal.can import CanFrame, CanPort
from hal.errors import HalError
from hal.interfaces import Board, DigitalIn, DigitalOut, EncoderTimer, Uart, UartErrors, Watchdog
from hal.record.format import FIXED, VARIABLE, Kind, RecordError, read_chunks, read_header
from hal.record.recorder import PORTS
from rtos.job import Job

__all__ = ["OUTPUT_KINDS", "RecordReader", "ReplayBoard", "Section", "Stream", "item_bytes", "port_name",
           "replay_sections"]

OUTPUT_KINDS: Final = frozenset({Kind.WRITE, Kind.ENC_SET, Kind.LED, Kind.KICK, Kind.CAN_TX})
_PORT_NAMES: Final = {v: k for k, v in PORTS.items()}
_OUTPUT_NAMES: Final = {Kind.ENC_SET: "encoder", Kind.LED: "led", Kind.KICK: "watchdog", Kind.CAN_TX: "can"}
_WRITE: Final = Kind.WRITE
_RAISE: Final = Kind.RAISE
_CAN_RX: Final = Kind.CAN_RX
_CAN_TX: Final = Kind.CAN_TX
_CLOCK_KEY: Final = Kind.CLOCK << 2
_HEALTH_KEY: Final = Kind.HEALTH << 2
_ENC_CNT_KEY: Final = Kind.ENC_CNT << 2
_ENC_DIR_KEY: Final = Kind.ENC_DIR << 2
_ENC_SET_KEY: Final = Kind.ENC_SET << 2
_ESTOP_KEY: Final = Kind.ESTOP << 2
_LED_KEY: Final = Kind.LED << 2
_KICK_KEY: Final = Kind.KICK << 2
_FLUSH_BYTES: Final = 1 << 16  # a stream hashes its bytes once this many are pending (one update per ~64 KB)


def port_name(key: int) -> str:
    """The name of an output key (``kind << 2 | port``): motor, imu, telemetry, can, encoder, led, watchdog."""
    kind, port = key >> 2, key & 3
    return _PORT_NAMES[port] if kind == _WRITE else _OUTPUT_NAMES.get(kind, f"kind{kind}")


def item_bytes(key: int, item: Any) -> bytes:
    """The bytes an output item stands for in its port's stream (a write: the bytes the port accepted)."""
    kind = key >> 2
    if kind == _WRITE:
        accepted, data = item
        return data if accepted == len(data) else data[:accepted]
    if kind == _CAN_TX:
        ok, frame = item
        return bytes([ok, frame.extended]) + frame.arbitration_id.to_bytes(4, "little") + frame.data
    return repr(item).encode()


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


class Stream:
    """The bytes one port carried, in the record and in the replay: counts and SHA-256 (hashed ~64 KB at a time).

    `sink` (a binary file) receives the replayed bytes as they are hashed: the replay's telemetry.bin.
    """

    def __init__(self, sink: BinaryIO | None = None) -> None:
        """Empty; `sink` gets the replayed bytes."""
        self.expected_hash: Any = hashlib.sha256()
        self.produced_hash: Any = hashlib.sha256()
        self.expected = bytearray()
        self.produced = bytearray()
        self.expected_n = 0
        self.produced_n = 0
        self.sink = sink

    def flush(self) -> None:
        """Hash (and write to the sink) the pending bytes."""
        if self.expected:
            self.expected_hash.update(self.expected)
            self.expected = bytearray()
        if self.produced:
            self.produced_hash.update(self.produced)
            if self.sink is not None:
                self.sink.write(self.produced)
            self.produced = bytearray()

    def as_dict(self) -> dict:
        """Counts, digests and whether the replayed bytes are the recorded ones (flushes first)."""
        self.flush()
        same = self.expected_hash.digest() == self.produced_hash.digest() and self.expected_n == self.produced_n
        return {"recorded_items": self.expected_n, "replayed_items": self.produced_n, "identical": same,
                "recorded_sha256": self.expected_hash.hexdigest(), "replayed_sha256": self.produced_hash.hexdigest()}


class ReplayBoard:
    """The replayed peripherals: `board` for the firmware, `begin(section)` before each job, `finish()` after."""

    def __init__(self, header: dict, sinks: dict[str, BinaryIO] | None = None) -> None:
        """Peripherals shaped like the recorded ones (bauds, encoder width, CAN) from the record's header;
        `sinks` by port name receive the replayed bytes of that port (e.g. telemetry)."""
        ports = header["ports"]
        self.section = Section(-1, 0, 0)
        self.produced: dict[int, list] = {}
        self.starved = 0  # calls the record had no answer for (a changed firmware asking more)
        self.unused = 0  # recorded answers no call took (a changed firmware asking less)
        self.last: dict[int, Any] = {}
        self.last_control = -1  # the start of the latest control job replayed (replay_sections)
        self.streams: dict[str, Stream] = {}
        self._by_key: dict[int, Stream] = {}
        self._sinks: dict[str, BinaryIO] = dict(sinks or {})
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
        self.unused += s.untaken()
        if s.outputs == self.produced:
            return {}
        diff: dict[int, tuple[list, list]] = {}
        for key in s.outputs.keys() | self.produced.keys():
            expected, produced = s.outputs.get(key, []), self.produced.get(key, [])
            if expected != produced:
                diff[key] = (expected, produced)
        return diff

    def stream(self, key: int) -> Stream:
        """The stream of an output key (one per port name)."""
        s = self._by_key.get(key)
        if s is None:
            name = port_name(key)
            s = self.streams.get(name)
            if s is None:
                s = self.streams[name] = Stream(self._sinks.get(name))
            self._by_key[key] = s
        return s

    def account(self, diff: dict[int, tuple[list, list]]) -> None:
        """Add the job's outputs to the streams: the replayed ones, and the recorded ones (the same when no diff)."""
        for key, items in self.produced.items():
            s = self.stream(key)
            data = item_bytes_all(key, items)
            s.produced += data
            s.produced_n += len(items)
            if not diff:  # the same items were recorded
                s.expected += data
                s.expected_n += len(items)
            if len(s.produced) >= _FLUSH_BYTES or len(s.expected) >= _FLUSH_BYTES:
                s.flush()
        if diff:
            for key, items in self.section.outputs.items():
                s = self.stream(key)
                s.expected += item_bytes_all(key, items)
                s.expected_n += len(items)

    def take(self, key: int, default: Any) -> Any:
        """The next recorded result of this call (key: kind << 2 | port); a HalError recorded there is raised."""
        s = self.section
        i = s.find(key)
        if i < 0:
            self.starved += 1
            return self.last.get(key, default)
        s.keys[i] = -1
        value = s.values[i]
        if isinstance(value, HalError):
            raise HalError(str(value))
        self.last[key] = value
        return value

    def put(self, key: int, value: Any) -> None:
        """Keep an output of the replayed firmware."""
        out = self.produced.get(key)
        if out is None:
            self.produced[key] = [value]
        else:
            out.append(value)

    def expected_accept(self, key: int, data: bytes) -> int:
        """How many bytes the recorded port accepted for this write (all, when the record has no such write)."""
        recorded = self.section.outputs.get(key)
        if recorded is not None:
            done = self.produced.get(key)
            i = 0 if done is None else len(done)
            if i < len(recorded):
                accepted, was = recorded[i]
                if was == data or accepted < len(was):
                    return min(int(accepted), len(data))
        return len(data)

    def now_cycles(self) -> int:
        """A recorded clock reading (the job's start when the record has none left)."""
        return int(self.take(_CLOCK_KEY, self.section.start))

    def health(self) -> tuple[int, int]:
        """The recorded kernel deadline health."""
        h = self.take(_HEALTH_KEY, (0, 0))
        return int(h[0]), int(h[1])


def item_bytes_all(key: int, items: list) -> bytes:
    """The bytes of a job's output items on one key, joined."""
    if len(items) == 1:
        return item_bytes(key, items[0])
    return b"".join([item_bytes(key, item) for item in items])


def replay_sections(replay: ReplayBoard, sections: Iterator[Section],
                    bodies: dict[int, tuple[Callable[[Job], object], Job]], control_task: int, stop_task: int,
                    stop: Callable[[int], object], on_diff: Callable[[Section, dict[int, tuple[list, list]]], None],
                    progress: Callable[[int], None] | None) -> tuple[int, int]:
    """Run each section's job on its recorded inputs, compare and account its outputs; (jobs run, last start).

    `stop(start)` runs the stop path's section; `on_diff(section, diff)` is told of each diverging job
    (`replay.last_control` is then the start of the latest job of `control_task`); `progress(start)` is
    called every 8192 jobs.
    """
    jobs, last = 0, 0
    for section in sections:
        replay.begin(section)
        tid = section.task_id
        if tid == control_task:
            replay.last_control = section.start
        if tid == stop_task:
            stop(section.start)
        else:
            body, job = bodies[tid]
            job.release = job.ready = job.start = section.start
            job.index = section.index
            body(job)
        jobs += 1
        diff = replay.finish()
        replay.account(diff)
        if diff:
            on_diff(section, diff)
        last = section.start
        if progress is not None and jobs % 8192 == 0:
            progress(last)
    return jobs, last


class ReplayUart(Uart):
    """A UART that answers from the record and keeps what is written."""

    def __init__(self, replay: ReplayBoard, port: int, baud: int, name: str) -> None:
        """The recorded port's baud and name."""
        super().__init__(baud, name)
        self.replay, self.port = replay, port
        self._write_key, self._read_key = Kind.WRITE << 2 | port, Kind.READ << 2 | port
        self._rx_key, self._tx_key = Kind.IN_WAITING << 2 | port, Kind.TX_FREE << 2 | port
        self._flush_key, self._errors_key = Kind.FLUSH << 2 | port, Kind.ERRORS << 2 | port

    def _send(self, data: bytes) -> int:
        key = self._write_key
        replay = self.replay
        s = replay.section
        i = s.find(key)
        if i >= 0 and isinstance(s.values[i], HalError):  # the recorded write raised
            s.keys[i] = -1
            raise HalError(str(s.values[i]))
        accepted = replay.expected_accept(key, data)
        replay.put(key, (accepted, data))
        return accepted

    def _receive(self, max_bytes: int) -> bytes:
        data: bytes = self.replay.take(self._read_key, b"")
        self.replay.last.pop(self._read_key, None)  # a starved read returns nothing, not the last bytes
        return data

    def _rx_count(self) -> int:
        return int(self.replay.take(self._rx_key, 0))

    def _tx_space(self) -> int:
        return int(self.replay.take(self._tx_key, 1 << 12))

    def _drain(self, timeout_s: float) -> bool:
        return bool(self.replay.take(self._flush_key, True))

    def _refresh_errors(self) -> None:
        e = self.replay.take(self._errors_key, (0, 0, 0, 0, 0))
        self._errors = UartErrors(*e)


class ReplayEncoder(EncoderTimer):
    """The encoder timer: recorded CNT and DIR readings; CNT writes kept."""

    def __init__(self, replay: ReplayBoard, bits: int, arr: int) -> None:
        """The recorded timer's width and auto-reload."""
        super().__init__(bits, arr)
        self.replay = replay

    def cnt(self) -> int:
        """The recorded CNT."""
        return int(self.replay.take(_ENC_CNT_KEY, 0))

    def counting_down(self) -> bool:
        """The recorded DIR bit."""
        return bool(self.replay.take(_ENC_DIR_KEY, False))

    def _write_cnt(self, value: int) -> None:
        self.replay.put(_ENC_SET_KEY, value)


class ReplayPin(DigitalIn):
    """The e-stop input: the recorded levels."""

    def __init__(self, replay: ReplayBoard) -> None:
        """Read from `replay`."""
        self.replay = replay

    def read(self) -> bool:
        """The recorded level."""
        return bool(self.replay.take(_ESTOP_KEY, False))


class ReplayLed(DigitalOut):
    """The status LED: levels kept for the comparison."""

    def __init__(self, replay: ReplayBoard, initial: bool) -> None:
        """Start at the recorded initial level."""
        super().__init__(initial)
        self.replay = replay

    def _drive(self, level: bool) -> None:
        self.replay.put(_LED_KEY, int(level))


class ReplayWatchdog(Watchdog):
    """The watchdog: kicks kept for the comparison."""

    def __init__(self, replay: ReplayBoard) -> None:
        """Kicks go to `replay`."""
        self.replay = replay

    def kick(self) -> None:
        """Keep the kick."""
        self.replay.put(_KICK_KEY, None)


class ReplayCan(CanPort):
    """The CAN port: recorded received frames; sent frames kept."""

    def __init__(self, replay: ReplayBoard, bitrate: int) -> None:
        """The recorded bus's bit rate."""
        super().__init__(bitrate, "can (replay)")
        self.replay = replay
        port = PORTS["can"]
        self._tx_key, self._rx_key = Kind.CAN_TX << 2 | port, Kind.CAN_RX << 2 | port
        self._pending_key, self._flush_key = Kind.CAN_PENDING << 2 | port, Kind.CAN_FLUSH << 2 | port

    def _send(self, frame: CanFrame) -> bool:
        key = self._tx_key
        recorded = self.replay.section.outputs.get(key, [])
        done = self.replay.produced.get(key)
        i = 0 if done is None else len(done)
        ok = bool(recorded[i][0]) if i < len(recorded) else True
        self.replay.put(key, (int(ok), frame))
        return ok

    def _receive(self) -> CanFrame | None:
        frame: CanFrame | None = self.replay.take(self._rx_key, None)
        self.replay.last.pop(self._rx_key, None)
        return frame

    def _tx_pending(self) -> int:
        return int(self.replay.take(self._pending_key, 0))

    def _drain(self, timeout_s: float) -> bool:
        return bool(self.replay.take(self._flush_key, True))
