"""The recorder: wraps the peripherals and the clock the firmware is handed and writes what they returned.

Every call the firmware makes on its `Board` goes through a recording peripheral that forwards it to the
real one (a pyserial port, the virtual MCU) and appends one event: the bytes each read returned, the
counts, the encoder's CNT, the pin levels, every clock reading, the kernel's deadline health, the
HalErrors raised; and what the firmware sent (writes, kicks, LED levels), so a replay can compare. The
composition root marks where each job starts (`Recorder.job`) so the replay can run the same job on the
same inputs. Events are packed in memory and handed, one chunk at a time, to a writer thread that
compresses and writes them (hal/record/format.py), so the firmware's loop never waits on zlib or the disk.
"""

from __future__ import annotations

import errno
import queue
import struct
import threading
from collections.abc import Callable
from dataclasses import replace
from pathlib import Path
from typing import Any

from hal.can import CanFrame, CanPort
from hal.errors import HalError
from hal.interfaces import Board, DigitalIn, DigitalOut, EncoderTimer, Uart, Watchdog
from hal.record.format import CHUNK_BYTES, FIXED, VARIABLE, Kind, pack_chunk, pack_end, write_header

__all__ = ["PORTS", "Recorder"]

PORTS = {"motor": 0, "imu": 1, "telemetry": 2, "can": 3}
_QUEUE_CHUNKS = 16  # chunks waiting for the writer at most (bounded memory); the loop blocks beyond that
# per kind, one packer of the tag byte and the fixed part (and, variable kinds, the length): one call per event
_FIXED_PACK = {k: struct.Struct("<B" + st.format.lstrip("<")).pack for k, st in FIXED.items()}
_VAR_PACK = {k: struct.Struct("<B" + st.format.lstrip("<") + "H").pack for k, st in VARIABLE.items()}
_JOB_PACK = _FIXED_PACK[Kind.JOB]


class Recorder:
    """Writes the inputs the firmware saw into `path`, in sections opened by `job` (one per task job)."""

    def __init__(self, path: Path, header: dict) -> None:
        """Create `path` and write the header (what was run: the replay rebuilds the firmware from it)."""
        self.path = path
        self._file = path.open("wb")
        write_header(self._file, header)
        self._buf = bytearray()
        self._queue: queue.Queue[bytes | None] = queue.Queue(_QUEUE_CHUNKS)
        self._error: BaseException | None = None
        self._thread = threading.Thread(target=self._writer, name="pafp-record-writer", daemon=True)
        self._thread.start()
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
        if self._buf:
            self.raw_bytes += len(self._buf)
            self._queue.put(bytes(self._buf))
            self._buf.clear()

    # Events --------------------------------------------------------------------------------------
    def emit(self, kind: int, port: int, *fixed: int, data: bytes | None = None) -> None:
        """Append one event: the tag, the fixed fields, and (variable kinds) the length and the bytes."""
        if data is None:
            self._buf += _FIXED_PACK[kind](kind << 2 | port, *fixed)
        else:
            self._buf += _VAR_PACK[kind](kind << 2 | port, *fixed, len(data))
            self._buf += data
        self.events += 1

    def job(self, task_id: int, start_cycles: int, index: int) -> None:
        """A new section: the events after this belong to job `index` of task `task_id`, started at `start_cycles`."""
        buf = self._buf
        if len(buf) >= CHUNK_BYTES:
            self._hand_over()  # chunks end on a section boundary
        self.jobs += 1
        self.events += 1
        buf += _JOB_PACK(0, task_id, start_cycles, index)

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
        self._thread.join()
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
        clock = board.now_cycles

        def now_cycles() -> int:
            t = clock()
            self.emit(Kind.CLOCK, 0, t)
            return t

        return replace(board, motor_uart=RecordingUart(board.motor_uart, self, PORTS["motor"]),
                       imu_uart=RecordingUart(board.imu_uart, self, PORTS["imu"]),
                       telemetry_uart=RecordingUart(board.telemetry_uart, self, PORTS["telemetry"]),
                       encoder=RecordingEncoder(board.encoder, self), estop=RecordingPin(board.estop, self),
                       led=RecordingLed(board.led, self), watchdog=RecordingWatchdog(board.watchdog, self),
                       now_cycles=now_cycles, can=None if board.can is None else RecordingCan(board.can, self))

    def health(self, kernel_health: Callable[[], tuple[int, int]]) -> Callable[[], tuple[int, int]]:
        """The firmware's view of the kernel's deadline health, recorded at each reading."""
        def recorded() -> tuple[int, int]:
            misses, streak = kernel_health()
            self.emit(Kind.HEALTH, 0, misses, streak)
            return misses, streak

        return recorded


def _guarded(rec: Recorder, kind: int, port: int, call: Callable[..., Any], *args: Any) -> Any:
    """call(*args); a HalError it raises is recorded as the result of this kind of call on this port, then re-raised."""
    try:
        return call(*args)
    except HalError as e:
        rec.raised(kind, port, e)
        raise


class RecordingUart(Uart):
    """Forwards to `inner`; records each call's result (reads' bytes, counts, errors) and each write."""

    def __init__(self, inner: Uart, rec: Recorder, port: int) -> None:
        """Same baud and name as `inner`."""
        super().__init__(inner.baud, name=inner.name)
        self.inner, self.rec, self.port = inner, rec, port

    def _send(self, data: bytes) -> int:
        n = _guarded(self.rec, Kind.WRITE, self.port, self.inner.write, data)
        self.rec.emit(Kind.WRITE, self.port, n, data=data)
        return n

    def _receive(self, max_bytes: int) -> bytes:
        data = _guarded(self.rec, Kind.READ, self.port, self.inner.read, max_bytes)
        self.rec.emit(Kind.READ, self.port, data=data)
        return data

    def _rx_count(self) -> int:
        n = _guarded(self.rec, Kind.IN_WAITING, self.port, self.inner.in_waiting)
        self.rec.emit(Kind.IN_WAITING, self.port, n)
        return n

    def _tx_space(self) -> int:
        n = _guarded(self.rec, Kind.TX_FREE, self.port, self.inner.tx_free)
        self.rec.emit(Kind.TX_FREE, self.port, n)
        return n

    def _drain(self, timeout_s: float) -> bool:
        ok = _guarded(self.rec, Kind.FLUSH, self.port, self.inner.flush, timeout_s)
        self.rec.emit(Kind.FLUSH, self.port, ok)
        return ok

    def _refresh_errors(self) -> None:
        e = self.inner.errors
        self.rec.emit(Kind.ERRORS, self.port, e.overrun, e.framing, e.noise, e.tx_dropped, e.rx_lost)
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
        self.rec.emit(Kind.ENC_CNT, 0, v)
        return v

    def counting_down(self) -> bool:
        """The inner DIR bit, recorded."""
        v = self.inner.counting_down()
        self.rec.emit(Kind.ENC_DIR, 0, v)
        return v

    def _write_cnt(self, value: int) -> None:
        self.inner.set_cnt(value)
        self.rec.emit(Kind.ENC_SET, 0, value)


class RecordingPin(DigitalIn):
    """The e-stop input, each reading recorded."""

    def __init__(self, inner: DigitalIn, rec: Recorder) -> None:
        """Wrap `inner`."""
        self.inner, self.rec = inner, rec

    def read(self) -> bool:
        """The inner level, recorded."""
        v = self.inner.read()
        self.rec.emit(Kind.ESTOP, 0, v)
        return v


class RecordingLed(DigitalOut):
    """The status LED: each level driven is recorded (an output)."""

    def __init__(self, inner: DigitalOut, rec: Recorder) -> None:
        """Start at the inner pin's level."""
        super().__init__(inner.level)
        self.inner, self.rec = inner, rec

    def _drive(self, level: bool) -> None:
        self.inner.write(level)
        self.rec.emit(Kind.LED, 0, level)


class RecordingWatchdog(Watchdog):
    """The watchdog: each kick is recorded (an output)."""

    def __init__(self, inner: Watchdog, rec: Recorder) -> None:
        """Wrap `inner`."""
        self.inner, self.rec = inner, rec

    def kick(self) -> None:
        """Kick the inner watchdog and record it."""
        self.inner.kick()
        self.rec.emit(Kind.KICK, 0)


def _frame_fields(frame: CanFrame | None) -> tuple[int, int, bytes]:
    if frame is None:
        return 0, 0, b""
    return 1 | (2 if frame.extended else 0), frame.arbitration_id, frame.data


class RecordingCan(CanPort):
    """Forwards to `inner`; records each frame received (or none), each frame sent and its outcome."""

    def __init__(self, inner: CanPort, rec: Recorder) -> None:
        """Same bit rate, name and error counters as `inner`."""
        super().__init__(inner.bitrate, inner.name)
        self.errors = inner.errors
        self.inner, self.rec = inner, rec
        self._port = PORTS["can"]

    def _send(self, frame: CanFrame) -> bool:
        ok = _guarded(self.rec, Kind.CAN_TX, self._port, self.inner.send, frame)
        self.rec.emit(Kind.CAN_TX, self._port, ok, frame.extended, frame.arbitration_id, data=frame.data)
        return ok

    def _receive(self) -> CanFrame | None:
        frame = _guarded(self.rec, Kind.CAN_RX, self._port, self.inner.receive)
        flags, ident, data = _frame_fields(frame)
        self.rec.emit(Kind.CAN_RX, self._port, flags, ident, data=data)
        return frame

    def _tx_pending(self) -> int:
        n = self.inner.tx_pending()
        self.rec.emit(Kind.CAN_PENDING, self._port, n)
        return n

    def _drain(self, timeout_s: float) -> bool:
        ok = self.inner.flush(timeout_s)
        self.rec.emit(Kind.CAN_FLUSH, self._port, ok)
        return ok

    def _close(self) -> None:
        self.inner.close()

