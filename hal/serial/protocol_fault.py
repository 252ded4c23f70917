"""pyserial URL handler ``fault://``: any port, with one of pafp's byte fault injectors between it and the reader.

In the manner of pyserial's ``spy://``, it wraps another port, here to inject a fault into what the firmware
reads from it, on a real bench as on the virtual one: the same injector classes (hal/virtual/faults, the
:class:`~hal.virtual.faults.base.ByteFault` ones) act on the bytes read. The URL::

    fault://PORT?fault=NAME&(at=SECONDS|phase=P)[&duration=SECONDS][&PARAM=VALUE...][&allow_dangerous=1]

PORT is a device path or a pyserial URL without a query of its own (``/dev/ttyUSB0``, ``/dev/pts/7``,
``socket://host:port``); ``at`` counts on the firmware's clock, from its start, which serial mode tells the port
through :meth:`Serial.follow_clock` (before the firmware starts -- the ports' start-up checks -- the fault does
not act); a port no firmware follows counts from the moment it opens. Counting from the open would let a slow
start-up (a host stall between the open and the firmware's first period) move the window into the firmware's
start-up, where a silent motor is rightly no fault yet (zero current, ``startup_grace_s``), so a fault meant
for a running foot would act where it tests nothing. ``phase`` (0 <= P < 1) is a gait phase instead: the
fault starts the first time the firmware's gait clock reaches it, which serial mode tells the port through
:meth:`Serial.follow_gait` (until then, and without it, the fault never acts); ``duration`` defaults to the
rest of the run. The record's times (when the fault first and last acted) are on the same clock.
A fault marked dangerous (it feeds the controller a plausible but false angle, so the foot is driven
by it: ``imu_frozen``, ``imu_bias_step``) is refused unless ``allow_dangerous=1`` is given: docs/hardware.md,
"Faults on a real bench". Faults that act elsewhere than on a wire (encoder, CPU, supply, plant, controller)
are refused: they exist on the virtual bench only. When the fault first acts and when the port closes, the
record (when, how often, what it changed) is logged at WARNING.
"""

from __future__ import annotations

import logging
import math
import time
import urllib.parse
from collections.abc import Callable
from typing import Any

import serial
from serial.serialutil import PortNotOpenError, SerialBase, SerialException

__all__ = ["FaultUrlError", "Serial", "parse_fault_url", "register_fault_handler"]

log = logging.getLogger(__name__)

_OWN_KEYS = ("fault", "at", "phase", "duration", "allow_dangerous", "seed")


class FaultUrlError(SerialException):
    """A fault:// URL refused (a bad or missing part, a fault not allowed on a wire); the message names the part, not
    the URL, which whoever opened the port names once."""


def register_fault_handler() -> None:
    """Let ``serial.serial_for_url`` open ``fault://`` URLs (lists ``hal.serial`` among the handler packages)."""
    if "hal.serial" not in serial.protocol_handler_packages:
        serial.protocol_handler_packages.append("hal.serial")


def _number(url: str, key: str, text: str) -> float:
    try:
        value = float(text)
    except ValueError:
        raise FaultUrlError(f"{key}={text!r} is not a number") from None
    return value


def parse_fault_url(url: str) -> tuple[str, Any]:
    """(the wrapped port, the armed injector) of a fault:// URL; SerialException naming the bad part."""
    from hal.virtual.faults import make_injector
    from hal.virtual.faults.base import ByteFault

    parts = urllib.parse.urlsplit(url)
    if parts.scheme != "fault":
        raise FaultUrlError("not a fault:// URL")
    inner = url[len("fault://"):].split("?", 1)[0]
    if not inner:
        raise FaultUrlError("name the port to wrap: fault://PORT?fault=NAME&at=SECONDS")
    query = urllib.parse.parse_qs(parts.query, keep_blank_values=True)
    options = {k: v[-1] for k, v in query.items()}
    name = options.get("fault")
    if not name:
        raise FaultUrlError("fault=NAME is required (with at=SECONDS or phase=P)")
    if "at" in options and "phase" in options:
        raise FaultUrlError(f"at={options['at']} and phase={options['phase']} both given: give either at=SECONDS "
                            "(on the firmware's clock) or phase=P (a gait phase, 0 <= P < 1), not both")
    if "at" not in options and "phase" not in options:
        raise FaultUrlError("one of at=SECONDS or phase=P (a gait phase, 0 <= P < 1) is required")
    phase = _number(url, "phase", options["phase"]) if "phase" in options else None
    if phase is not None and not 0.0 <= phase < 1.0:
        raise FaultUrlError(f"phase={options['phase']} out of range: a gait phase, 0 <= P < 1")
    at = _number(url, "at", options["at"]) if phase is None else 0.0
    duration = _number(url, "duration", options["duration"]) if "duration" in options else math.inf
    params: dict[str, Any] = {}
    for k, v in options.items():
        if k not in _OWN_KEYS:
            try:
                params[k] = _number(url, k, v)
            except FaultUrlError:
                params[k] = v  # a named choice
    try:
        fault = make_injector(name, at, duration, int(_number(url, "seed", options.get("seed", "0"))), **params)
    except ValueError as e:
        raise FaultUrlError(str(e)) from None
    if not isinstance(fault, ByteFault):
        raise FaultUrlError(f"fault {name} acts on the {fault.WHERE}, not on a serial line: it exists on "
                              "the virtual bench only (pafp faults)")
    if fault.DANGEROUS and options.get("allow_dangerous") != "1":
        raise FaultUrlError(f"fault {name} is refused on a real port: {fault.HAZARD}; add "
                              "allow_dangerous=1 only with the foot free of any person (docs/hardware.md)")
    fault.phase = phase
    if phase is not None:
        fault.move_onset(math.inf)  # placed once the gait clock runs (Serial.follow_gait)
    return inner, fault


class Serial(SerialBase):
    """A port whose reads pass through a byte fault injector (see the module docstring)."""

    def __init__(self, *args: Any, **kwargs: Any) -> None:
        """As pyserial's SerialBase; the wrapped port opens when this one does."""
        self.inner: Any = None
        self.fault: Any = None
        self._t0 = 0.0
        self._reported = False
        self._gait: tuple[Callable[[], float | None], float] | None = None
        self._clock: Callable[[], float | None] | None = None
        super().__init__(*args, **kwargs)

    def follow_clock(self, now_s: Callable[[], float | None]) -> None:
        """Count the fault's window on the firmware's clock: now_s() is the firmware's time in seconds since its
        start, None before it started (then the fault does not act). Without it, time counts from the open."""
        self._clock = now_s

    def now_s(self) -> float | None:
        """The fault's time now: the firmware's clock when followed (None before its start), else since the open."""
        if self._clock is not None:
            return self._clock()
        return time.monotonic() - self._t0

    def follow_gait(self, gait_time_s: Callable[[], float | None], stride_s: float) -> None:
        """Place a ``phase=P`` onset on the firmware's gait clock: gait_time_s() is the time since the gait
        started (None before), stride_s the stride's length. The fault starts the first time the phase is P."""
        self._gait = (gait_time_s, stride_s)

    def _place_onset(self, now_s: float) -> None:
        if self._gait is None or not math.isinf(self.fault.onset_s):
            return
        gait_t = self._gait[0]()
        if gait_t is None:
            return
        stride = self._gait[1]
        target = self.fault.phase * stride
        while target < gait_t:
            target += stride
        self.fault.move_onset(now_s + target - gait_t)
        log.warning("fault://: %s placed at gait phase %g: at %.4f s (%s)", self.fault.NAME, self.fault.phase,
                    self.fault.onset_s, self._time_base())

    def open(self) -> None:
        """Open the wrapped port with this port's settings and arm the fault from now."""
        if self._port is None:
            raise SerialException("Port must be configured before it can be used.")
        inner, self.fault = parse_fault_url(self._port)
        self.inner = serial.serial_for_url(inner, baudrate=self._baudrate, timeout=self._timeout,
                                           write_timeout=self._write_timeout)
        self._t0 = time.monotonic()
        self.is_open = True

    def close(self) -> None:
        """Close the wrapped port; log what the fault did."""
        if self.inner is not None:
            self.inner.close()
            self.inner = None
            rec = self.fault.record
            log.warning("fault://: %s: fired %d times, first at %s s (%s; %s)", self.fault.describe(), rec.count,
                        None if rec.first_s is None else round(rec.first_s, 4), self._time_base(),
                        rec.what or "nothing")
        self.is_open = False

    def _time_base(self) -> str:
        return "after open" if self._clock is None else "on the firmware's clock"

    def _reconfigure_port(self, force_update: bool = False) -> None:
        if self.inner is not None:
            self.inner.baudrate = self._baudrate

    def _open_inner(self) -> Any:
        if not self.is_open or self.inner is None:
            raise PortNotOpenError()
        return self.inner

    @property
    def in_waiting(self) -> int:
        """Bytes the wrapped port holds (the fault may remove some of them when read)."""
        return int(self._open_inner().in_waiting)

    def read(self, size: int = 1) -> bytes:
        """Read from the wrapped port; the fault acts on what came."""
        data = bytes(self._open_inner().read(size))
        now_s = self.now_s()
        if now_s is None:  # the firmware it follows has not started: its start-up checks read the port as it is
            return data
        if self.fault.phase is not None:
            self._place_onset(now_s)
        out = self.fault.filter(data, now_s)
        if out != data and not self._reported:
            self._reported = True
            log.warning("fault://: %s acts from %.4f s (%s)", self.fault.NAME, self.fault.record.first_s,
                        self._time_base())
        return out

    def write(self, data: bytes) -> int | None:
        """Write to the wrapped port unchanged."""
        return self._open_inner().write(data)

    def flush(self) -> None:
        """Wait for the wrapped port's output."""
        self._open_inner().flush()

    def reset_input_buffer(self) -> None:
        """Drop the wrapped port's input."""
        self._open_inner().reset_input_buffer()

    def reset_output_buffer(self) -> None:
        """Drop the wrapped port's output."""
        self._open_inner().reset_output_buffer()

    @property
    def out_waiting(self) -> int:
        """Bytes the wrapped port still has to send."""
        return int(getattr(self._open_inner(), "out_waiting", 0))

    def fileno(self) -> int:
        """The wrapped port's descriptor (for the driver's error counters)."""
        return int(self._open_inner().fileno())
