"""Serial mode's watchdog outside the control loop: the safe frames go out when the loop stops kicking.

On the STM32 an independent watchdog (IWDG) resets the MCU when the firmware stops kicking it. On the
host the whole control loop is one Python thread: a controller stuck in ``update`` (a loop, a sleep, a
blocking call) stalls the supervisor and the stop path with it, and nothing stops the motor before its
own 1 s command timeout. :class:`HostWatchdog` is a second thread. The firmware's watchdog task kicks it
(the board's watchdog handle, once per kick period when the control task has run); when no kick has come
for ``timeout_s`` it writes the stop frames (the profile's safe state, firmware/safe_state.py), pre-built at
start-up by the motor driver's own stop path, on a handle of its own (a duplicate of the UART's file descriptor, or a
second python-can bus on the same channel), asks the loop to stop at its next scheduling point, and writes
them again every ``timeout_s`` while the loop stays silent (the motor's own timeout would end the safe
behaviour). Limits: a thread needs the interpreter's lock, which a pure-Python loop hands over every switch
interval (5 ms) but C code that holds it does not; ports the loop serves in-process (``sim://``) stall
with the loop, so there the watchdog is not armed. docs/serial_mode.md, "The host watchdog".
"""

from __future__ import annotations

import logging
import os
import termios
import threading
import time
from collections.abc import Callable
from dataclasses import dataclass

from firmware.config import FirmwareConfig
from firmware.drivers.motor_links import make_motor_driver
from firmware.safe_state import SafePolicy
from hal.can import CanFrame, CanPort
from hal.errors import HalError
from hal.interfaces import Board, Uart
from hal.pycan import PythonCanPort, is_can_url, open_can, parse_can_url
from hal.serial.backend import SerialUart
from hal.virtual.null import NullUart

__all__ = ["CanSender", "FdSender", "HostWatchdog", "WatchdogRecord", "arm_watchdog", "stop_frames"]

log = logging.getLogger(__name__)

WRITE_TIMEOUT_S = 0.05  # the watchdog's own write gives up after this long (a port that takes nothing)


class _RecordingUart(NullUart):
    """Accepts every write and keeps the bytes (the stop frames, pre-built by the driver)."""

    def __init__(self, baud: int) -> None:
        super().__init__(baud, "stop-frames")
        self.data = bytearray()

    def _send(self, data: bytes) -> int:
        self.data += data
        return len(data)


class _RecordingCan(CanPort):
    """Accepts every frame and keeps it."""

    def __init__(self, bitrate: int) -> None:
        super().__init__(bitrate, "stop-frames")
        self.frames: list[CanFrame] = []

    def _send(self, frame: CanFrame) -> bool:
        self.frames.append(frame)
        return True

    def _receive(self) -> CanFrame | None:
        return None


def stop_frames(board: Board, config: FirmwareConfig) -> tuple[bytes, list[CanFrame]]:
    """The bytes (UART) and frames (CAN) the firmware's stop path sends, built by the very driver on a recorder."""
    uart = _RecordingUart(board.motor_uart.baud)
    can = _RecordingCan(board.can.bitrate) if board.can is not None else None
    rec = Board(motor_uart=uart, imu_uart=board.imu_uart, telemetry_uart=board.telemetry_uart,
                encoder=board.encoder, estop=board.estop, led=board.led, watchdog=board.watchdog,
                now_cycles=board.now_cycles, f_cpu_hz=board.f_cpu_hz, can=can)
    driver = make_motor_driver(rec, config)
    stop = SafePolicy.of(config.safety, driver.SAFE_BEHAVIOURS, config.motor_link).stop_command()
    driver.send_stop(0.0, stop, WRITE_TIMEOUT_S)
    return bytes(uart.data), list(can.frames) if can is not None else []


class FdSender:
    """Writes pre-built bytes on a duplicate of a port's file descriptor, then waits for the line to drain."""

    def __init__(self, uart: SerialUart, data: bytes) -> None:
        """Duplicate the port's descriptor now (OSError, ValueError if the port has none)."""
        fd = uart.serial.fileno()
        self.fd = os.dup(fd)
        self.data = data
        self.handle = f"duplicate of fd {fd} ({uart.url})"

    def send(self) -> int:
        """Write every byte (a non-blocking descriptor is retried up to WRITE_TIMEOUT_S); the bytes written."""
        view, done = memoryview(self.data), 0
        deadline = time.monotonic() + WRITE_TIMEOUT_S
        while done < len(view):
            try:
                done += os.write(self.fd, view[done:])
            except BlockingIOError:
                if time.monotonic() > deadline:
                    break
                time.sleep(0.0002)
        try:
            termios.tcdrain(self.fd)
        except termios.error:
            pass  # not a tty (a socket, a pipe): the bytes are with the kernel
        return done

    def close(self) -> None:
        """Close the duplicate."""
        os.close(self.fd)


class CanSender:
    """Sends pre-built frames on a python-can bus of its own, on the motor's channel."""

    def __init__(self, port: PythonCanPort, frames: list[CanFrame]) -> None:
        """Own `port` (a second bus opened on the same channel)."""
        self.port = port
        self.frames = frames
        self.handle = f"second bus on {port.name}"

    def send(self) -> int:
        """Send every frame; the data bytes sent."""
        sent = 0
        for f in self.frames:
            if self.port.send(f):
                sent += len(f.data)
        self.port.flush(WRITE_TIMEOUT_S)
        return sent

    def close(self) -> None:
        """Shut the bus down."""
        self.port.close()


@dataclass
class WatchdogRecord:
    """What the host watchdog did (summary.json["host_watchdog"])."""

    armed: bool
    timeout_ms: float
    handle: str = ""  # what it writes on, or why it is not armed
    fired_at_s: float | None = None  # run time of its first write
    silent_ms: float | None = None  # time since the last kick at its first write: the measured bound
    task: str | None = None  # the job running when it fired
    sends: int = 0
    bytes_sent: int = 0
    error: str | None = None

    def as_dict(self) -> dict[str, object]:
        """For summary.json."""
        return {"armed": self.armed, "timeout_ms": self.timeout_ms, "handle": self.handle,
                "fired": self.fired_at_s is not None, "fired_at_s": self.fired_at_s, "silent_ms": self.silent_ms,
                "task": self.task, "sends": self.sends, "bytes_sent": self.bytes_sent, "error": self.error}


class HostWatchdog:
    """A thread that sends the stop frames when ``kick`` has not been called for ``timeout_s``."""

    def __init__(self, timeout_s: float, sender: FdSender | CanSender, on_fire: Callable[[], None],
                 running: Callable[[], str | None] = lambda: None,
                 clock: Callable[[], float] = time.perf_counter) -> None:
        """Not started; ``on_fire`` (ask the loop to stop) must be safe from another thread: set a flag."""
        self.timeout_s = timeout_s
        self.sender = sender
        self.on_fire = on_fire
        self.running = running
        self.clock = clock
        self.t0 = clock()
        self.record = WatchdogRecord(True, round(timeout_s * 1e3, 3), sender.handle)
        self._last = self.t0
        self._halt = threading.Event()  # wakes the thread to end (close)
        self._halted = False  # no more writes (halt: a flag, so the stop path does not wait for the thread to run)
        self._sending = threading.Lock()  # held while writing: halt() waits for a write under way
        self._thread = threading.Thread(target=self._watch, name="pafp-host-watchdog", daemon=True)

    def start(self) -> None:
        """Count from now (the run's time 0 for the record) and start watching."""
        self.t0 = self._last = self.clock()
        self._thread.start()

    def kick(self) -> None:
        """The loop is alive (called from the loop's thread)."""
        self._last = self.clock()

    def _watch(self) -> None:
        sent_at: float | None = None
        while True:
            now = self.clock()
            last = self._last
            due = last + self.timeout_s if sent_at is None or sent_at < last else sent_at + self.timeout_s
            if now < due:
                if self._halt.wait(due - now):
                    return
                continue
            with self._sending:
                if self._halted:
                    return
                self._fire(now, last)
            sent_at = self.clock()

    def _fire(self, now: float, last: float) -> None:
        r = self.record
        try:
            r.bytes_sent += self.sender.send()
        except (OSError, HalError) as exc:
            r.error = r.error or f"{type(exc).__name__}: {exc}"
        r.sends += 1
        if r.fired_at_s is None:
            r.fired_at_s = round(now - self.t0, 6)
            r.silent_ms = round((self.clock() - last) * 1e3, 3)
            r.task = self.running()
            self.on_fire()
            log.error("host watchdog: no kick for %.0f ms (task %s running): sent the safe state's frames",
                      r.silent_ms, r.task)

    def halt(self) -> WatchdogRecord:
        """Stop writing: once this returns nothing more is sent (a write under way is waited for). Call it
        before the stop path writes, so the stop path's frames are the last on the wire."""
        with self._sending:
            self._halted = True
        return self.record

    def close(self) -> WatchdogRecord:
        """Halt, wait for the thread to end, release the handle."""
        self.halt()
        self._halt.set()
        if self._thread.is_alive():
            self._thread.join()
        self.sender.close()
        return self.record


def arm_watchdog(motor: Uart, motor_url: str, board: Board, config: FirmwareConfig, on_fire: Callable[[], None],
                 running: Callable[[], str | None] = lambda: None) -> HostWatchdog | WatchdogRecord:
    """A watchdog on a handle of its own to the motor (not started), or the record of why there is none.

    `motor` is the motor's UART as opened (not a capture's tap); over CAN (`motor_url` can://...) a second
    bus is opened on the URL's channel.
    """
    record = WatchdogRecord(False, round(config.host_watchdog_s * 1e3, 3))
    data, frames = stop_frames(board, config)
    sender: FdSender | CanSender
    try:
        if is_can_url(motor_url):
            sender = CanSender(open_can(parse_can_url(motor_url, "--motor")), frames)
        elif isinstance(motor, SerialUart):
            sender = FdSender(motor, data)
        else:
            record.handle = (f"not armed: the motor port {motor.name!r} is served in this process and stalls with "
                             "the loop")
            return record
    except (OSError, ValueError, AttributeError, HalError) as exc:  # no descriptor to duplicate, no second bus
        record.handle = f"not armed: {type(exc).__name__}: {exc}"
        return record
    return HostWatchdog(config.host_watchdog_s, sender, on_fire, running)
