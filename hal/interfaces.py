"""The MCU's peripherals as small abstract classes; the firmware is handed a `Board` of them.

In the manner of python-can's ``BusABC``: the checks and bookkeeping shared by every backend
(argument validation, error counters, the closed state) live here once, and each backend supplies
a few tiny hooks (``_send``, ``_receive``, ``_rx_count``, ...). The firmware imports this module
only; it never imports a backend.
"""

from __future__ import annotations

import dataclasses
from abc import ABC, abstractmethod
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import Final

from mypy_extensions import mypyc_attr

from hal.can import CanPort
from hal.errors import HalError

__all__ = [
    "Adc",
    "Board",
    "DigitalIn",
    "DigitalOut",
    "EncoderTimer",
    "Uart",
    "UartErrors",
    "Watchdog",
]

_MAX_BAUD: Final = 20_000_000


@dataclass
class UartErrors:
    """Error counters of one UART since it was opened (a snapshot when read through `Uart.errors`).

    overrun: overrun events (STM32 ORE): a run of consecutive received bytes lost because the
    receive buffer was full counts once; rx_lost: every received byte lost that way;
    framing/noise: bytes received with a framing error (FE) or noise flag (NF);
    tx_dropped: bytes that `Uart.write` refused because the transmit queue was full.
    """

    overrun: int = 0
    framing: int = 0
    noise: int = 0
    tx_dropped: int = 0
    rx_lost: int = 0

    def total(self) -> int:
        """All error events and lost bytes added up (0 means a clean link)."""
        return self.overrun + self.framing + self.noise + self.tx_dropped + self.rx_lost


@mypyc_attr(allow_interpreted_subclasses=True)  # backends and test doubles subclass it
class Uart(ABC):
    """A UART as the firmware sees it: non-blocking, bounded transmit queue, receive buffer.

    ``write`` never blocks: it accepts what fits in the transmit queue and refuses (and counts)
    the rest, so a logger can drop records instead of stalling a control task. ``read`` returns
    only the bytes that have arrived by now.
    """

    def __init__(self, baud: object, name: str = "uart") -> None:
        """Validate the baud rate (an int; typed ``object``: docs/compiled.md, "Values checked as given").

        Also sets up the shared error counters.
        """
        if isinstance(baud, bool) or not isinstance(baud, int) or not 0 < baud <= _MAX_BAUD:
            raise ValueError(f"baud {baud!r} out of range: an int in 1..{_MAX_BAUD}")
        self._baud: int = baud
        self.name = name
        self._errors = UartErrors()
        self._closed = False

    @property
    def baud(self) -> int:
        """The configured baud rate in bit/s."""
        return self._baud

    @property
    def closed(self) -> bool:
        """True once `close` has been called."""
        return self._closed

    @property
    def errors(self) -> UartErrors:
        """A snapshot of the error counters, brought up to date first."""
        if not self._closed:
            self._refresh_errors()
        return dataclasses.replace(self._errors)

    def write(self, data: bytes | bytearray | memoryview) -> int:
        """Queue bytes without blocking; return how many were accepted (the refused rest is counted)."""
        self._check_open()
        if type(data) is bytes:  # the usual case: immutable already, no copy
            payload = data
        elif isinstance(data, (bytes, bytearray, memoryview)):
            payload = bytes(data)
        else:
            raise TypeError(f"write() takes bytes, bytearray or memoryview, not {type(data).__name__}")
        if not payload:
            return 0
        accepted = self._send(payload)
        if not 0 <= accepted <= len(payload):
            raise HalError(f"{self.name}: backend accepted {accepted} of {len(payload)} bytes")
        self._errors.tx_dropped += len(payload) - accepted
        return accepted

    def tx_free(self) -> int:
        """Bytes the transmit queue can accept right now."""
        self._check_open()
        return self._tx_space()

    def read(self, max_bytes: int = -1) -> bytes:
        """Return up to max_bytes received bytes (-1: all) that have arrived by now; never blocks."""
        self._check_open()
        if isinstance(max_bytes, bool) or not isinstance(max_bytes, int) or max_bytes < -1:
            raise ValueError(f"max_bytes {max_bytes!r} out of range: -1 (all) or an int >= 0")
        if max_bytes == 0:
            return b""
        return self._receive(max_bytes)

    def in_waiting(self) -> int:
        """Number of received bytes ready to be read now."""
        self._check_open()
        return self._rx_count()

    def flush(self, timeout_s: float = 0.5) -> bool:
        """Block until every accepted byte has left the transmitter (or ``timeout_s``); True when drained.

        The stop path calls it so that the motor's safe command is on the wire before the port closes.
        """
        self._check_open()
        if not 0 < timeout_s <= 60:
            raise ValueError(f"timeout_s {timeout_s!r} out of range: 0 < timeout_s <= 60")
        return self._drain(timeout_s)

    def close(self) -> None:
        """Release the port; further use raises HalError. Closing twice is harmless."""
        if not self._closed:
            self._closed = True
            self._close()

    def __enter__(self) -> Uart:
        """Use the UART as a context manager that closes it on exit."""
        return self

    def __exit__(self, *exc: object) -> None:
        """Close on leaving the with-block."""
        self.close()

    def _check_open(self) -> None:
        if self._closed:
            raise HalError(f"{self.name}: UART is closed")

    # Backend hooks -------------------------------------------------------------------------
    @abstractmethod
    def _send(self, data: bytes) -> int:
        """Hand non-empty data to the line; return the number of leading bytes accepted."""

    @abstractmethod
    def _receive(self, max_bytes: int) -> bytes:
        """Return up to max_bytes (-1: all) received bytes."""

    @abstractmethod
    def _rx_count(self) -> int:
        """Number of received bytes ready now."""

    @abstractmethod
    def _tx_space(self) -> int:
        """Free space in the transmit queue now."""

    def _refresh_errors(self) -> None:  # noqa: B027 (optional hook)
        """Bring ``self._errors`` up to date (backends with lazily computed counters override)."""

    def _drain(self, timeout_s: float) -> bool:
        """Wait until the transmit queue is empty; True when it is (default: nothing is ever held)."""
        return True

    def _close(self) -> None:  # noqa: B027 (optional hook)
        """Release backend resources."""


@mypyc_attr(allow_interpreted_subclasses=True)  # backends and test doubles subclass it
class EncoderTimer(ABC):
    """A general-purpose timer in quadrature encoder mode (STM32 TIMx with SMS = 011, x4).

    CNT is an unsigned ``bits``-wide register counting 0..ARR and wrapping; the firmware does its
    own wrap-safe arithmetic, e.g. ``(int16_t)(cnt - prev)``.
    """

    def __init__(self, bits: int = 16, arr: object = None) -> None:
        """Validate the counter width (16 or 32) and the auto-reload value (default 2**bits - 1)."""
        if bits not in (16, 32):
            raise ValueError(f"bits {bits!r} not supported: 16 (TIM1/3/4/8) or 32 (TIM2/5)")
        top = (1 << bits) - 1
        if arr is None:
            arr = top
        if isinstance(arr, bool) or not isinstance(arr, int) or not 1 <= arr <= top:
            raise ValueError(f"arr {arr!r} out of range: an int in 1..{top} for a {bits}-bit timer")
        self._bits = bits
        self._arr = arr

    @property
    def bits(self) -> int:
        """Counter width in bits (16 or 32)."""
        return self._bits

    @property
    def arr(self) -> int:
        """Auto-reload value: CNT counts 0..arr and wraps."""
        return self._arr

    @abstractmethod
    def cnt(self) -> int:
        """The CNT register now, in 0..arr."""

    @abstractmethod
    def counting_down(self) -> bool:
        """The DIR bit (TIMx_CR1 bit 4): True if the last count change was downwards."""

    def set_cnt(self, value: int) -> None:
        """Write the CNT register (``__HAL_TIM_SET_COUNTER``); value in 0..arr."""
        if isinstance(value, bool) or not isinstance(value, int) or not 0 <= value <= self._arr:
            raise ValueError(f"CNT value {value!r} out of range: an int in 0..{self._arr}")
        self._write_cnt(value)

    @abstractmethod
    def _write_cnt(self, value: int) -> None:
        """Backend hook for `set_cnt` with a validated value."""


@mypyc_attr(allow_interpreted_subclasses=True)  # backends and test doubles subclass it
class Adc(ABC):
    """An ADC whose regular channels a DMA stream copies to memory (STM32 scan mode + circular DMA).

    The firmware reads the DMA buffer: ``read()`` returns, for every channel in scan order, the code of
    its last completed conversion (0 before the first), never blocking. ``bits`` is the resolution (the
    STM32's RES field: 12, 10, 8 or 6; a backend over another converter may say up to 16); ``vref_v`` the
    reference voltage, so one LSB is ``vref_v / 2**bits`` volts (RM0090 13.3.4 / AN2834: an ideal
    12-bit code is V_in * 4096 / V_REF). Backends supply ``_dma_buffer``.
    """

    def __init__(self, channels: Sequence[str], bits: int = 12, vref_v: float = 3.3) -> None:
        """Check the channel names (unique, non-empty), the resolution (6..16 bits) and the reference (V)."""
        names = tuple(channels)
        if not names or len(set(names)) != len(names) or not all(isinstance(n, str) and n for n in names):
            raise ValueError(f"channels {names!r} invalid: one or more distinct non-empty names")
        if isinstance(bits, bool) or not isinstance(bits, int) or not 6 <= bits <= 16:
            raise ValueError(f"bits {bits!r} out of range: an int in 6..16")
        if isinstance(vref_v, bool) or not isinstance(vref_v, (int, float)) or not 1.0 <= vref_v <= 5.5:
            raise ValueError(f"vref_v {vref_v!r} out of range: 1.0..5.5 V")
        self._channels = names
        self._bits = bits
        self._vref_v = float(vref_v)

    @property
    def channels(self) -> tuple[str, ...]:
        """The channel names in scan (DMA buffer) order."""
        return self._channels

    @property
    def bits(self) -> int:
        """Resolution in bits."""
        return self._bits

    @property
    def vref_v(self) -> float:
        """The reference voltage (full scale) in V."""
        return self._vref_v

    @property
    def full_scale(self) -> int:
        """The largest code, 2**bits - 1."""
        return (1 << self._bits) - 1

    def index(self, name: str) -> int:
        """The position of channel name in the buffer; ValueError naming the channels otherwise."""
        try:
            return self._channels.index(name)
        except ValueError:
            raise ValueError(f"ADC channel {name!r} unknown: one of {list(self._channels)}") from None

    def read(self) -> list[int]:
        """The DMA buffer now: the last completed code of each channel, in scan order."""
        codes = self._dma_buffer()
        if len(codes) != len(self._channels):
            raise HalError(f"ADC backend returned {len(codes)} codes for {len(self._channels)} channels")
        return codes

    def volts(self, code: int) -> float:
        """The input voltage a code stands for (code * vref / 2**bits)."""
        return code * self._vref_v / (1 << self._bits)

    @abstractmethod
    def _dma_buffer(self) -> list[int]:
        """Backend hook: the codes of the last completed conversions, one per channel."""


@mypyc_attr(allow_interpreted_subclasses=True)  # backends and test doubles subclass it
class Watchdog(ABC):
    """The independent watchdog as the firmware sees it: kick it or the MCU resets."""

    @abstractmethod
    def kick(self) -> None:
        """Reload the watchdog counter (IWDG_KR = 0xAAAA)."""


@mypyc_attr(allow_interpreted_subclasses=True)  # backends and test doubles subclass it
class DigitalIn(ABC):
    """A digital input pin (the e-stop switch)."""

    @abstractmethod
    def read(self) -> bool:
        """The pin level now (True = high)."""


@mypyc_attr(allow_interpreted_subclasses=True)  # backends and test doubles subclass it
class DigitalOut(ABC):
    """A digital output pin (the status LED): shared level bookkeeping, a tiny drive hook."""

    def __init__(self, initial: bool = False) -> None:
        """Start at the given level."""
        self._level = bool(initial)

    @property
    def level(self) -> bool:
        """The level last written."""
        return self._level

    def write(self, level: bool) -> None:
        """Drive the pin to level."""
        level = bool(level)
        self._drive(level)
        self._level = level

    def toggle(self) -> None:
        """Invert the pin level."""
        self.write(not self._level)

    @abstractmethod
    def _drive(self, level: bool) -> None:
        """Backend hook: put the level on the pin (called before the new level is remembered)."""


@dataclass(frozen=True)
class Board:
    """Everything the firmware is handed at start-up: its peripherals and the cycle clock."""

    motor_uart: Uart
    imu_uart: Uart
    telemetry_uart: Uart
    encoder: EncoderTimer
    estop: DigitalIn
    led: DigitalOut
    watchdog: Watchdog
    now_cycles: Callable[[], int]
    f_cpu_hz: int
    can: CanPort | None = None  # the CAN controller, on boards whose motor link is CAN
    adc: Adc | None = None  # the ADC with the ground sensors (load cell, heel/toe FSRs), on boards that have them

    def __post_init__(self) -> None:
        """Check the clock frequency."""
        if isinstance(self.f_cpu_hz, bool) or not isinstance(self.f_cpu_hz, int) or self.f_cpu_hz <= 0:
            raise ValueError(f"f_cpu_hz {self.f_cpu_hz!r} out of range: a positive int")

    def ticks_ms(self) -> int:
        """Milliseconds since reset, as HAL_GetTick() reports them with a 1 kHz SysTick."""
        return self.now_cycles() * 1000 // self.f_cpu_hz

    def uarts(self) -> dict[str, Uart]:
        """The three UARTs by role name (motor, imu, telemetry)."""
        return {"motor": self.motor_uart, "imu": self.imu_uart, "telemetry": self.telemetry_uart}
