"""pyserial URL handler ``sim://``: a virtual AK60-6, BNO08x or ground-sensor board on a virtual plant, in
wall-clock time.

After :func:`register_sim_handler` (which lists ``hal.serial`` in ``serial.protocol_handler_packages``)
any pyserial program can open::

    serial.serial_for_url("sim://ak60-6?baud=921600", timeout=0.1)
    serial.serial_for_url("sim://bno08x")          # 115200, banner then RVC frames at 100 Hz
    serial.serial_for_url("sim://ground-sensors")  # 115200, a Firmata board with the load cell and FSRs

URL: ``sim://DEVICE[?baud=N&fixture=NAME&seed=S]``; DEVICE is ``ak60-6`` (alias ``motor``), ``bno08x``
(alias ``imu``), ``ground-sensors`` (alias ``firmata``: the load cell and FSRs, unloaded, behind a Firmata
board; hal/virtual/devices/firmata_board.py) or any name registered in ``hal.virtual.devices.registry.DEVICES``.
The baud is the URL's, else the port's ``baudrate`` unless that is pyserial's default 9600, else the device
model's default. The device runs on the wall clock from ``open()``: a read returns only bytes whose stop bit
has ended by now; writes go on the wire from the moment of the call. Timeouts follow
pyserial: ``timeout=None`` blocks until ``size`` bytes, ``0`` returns at once, a float waits up to that
many seconds (polling every 0.5 ms). A baud rate changed after opening is ignored (logged).
"""

from __future__ import annotations

import logging
import time
from typing import Any

import serial
from serial.serialutil import PortNotOpenError, SerialBase, SerialException, SerialTimeoutException, to_bytes

from hal.serial.sim_port import WallDevices, parse_sim_url
from hal.virtual.uart import VirtualUart

__all__ = ["POLL_S", "Serial", "register_sim_handler"]

log = logging.getLogger(__name__)

POLL_S = 0.0005
"""Sleep between two looks at the virtual line while a read or write waits."""
_PYSERIAL_DEFAULT_BAUD = 9600


def register_sim_handler() -> None:
    """Let ``serial.serial_for_url`` open ``sim://`` URLs (adds ``hal.serial`` to the handler packages once)."""
    if "hal.serial" not in serial.protocol_handler_packages:
        serial.protocol_handler_packages.append("hal.serial")


class Serial(SerialBase):
    """A pyserial port whose far end is a virtual device (see the module docstring)."""

    def __init__(self, *args: Any, **kwargs: Any) -> None:
        """As pyserial's SerialBase; the device starts when the port opens."""
        self.devices: WallDevices | None = None
        self._uart: VirtualUart | None = None
        self._cancel_read = False
        self._cancel_write = False
        super().__init__(*args, **kwargs)

    def open(self) -> None:
        """Start the virtual device named by the URL; SerialException for a bad URL."""
        if self.is_open:  # type: ignore[has-type]  # set by pyserial's SerialBase
            raise SerialException("Port is already open.")
        if self._port is None:
            raise SerialException("Port must be configured before it can be used.")
        try:
            url = parse_sim_url(self._port)
        except ValueError as exc:
            raise SerialException(f"cannot open {self._port!r}: {exc}") from None
        baud = url.baud
        if baud is None:
            given = self._baudrate
            baud = given if given != _PYSERIAL_DEFAULT_BAUD else None  # None: the device's own default
        try:
            self.devices = WallDevices([url.device], bauds={} if baud is None else {url.role: int(baud)},
                                       fixture=url.fixture, seed=url.seed)
        except ValueError as exc:
            raise SerialException(f"cannot open {self._port!r}: {exc}") from None
        self._uart = self.devices.uarts[url.role]
        self.is_open = True
        log.debug("opened %s: %s (%s) at %d baud", self._port, url.device, url.role, self._uart.baud)

    def close(self) -> None:
        """Stop the device."""
        if self.is_open and self.devices is not None:
            self.devices.close()
        self.is_open = False
        self._uart = None

    def _reconfigure_port(self, *args: Any, **kwargs: Any) -> None:
        """Settings cannot change the virtual link once open (a different baud is logged and ignored)."""
        if self._uart is not None and self._baudrate != self._uart.baud:
            log.warning("%s: baudrate %s ignored: the virtual device runs at %d", self._port, self._baudrate,
                        self._uart.baud)

    def _line(self) -> VirtualUart:
        if not self.is_open or self._uart is None:
            raise PortNotOpenError()
        return self._uart

    @property
    def in_waiting(self) -> int:
        """Bytes that have arrived and not been read."""
        return self._line().in_waiting()

    @property
    def out_waiting(self) -> int:
        """Bytes written whose stop bit has not ended yet."""
        uart = self._line()
        return uart.tx_queue_size - uart.tx_free()

    def read(self, size: int = 1) -> bytes:
        """Read up to size bytes, waiting as the timeout says (None: until size bytes have arrived)."""
        uart = self._line()
        data = bytearray(uart.read(size) if size > 0 else b"")
        timeout = self._timeout
        if len(data) >= size or timeout == 0:
            return bytes(data)
        deadline = None if timeout is None else time.monotonic() + timeout
        self._cancel_read = False
        while len(data) < size and not self._cancel_read and self.is_open:
            wait = POLL_S
            if deadline is not None:
                left = deadline - time.monotonic()
                if left <= 0:
                    break
                wait = min(wait, left)
            time.sleep(wait)
            data += uart.read(size - len(data))
        return bytes(data)

    def write(self, data: Any) -> int:
        """Put bytes on the wire from now; waits for queue space up to write_timeout (0: partial write)."""
        uart = self._line()
        payload = to_bytes(data)
        sent = uart.write(payload)
        if sent == len(payload) or self._write_timeout == 0:
            return sent
        deadline = None if self._write_timeout is None else time.monotonic() + self._write_timeout
        self._cancel_write = False
        while sent < len(payload) and not self._cancel_write:
            if deadline is not None and time.monotonic() >= deadline:
                raise SerialTimeoutException("Write timeout")
            time.sleep(POLL_S)
            sent += uart.write(payload[sent:])
        return sent

    def flush(self) -> None:
        """Wait until every written byte has left the wire."""
        while self.out_waiting:
            time.sleep(POLL_S)

    def reset_input_buffer(self) -> None:
        """Discard the bytes that have arrived."""
        self._line().read()

    def reset_output_buffer(self) -> None:
        """Nothing to discard: written bytes are already on the virtual wire."""
        self._line()

    def cancel_read(self) -> None:
        """Make a waiting read return."""
        self._cancel_read = True

    def cancel_write(self) -> None:
        """Make a waiting write return."""
        self._cancel_write = True

    def send_break(self, duration: float = 0.25) -> None:
        """No break condition on the virtual line."""
        self._line()

    def _update_break_state(self) -> None:
        """No break condition on the virtual line."""

    def _update_rts_state(self) -> None:
        """The virtual device ignores RTS."""

    def _update_dtr_state(self) -> None:
        """The virtual device ignores DTR."""

    @property
    def cts(self) -> bool:
        """Always clear to send."""
        self._line()
        return True

    @property
    def dsr(self) -> bool:
        """The device is always ready."""
        self._line()
        return True

    @property
    def ri(self) -> bool:
        """No ring indicator."""
        self._line()
        return False

    @property
    def cd(self) -> bool:
        """Carrier always present."""
        self._line()
        return True
