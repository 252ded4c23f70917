"""Start-up checks of serial mode: open each port and make sure the right device answers, within 1 s.

A port that cannot be opened, a port on which nothing valid arrives (wrong baud rate, garbage) and a
device that speaks another protocol each give one `StartupError` naming the port and what was
expected. Nothing is written to the output directory before these checks pass.
"""

from __future__ import annotations

import logging
import time
from collections.abc import Callable

from firmware.drivers.motor import FEEDBACK_MASK
from hal.errors import HalError
from hal.interfaces import Uart
from protocol.rvc import RvcDecoder
from protocol.telemetry import TelemetryDecoder
from protocol.vesc import Decoder, GetValuesSelective, Values, ValuesSelective

__all__ = ["EXPECTED", "StartupError", "check_imu", "check_motor", "identify"]

log = logging.getLogger(__name__)

EXPECTED = {
    "motor": "an AK60-6 answering VESC servo-mode requests (GET_VALUES_SELECTIVE)",
    "imu": "a BNO08x streaming UART-RVC frames (0xAAAA header, 100 Hz)",
}
REQUEST_EVERY_S = 0.1


class StartupError(Exception):
    """A port failed its start-up check; the message names the port and what was expected."""


def identify(data: bytes) -> str | None:
    """Name the protocol that `data` carries valid frames of ('VESC', 'UART-RVC', 'pafp telemetry'), or None.

    >>> print(identify(b"junk"))
    None
    """
    if Decoder("from-motor").feed(data):
        return "VESC"
    if RvcDecoder().feed(data):
        return "UART-RVC"
    if TelemetryDecoder().feed(data):
        return "pafp telemetry"
    return None


def _verdict(role: str, port: str, baud: int, seen: bytes, timeout_s: float) -> StartupError:
    """The error for a port on which no valid frame of the expected protocol came in time."""
    want = EXPECTED[role]
    if not seen:
        return StartupError(f"{role} port {port!r}: silent for {timeout_s:g} s; expected {want} at {baud} baud")
    other = identify(seen)
    if other is not None:
        return StartupError(f"{role} port {port!r}: the device speaks {other}, not what was expected: {want}")
    return StartupError(f"{role} port {port!r}: {len(seen)} bytes but no valid frame in {timeout_s:g} s "
                        f"(wrong baud rate? not {baud}?); expected {want}")


def check_motor(uart: Uart, port: str, *, timeout_s: float = 1.0,
                clock: Callable[[], float] = time.monotonic, sleep: Callable[[float], None] = time.sleep) -> int:
    """Ask for feedback until a valid VESC reply comes; return the bytes seen; StartupError otherwise."""
    decoder = Decoder("from-motor")
    return _await_valid("motor", uart, port,
                        lambda data: any(isinstance(m, (ValuesSelective, Values)) for m in decoder.feed(data)),
                        GetValuesSelective(FEEDBACK_MASK).encode(), timeout_s, clock, sleep)


def check_imu(uart: Uart, port: str, *, timeout_s: float = 1.0,
              clock: Callable[[], float] = time.monotonic, sleep: Callable[[float], None] = time.sleep) -> int:
    """Listen until a valid UART-RVC frame comes; return the bytes seen; StartupError otherwise."""
    decoder = RvcDecoder()
    return _await_valid("imu", uart, port, lambda data: bool(decoder.feed(data)), None, timeout_s, clock, sleep)


def _await_valid(role: str, uart: Uart, port: str, valid: Callable[[bytes], bool], request: bytes | None,
                 timeout_s: float, clock: Callable[[], float], sleep: Callable[[float], None]) -> int:
    """Read (writing ``request`` every REQUEST_EVERY_S if given) until ``valid(data)``; return the bytes seen.

    StartupError naming the port and what was expected if the port fails or nothing valid comes in time.
    """
    seen = bytearray()
    t0 = clock()
    next_request = t0
    try:
        while clock() - t0 < timeout_s:
            if request is not None and clock() >= next_request:
                uart.write(request)
                next_request += REQUEST_EVERY_S
            data = uart.read()
            seen += data
            if valid(data):
                log.info("%s port %s answered after %.1f ms", role, port, (clock() - t0) * 1e3)
                return len(seen)
            sleep(0.002)
    except HalError as exc:
        raise StartupError(f"{role} port {port!r}: {exc}; expected {EXPECTED[role]}") from exc
    raise _verdict(role, port, uart.baud, bytes(seen), timeout_s)
