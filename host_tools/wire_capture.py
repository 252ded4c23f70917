"""Wire capture: the raw bytes of every port in each direction, and an index that lines them up in time.

A capture directory holds, per port (``motor``, ``imu``, ``telemetry``) and direction:

* ``<port>.tx.bin`` / ``<port>.rx.bin``: the bytes this process wrote to / read from the port, raw and in
  order, so ``pafp decode`` reads them as they are;
* ``index.csv``: one row per read or write that moved bytes: ``t_s,file,offset,bytes``: at ``t_s``
  (seconds on the run's clock: virtual time in a virtual run, wall time since the start otherwise)
  ``bytes`` bytes went to ``file`` starting at ``offset``;
* ``<port>.can.log`` for a port on a CAN bus: every frame sent (``T``) and received (``R``), one line each in
  candump's ``-L`` format with python-can's direction flag, ``(t_s) can0 ID#DATA T``, which python-can's
  ``can.LogReader`` and the can-utils tools (``canplayer``, ``log2asc``) read;
* ``capture.json`` (written on close): per file its byte count, protocol and the ``pafp decode`` command
  that reads it (for a ``.can.log``: its frame count and how to read it). Which way a file goes depends on
  the side: the firmware's ``motor.tx.bin`` is to-motor, the emulated motor's ``motor.tx.bin``
  (``pafp emulate --capture``) is from-motor.

Files are appended as the run goes and flushed every ``FLUSH_EVERY`` records and on close, so a run that
dies leaves them valid up to the last flush. A write that fails (a full disk) raises once, naming the file,
and ends the capture: ``error`` keeps it, later records and the close do nothing more (the caller reports it,
exit 74). Reference: docs/serial_mode.md, "Wire capture".
"""

from __future__ import annotations

import json
from collections.abc import Callable, Iterator
from contextlib import contextmanager, suppress
from dataclasses import replace
from pathlib import Path
from typing import BinaryIO, TextIO

from hal.can import CanFrame, CanPort
from hal.interfaces import Board, Uart
from host_tools.outdir import naming, write_atomic

__all__ = ["TapCanPort", "TapUart", "WireCapture", "candump_line"]

FLUSH_EVERY = 256
PROTOCOLS = {"motor": "vesc", "imu": "rvc", "telemetry": "telemetry"}
# the `pafp decode --direction` of a motor file, by the side that captured it and the file's direction
_VESC_DIRECTION = {("host", "tx"): "to-motor", ("host", "rx"): "from-motor",
                   ("device", "tx"): "from-motor", ("device", "rx"): "to-motor"}


class WireCapture:
    """Raw per-port, per-direction byte files plus a time index, in `directory`."""

    def __init__(self, directory: Path, clock_s: Callable[[], float], side: str = "host") -> None:
        """Create `directory` (it must not hold an earlier capture); `side` is 'host' or 'device'."""
        if side not in ("host", "device"):
            raise ValueError(f"capture side {side!r} invalid: 'host' (the firmware) or 'device' (an emulator)")
        directory.mkdir(parents=True, exist_ok=True)
        if (directory / "index.csv").exists():
            raise ValueError(f"capture directory {str(directory)!r} already holds a capture (index.csv): "
                             "give an empty or new directory")
        self.directory = directory
        self.clock_s = clock_s
        self.side = side
        self._files: dict[str, BinaryIO] = {}
        self._sizes: dict[str, int] = {}
        self._index: TextIO = (directory / "index.csv").open("w", encoding="ascii", newline="")
        self._index.write("t_s,file,offset,bytes\n")
        self._can_logs: dict[str, TextIO] = {}
        self._can_frames: dict[str, int] = {}
        self._can_protocols: dict[str, str] = {}
        self._unflushed = 0
        self.closed = False
        self.error: OSError | None = None  # the write that failed and ended the capture

    def open(self, port: str, *directions: str) -> None:
        """Create the files of `port` for `directions` ('tx', 'rx') now, so an idle direction is an empty file."""
        for d in directions:
            self._file(f"{port}.{d}.bin")

    def _file(self, name: str) -> BinaryIO:
        f = self._files.get(name)
        if f is None:
            f = self._files[name] = (self.directory / name).open("wb")
            self._sizes[name] = 0
        return f

    def record(self, port: str, direction: str, data: bytes, t_s: float | None = None) -> None:
        """Append `data` moved on `port` in `direction` ('tx' or 'rx') at `t_s` (default: now)."""
        if not data or self.closed:
            return
        name = f"{port}.{direction}.bin"
        with self._failing(name):
            f = self._file(name)
            f.write(data)
        offset = self._sizes[name]
        self._sizes[name] = offset + len(data)
        t = self.clock_s() if t_s is None else t_s
        with self._failing("index.csv"):
            self._index.write(f"{t:.9f},{name},{offset},{len(data)}\n")
        self._unflushed += 1
        if self._unflushed >= FLUSH_EVERY:
            self.flush()

    @contextmanager
    def _failing(self, name: str) -> Iterator[None]:
        """An OSError inside names the file `name`, is kept in ``error`` and ends the capture (raised once)."""
        try:
            with naming(self.directory / name):
                yield
        except OSError as exc:
            self.error = exc
            self.closed = True
            raise

    def record_frame(self, port: str, frame: CanFrame, received: bool, t_s: float | None = None) -> None:
        """Append one CAN frame sent (received False) or received on `port` to `<port>.can.log`."""
        if self.closed:
            return
        name = f"{port}.can.log"
        with self._failing(name):
            log = self._can_logs.get(name)
            if log is None:
                log = self._can_logs[name] = (self.directory / name).open("w", encoding="ascii", newline="\n")
                self._can_frames[name] = 0
            log.write(candump_line(self.clock_s() if t_s is None else t_s, frame, received))
        self._can_frames[name] += 1
        self._unflushed += 1
        if self._unflushed >= FLUSH_EVERY:
            self.flush()

    def flush(self) -> None:
        """Push everything recorded so far to the files."""
        for name, f in [*self._files.items(), *self._can_logs.items()]:
            with self._failing(name):
                f.flush()
        with self._failing("index.csv"):
            self._index.flush()
        self._unflushed = 0

    def tap(self, port: str, uart: Uart) -> TapUart:
        """`uart` seen through a tap that records what crosses it as `port`."""
        self.open(port, "tx", "rx")
        return TapUart(uart, self, port)

    def tap_can(self, port: str, can_port: CanPort, protocol: str = "can") -> TapCanPort:
        """`can_port` seen through a tap that logs every frame to `<port>.can.log` (`protocol` for capture.json)."""
        name = f"{port}.can.log"
        self._can_protocols[name] = protocol
        if name not in self._can_logs:
            self._can_logs[name] = (self.directory / name).open("w", encoding="ascii", newline="\n")
            self._can_frames[name] = 0
        return TapCanPort(can_port, self, port)

    def tap_board(self, board: Board) -> Board:
        """The board with its three UARTs tapped (the firmware gets this one)."""
        return replace(board, motor_uart=self.tap("motor", board.motor_uart),
                       imu_uart=self.tap("imu", board.imu_uart),
                       telemetry_uart=self.tap("telemetry", board.telemetry_uart))

    def manifest(self) -> dict:
        """Per file: bytes, protocol and how to decode it."""
        files = {}
        for name in sorted(self._sizes):
            port, direction, _ = name.split(".")
            protocol = PROTOCOLS.get(port, "raw")
            cmd = f"pafp decode --protocol {protocol}"
            if protocol == "vesc":
                cmd += f" --direction {_VESC_DIRECTION[self.side, direction]}"
            files[name] = {"bytes": self._sizes[name], "port": port, "direction": direction,
                           "protocol": protocol, "decode": f"{cmd} {name}"}
        for name in sorted(self._can_frames):
            files[name] = {"frames": self._can_frames[name], "port": name.split(".")[0], "direction": "both (T/R)",
                           "protocol": self._can_protocols.get(name, "can"), "format": "candump -L",
                           "decode": f"python -c \"import can; print(*can.LogReader('{name}'), sep=chr(10))\""}
        return {"side": self.side, "clock": "seconds since the run's start", "files": files}

    def close(self) -> None:
        """Flush and close every file; write capture.json (atomically). Closing twice is harmless."""
        if self.closed:
            if self.error is not None:  # a failed capture: let go of the files, say nothing more
                for f in [*self._files.values(), *self._can_logs.values(), self._index]:
                    with suppress(OSError):
                        f.close()
            return
        for name, f in [*self._files.items(), *self._can_logs.items()]:
            with self._failing(name):
                f.close()
        with self._failing("index.csv"):
            self._index.close()
        self.closed = True
        with self._failing("capture.json"):
            write_atomic(self.directory / "capture.json", json.dumps(self.manifest(), indent=2) + "\n")


class TapUart(Uart):
    """A `Uart` that forwards to `inner` and records every byte written and read (a logic analyser on the pins)."""

    def __init__(self, inner: Uart, capture: WireCapture, port: str) -> None:
        """Same baud and name as `inner`."""
        super().__init__(inner.baud, name=inner.name)
        self.inner = inner
        self.capture = capture
        self.port = port

    def _send(self, data: bytes) -> int:
        n = self.inner.write(data)
        self.capture.record(self.port, "tx", data[:n])
        return n

    def _receive(self, max_bytes: int) -> bytes:
        data = self.inner.read(max_bytes)
        self.capture.record(self.port, "rx", data)
        return data

    def _rx_count(self) -> int:
        return self.inner.in_waiting()

    def _tx_space(self) -> int:
        return self.inner.tx_free()

    def _drain(self, timeout_s: float) -> bool:
        return self.inner.flush(timeout_s)

    def _refresh_errors(self) -> None:
        self._errors = self.inner.errors  # the inner port's counters (it counted the refused bytes too)

    def _close(self) -> None:
        self.inner.close()


def candump_line(t_s: float, frame: CanFrame, received: bool) -> str:
    """One frame as a line of ``candump -L`` with python-can's direction flag (R received, T sent).

    >>> candump_line(0.5, CanFrame(0x101, bytes([0, 0, 0, 0]), True), False)
    '(0.500000) can0 00000101#00000000 T\\n'
    >>> candump_line(1.25, CanFrame(0x1, b"\\xff"), True)
    '(1.250000) can0 001#FF R\\n'
    """
    ident = f"{frame.arbitration_id:08X}" if frame.extended else f"{frame.arbitration_id:03X}"
    return f"({t_s:.6f}) can0 {ident}#{frame.data.hex().upper()} {'R' if received else 'T'}\n"


class TapCanPort(CanPort):
    """A `CanPort` that forwards to `inner` and logs every frame sent and received (a bus analyser)."""

    def __init__(self, inner: CanPort, capture: WireCapture, port: str) -> None:
        """Same bit rate and name as `inner`."""
        super().__init__(inner.bitrate, inner.name)
        self.inner = inner
        self.capture = capture
        self.port = port
        self.errors = inner.errors

    def send(self, frame: CanFrame) -> bool:
        """Send through `inner` (which counts a refusal in the errors both share) and log the frame if sent."""
        self._check_open()
        ok = self.inner.send(frame)
        if ok:
            self.capture.record_frame(self.port, frame, False)
        return ok

    def _send(self, frame: CanFrame) -> bool:
        return self.inner.send(frame)  # not reached: send is the tap's own

    def _receive(self) -> CanFrame | None:
        frame = self.inner.receive()
        if frame is not None:
            self.capture.record_frame(self.port, frame, True)
        return frame

    @property
    def echoes(self) -> int:
        """The inner port's own frames handed back by the bus and dropped (hal.pycan), if it counts them."""
        return int(getattr(self.inner, "echoes", 0))

    def _tx_pending(self) -> int:
        return self.inner.tx_pending()

    def _drain(self, timeout_s: float) -> bool:
        return self.inner.flush(timeout_s)

    def _close(self) -> None:
        self.inner.close()
