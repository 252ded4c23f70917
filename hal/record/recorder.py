"""The recorder: wraps the peripherals and the clock the firmware is handed and writes what they returned.

Every call the firmware makes on its `Board` goes through a recording peripheral that forwards it to the
real one (a pyserial port, the virtual MCU) and appends one event: the bytes each read returned, the
counts, the encoder's CNT, the pin levels, every clock reading, the kernel's deadline health, the
HalErrors raised; and what the firmware sent (writes, kicks, LED levels), so a replay can compare. The
composition root marks where each job starts (`Recorder.job`, or a task body wrapped in `SectionedBody`)
so the replay can run the same job on the same inputs. Events are packed in memory and handed, one chunk
at a time, to a writer thread that compresses and writes them (hal/record/format.py), so the firmware's
loop never waits on zlib or the disk (zlib releases the GIL while it deflates).

The module is compiled (setup.py's COMPILED): in serial mode each recorded call costs the loop's jobs
time, so the hot path is a few C calls per event: each wrapper holds its event tags and packers bound
at construction, and appends one packed event to the chunk's one bytearray.
"""

from __future__ import annotations

import errno
import queue
import struct
import threading
from collections.abc import Callable
from dataclasses import replace
from pathlib import Path
from typing import Any, Final

from hal.can import CanFrame, CanPort
from hal.errors import HalError
from hal.interfaces import Board, DigitalIn, DigitalOut, EncoderTimer, Uart, Watchdog
from hal.record.format import CHUNK_BYTES, FIXED, VARIABLE, Kind, pack_chunk, pack_end, write_header

__all__ = ["PORTS", "Recorder", "SectionedBody"]

PORTS: Final = {"motor": 0, "imu": 1, "telemetry": 2, "can": 3}
_QUEUE_CHUNKS: Final = 16  # chunks waiting for the writer at most (bounded memory); the loop blocks beyond that
# per kind, one packer of the tag byte and the fixed part (and, variable kinds, the length): one call per event
_FIXED_PACK: Final[dict[int, Callable[..., bytes]]] = {
    k: struct.Struct("<B" + st.format.lstrip("<")).pack for k, st in FIXED.items()}
_VAR_PACK: Final[dict[int, Callable[..., bytes]]] = {
    k: struct.Struct("<B" + st.format.lstrip("<") + "H").pack for k, st in VARIABLE.items()}
_JOB_PACK: Final = _FIXED_PACK[Kind.JOB]
_U8_PACK: Final = struct.Struct("<BB").pack  # tag, one byte (FLUSH, ENC_DIR, ESTOP, LED)
_U32_PACK: Final = struct.Struct("<BI").pack  # tag, u32 (IN_WAITING, TX_FREE, ENC_CNT, ENC_SET, CAN_PENDING)
_CLOCK_PACK: Final = _FIXED_PACK[Kind.CLOCK]
_HEALTH_PACK: Final = _FIXED_PACK[Kind.HEALTH]
_READ_PACK: Final = _VAR_PACK[Kind.READ]
_WRITE_PACK: Final = _VAR_PACK[Kind.WRITE]
_CAN_RX_PACK: Final = _VAR_PACK[Kind.CAN_RX]
_CAN_TX_PACK: Final = _VAR_PACK[Kind.CAN_TX]
_ERRORS_PACK: Final = _FIXED_PACK[Kind.ERRORS]
_KICK: Final = bytes([Kind.KICK << 2])
_CLOCK_TAG: Final = Kind.CLOCK << 2
_HEALTH_TAG: Final = Kind.HEALTH << 2
_ENC_CNT_TAG: Final = Kind.ENC_CNT << 2
_ENC_DIR_TAG: Final = Kind.ENC_DIR << 2
_ENC_SET_TAG: Final = Kind.ENC_SET << 2
_ESTOP_TAG: Final = Kind.ESTOP << 2
_LED_TAG: Final = Kind.LED << 2


def _tag(kind: int, port: int) -> int:
    return kind << 2 | port


class Recorder:
    """Writes the inputs the firmware saw into `path`, in sections opened by `job` (one per task job)."""

    def __init__(self, path: Path, header: dict) -> None:
        """Create `path` and write the header (what was run: the replay rebuilds the firmware from it)."""
        self.path = path
        self._file = path.open("wb")
        write_header(self._file, header)
        self.buf = bytearray()
        self._queue: queue.Queue[bytes | None] = queue.Queue(_QUEUE_CHUNKS)
        self._error: BaseException | None = None
        self._writer_thread = threading.Thread(target=self._writer, name="pafp-record-writer", daemon=True)
        self._writer_thread.start()
        self.events = 0
        self.jobs = 0
        self.raw_bytes = 0
        self.closed = False

    # The writer thread ---------------------------------------------------------------------------
    def _writer(self) -> None:
        while True:
            raw = self._queue.get()
            if raw is None:
                return
            try:
                self._file.write(pack_chunk(raw))
            except BaseException as e:  # noqa: BLE001 -- reported by close()
                self._error = e

    def _hand_over(self) -> None:
        if self.buf:
            self.raw_bytes += len(self.buf)
            self._queue.put(bytes(self.buf))
            self.buf = bytearray()

    # Events --------------------------------------------------------------------------------------
    def emit(self, kind: int, port: int, *fixed: int, data: bytes | None = None) -> None:
        """Append one event: the tag, the fixed fields, and (variable kinds) the length and the bytes."""
        if data is None:
            self.buf += _FIXED_PACK[kind](kind << 2 | port, *fixed)
        else:
            self.buf += _VAR_PACK[kind](kind << 2 | port, *fixed, len(data))
            self.buf += data
        self.events += 1

    def u8(self, tag: int, value: int) -> None:
        """Append an event of a one-byte payload (the tag names its kind and port)."""
        self.buf += _U8_PACK(tag, value)
        self.events += 1

    def u32(self, tag: int, value: int) -> None:
        """Append an event of a u32 payload."""
        self.buf += _U32_PACK(tag, value)
        self.events += 1

    def clock(self, t: int) -> None:
        """Append a clock reading."""
        self.buf += _CLOCK_PACK(_CLOCK_TAG, t)
        self.events += 1

    def read(self, tag: int, data: bytes) -> None:
        """Append the bytes a read returned."""
        buf = self.buf
        buf += _READ_PACK(tag, len(data))
        buf += data
        self.events += 1

    def write(self, tag: int, accepted: int, data: bytes) -> None:
        """Append a write: how many bytes the port accepted, the bytes written."""
        buf = self.buf
        buf += _WRITE_PACK(tag, accepted, len(data))
        buf += data
        self.events += 1

    def job(self, task_id: int, start_cycles: int, index: int) -> None:
        """A new section: the events after this belong to job `index` of task `task_id`, started at `start_cycles`."""
        if len(self.buf) >= CHUNK_BYTES:
            self._hand_over()  # chunks end on a section boundary
        self.jobs += 1
        self.events += 1
        self.buf += _JOB_PACK(0, task_id, start_cycles, index)

    def raised(self, kind: int, port: int, exc: HalError) -> None:
        """The call of `kind` on `port` raised `exc` (the replay raises it again there)."""
        self.emit(Kind.RAISE, port, kind, data=str(exc).encode("utf-8"))

    def close(self, footer: dict) -> None:
        """Hand over the last events, wait for the writer, write the end mark and the footer. Twice is harmless."""
        if self.closed:
            return
        self.closed = True
        self._hand_over()
        self._queue.put(None)
        self._writer_thread.join()
        footer = {**footer, "events": self.events, "jobs": self.jobs, "raw_bytes": self.raw_bytes}
        try:
            self._file.write(pack_end(footer))
        finally:
            self._file.close()
        if self._error is not None:
            err = self._error
            raise OSError(getattr(err, "errno", None) or errno.EIO, getattr(err, "strerror", None) or str(err),
                          str(self.path)) from err

    # Wrapping the board ---------------------------------------------------------------------------
    def board(self, board: Board) -> Board:
        """The board the firmware gets: every peripheral and the clock recording through this recorder."""
        return replace(board, motor_uart=RecordingUart(board.motor_uart, self, PORTS["motor"]),
                       imu_uart=RecordingUart(board.imu_uart, self, PORTS["imu"]),
                       telemetry_uart=RecordingUart(board.telemetry_uart, self, PORTS["telemetry"]),
                       encoder=RecordingEncoder(board.encoder, self), estop=RecordingPin(board.estop, self),
                       led=RecordingLed(board.led, self), watchdog=RecordingWatchdog(board.watchdog, self),
                       now_cycles=RecordingClock(board.now_cycles, self),
                       can=None if board.can is None else RecordingCan(board.can, self))

    def health(self, kernel_health: Callable[[], tuple[int, int]]) -> Callable[[], tuple[int, int]]:
        """The firmware's view of the kernel's deadline health, recorded at each reading."""
        return RecordingHealth(kernel_health, self)


class SectionedBody:
    """A task body that opens its job's section in the record first (`Recorder.job`), then runs the body."""

    def __init__(self, rec: Recorder, task_id: int, body: Callable[[Any], object]) -> None:
        """Sections of task `task_id` (its index in the task names the record's header lists)."""
        self.rec, self.task_id, self.body = rec, task_id, body

    def __call__(self, job: Any) -> object:
        """Open the section of `job` (an rtos.Job: its start and index), then run the body."""
        self.rec.job(self.task_id, job.start, job.index)
        return self.body(job)


class RecordingClock:
    """Board.now_cycles, each reading recorded."""

    def __init__(self, clock: Callable[[], int], rec: Recorder) -> None:
        """Wrap `clock`."""
        self.inner, self.rec = clock, rec

    def __call__(self) -> int:
        """The inner reading, recorded."""
        t: int = self.inner()
        self.rec.clock(t)
        return t


class RecordingHealth:
    """The kernel's deadline health as the firmware reads it, each reading recorded."""

    def __init__(self, health: Callable[[], tuple[int, int]], rec: Recorder) -> None:
        """Wrap `health`."""
        self.inner, self.rec = health, rec

    def __call__(self) -> tuple[int, int]:
        """The inner reading, recorded."""
        misses, streak = self.inner()
        rec = self.rec
        rec.buf += _HEALTH_PACK(_HEALTH_TAG, misses, streak)
        rec.events += 1
        return misses, streak


class RecordingUart(Uart):
    """Forwards to `inner`; records each call's result (reads' bytes, counts, errors) and each write."""

    def __init__(self, inner: Uart, rec: Recorder, port: int) -> None:
        """Same baud and name as `inner`."""
        super().__init__(inner.baud, name=inner.name)
        self.inner, self.rec, self.port = inner, rec, port
        self._write_tag, self._read_tag = _tag(Kind.WRITE, port), _tag(Kind.READ, port)
        self._rx_tag, self._tx_tag = _tag(Kind.IN_WAITING, port), _tag(Kind.TX_FREE, port)
        self._flush_tag = _tag(Kind.FLUSH, port)

    def _send(self, data: bytes) -> int:
        try:
            n = self.inner.write(data)
        except HalError as e:
            self.rec.raised(Kind.WRITE, self.port, e)
            raise
        self.rec.write(self._write_tag, n, data)
        return n

    def _receive(self, max_bytes: int) -> bytes:
        try:
            data = self.inner.read(max_bytes)
        except HalError as e:
            self.rec.raised(Kind.READ, self.port, e)
            raise
        self.rec.read(self._read_tag, data)
        return data

    def _rx_count(self) -> int:
        try:
            n = self.inner.in_waiting()
        except HalError as e:
            self.rec.raised(Kind.IN_WAITING, self.port, e)
            raise
        self.rec.u32(self._rx_tag, n)
        return n

    def _tx_space(self) -> int:
        try:
            n = self.inner.tx_free()
        except HalError as e:
            self.rec.raised(Kind.TX_FREE, self.port, e)
            raise
        self.rec.u32(self._tx_tag, n)
        return n

    def _drain(self, timeout_s: float) -> bool:
        try:
            ok = self.inner.flush(timeout_s)
        except HalError as e:
            self.rec.raised(Kind.FLUSH, self.port, e)
            raise
        self.rec.u8(self._flush_tag, ok)
        return ok

    def _refresh_errors(self) -> None:
        e = self.inner.errors
        rec = self.rec
        rec.buf += _ERRORS_PACK(_tag(Kind.ERRORS, self.port), e.overrun, e.framing, e.noise, e.tx_dropped, e.rx_lost)
        rec.events += 1
        self._errors = e

    def _close(self) -> None:
        self.inner.close()


class RecordingEncoder(EncoderTimer):
    """Forwards to `inner`; records CNT and DIR readings and CNT writes."""

    def __init__(self, inner: EncoderTimer, rec: Recorder) -> None:
        """Same width and auto-reload as `inner`."""
        super().__init__(inner.bits, inner.arr)
        self.inner, self.rec = inner, rec

    def cnt(self) -> int:
        """The inner CNT, recorded."""
        v = self.inner.cnt()
        self.rec.u32(_ENC_CNT_TAG, v)
        return v

    def counting_down(self) -> bool:
        """The inner DIR bit, recorded."""
        v = self.inner.counting_down()
        self.rec.u8(_ENC_DIR_TAG, v)
        return v

    def _write_cnt(self, value: int) -> None:
        self.inner.set_cnt(value)
        self.rec.u32(_ENC_SET_TAG, value)


class RecordingPin(DigitalIn):
    """The e-stop input, each reading recorded."""

    def __init__(self, inner: DigitalIn, rec: Recorder) -> None:
        """Wrap `inner`."""
        self.inner, self.rec = inner, rec

    def read(self) -> bool:
        """The inner level, recorded."""
        v = self.inner.read()
        self.rec.u8(_ESTOP_TAG, v)
        return v


class RecordingLed(DigitalOut):
    """The status LED: each level driven is recorded (an output)."""

    def __init__(self, inner: DigitalOut, rec: Recorder) -> None:
        """Start at the inner pin's level."""
        super().__init__(inner.level)
        self.inner, self.rec = inner, rec

    def _drive(self, level: bool) -> None:
        self.inner.write(level)
        self.rec.u8(_LED_TAG, level)


class RecordingWatchdog(Watchdog):
    """The watchdog: each kick is recorded (an output)."""

    def __init__(self, inner: Watchdog, rec: Recorder) -> None:
        """Wrap `inner`."""
        self.inner, self.rec = inner, rec

    def kick(self) -> None:
        """Kick the inner watchdog and record it."""
        self.inner.kick()
        self.rec.buf += _KICK
        self.rec.events += 1


class RecordingCan(CanPort):
    """Forwards to `inner`; records each frame received (or none), each frame sent and its outcome."""

    def __init__(self, inner: CanPort, rec: Recorder) -> None:
        """Same bit rate, name and error counters as `inner`."""
        super().__init__(inner.bitrate, inner.name)
        self.errors = inner.errors
        self.inner, self.rec = inner, rec
        self._port = PORTS["can"]
        self._rx_tag, self._tx_tag = _tag(Kind.CAN_RX, self._port), _tag(Kind.CAN_TX, self._port)

    def _send(self, frame: CanFrame) -> bool:
        try:
            ok = self.inner.send(frame)
        except HalError as e:
            self.rec.raised(Kind.CAN_TX, self._port, e)
            raise
        rec, data = self.rec, frame.data
        rec.buf += _CAN_TX_PACK(self._tx_tag, ok, frame.extended, frame.arbitration_id, len(data))
        rec.buf += data
        rec.events += 1
        return ok

    def _receive(self) -> CanFrame | None:
        try:
            frame = self.inner.receive()
        except HalError as e:
            self.rec.raised(Kind.CAN_RX, self._port, e)
            raise
        rec = self.rec
        if frame is None:
            rec.buf += _CAN_RX_PACK(self._rx_tag, 0, 0, 0)
        else:
            data = frame.data
            rec.buf += _CAN_RX_PACK(self._rx_tag, 1 | (2 if frame.extended else 0), frame.arbitration_id, len(data))
            rec.buf += data
        rec.events += 1
        return frame

    def _tx_pending(self) -> int:
        n = self.inner.tx_pending()
        self.rec.u32(_tag(Kind.CAN_PENDING, self._port), n)
        return n

    def _drain(self, timeout_s: float) -> bool:
        ok = self.inner.flush(timeout_s)
        self.rec.u8(_tag(Kind.CAN_FLUSH, self._port), ok)
        return ok

    def _close(self) -> None:
        self.inner.close()
