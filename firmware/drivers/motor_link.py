"""What every motor driver publishes, whatever its link (UART, CAN servo mode, CAN MIT mode).

The firmware's tasks and the reports read a motor driver through :class:`MotorLink` only: ``poll``
(take the feedback that arrived), ``send`` (the current or brake command), ``send_safe`` (one drive command
of the safe state, firmware/safe_state.py, among the link's ``SAFE_BEHAVIOURS``), ``send_stop`` (the stop
path), ``feedback`` (:class:`MotorFeedback`), ``stats`` (:class:`MotorLinkStats`), ``last_command_s``,
the latched ``link_lost`` of :class:`~firmware.drivers.link.LinkState`, ``decoder.stats.bytes_in``
(bytes taken, for the motor task's cost model), ``crc_errors`` and ``published()`` (link-specific
counters for the report). Which driver runs is chosen by name (:mod:`firmware.drivers.motor_links`).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any, ClassVar

from mypy_extensions import mypyc_attr

from firmware.drivers.link import LinkState
from firmware.safe_state import SafeCommand

__all__ = ["MotorFeedback", "MotorLink", "MotorLinkStats", "RxCounter", "RxStats", "SafeStop", "stop_command"]


@dataclass
class MotorFeedback:
    """The latest feedback from the motor (SI units); `received_s` None until the first reply."""

    current_a: float = 0.0
    erpm: int = 0
    position_rad: float = 0.0
    fault: int = 0
    temp_motor_c: float = math.nan
    temp_fet_c: float = math.nan
    v_in_v: float = math.nan
    received_s: float | None = None
    temp_received_s: float | None = None  # when temp_motor_c came (the UART link: with the full GET_VALUES)


@dataclass
class SafeStop:
    """What the stop path put on the motor's wire: the bytes, how many the port took, whether they left it.

    Over CAN ``frames`` holds the data bytes of the safe frames one after the other. ``names`` says what
    the frames are, in order, as the driver sent them (for the summary and the log).
    """

    frames: bytes
    at_s: float
    names: tuple[str, ...] = ()
    written: int = 0
    drained: bool = False
    error: str = ""

    @property
    def on_wire(self) -> bool:
        """True when every byte was accepted and the port reported its transmitter empty."""
        return self.written == len(self.frames) and self.drained and not self.error


@dataclass
class MotorLinkStats:
    """Accounting of the motor link: requests, replies, and what went wrong."""

    requests: int = 0
    replies: int = 0
    full_replies: int = 0
    missing_replies: int = 0
    stale_replies: int = 0
    tx_refused: int = 0
    max_age_s: float = 0.0
    rx_timeouts: int = 0


@dataclass
class RxStats:
    """Bytes and frames a frame-based driver took in (a CAN controller checks CRCs and framing itself:
    the byte-stream counters of the VESC decoder stay 0)."""

    bytes_in: int = 0
    frames: int = 0
    crc_errors: int = 0
    dropped_bytes: int = 0
    bad_end_bytes: int = 0


class RxCounter:
    """The ``decoder`` of a frame-based driver: only its ``stats`` (the UART driver's is the VESC decoder)."""

    def __init__(self) -> None:
        """Nothing counted yet."""
        self.stats = RxStats()


def stop_command(command: SafeCommand | float) -> SafeCommand:
    """The stop path's command: a SafeCommand as given, a number as the brake current (zero current, then the brake)."""
    return command if isinstance(command, SafeCommand) else SafeCommand("brake", abs(float(command)))


@mypyc_attr(allow_interpreted_subclasses=True)
class MotorLink(LinkState):
    """The motor driver interface (see the module docstring); subclasses set the attributes in __init__."""

    feedback: MotorFeedback
    stats: MotorLinkStats
    last_command_s: float | None
    decoder: Any
    SAFE_BEHAVIOURS: ClassVar[tuple[str, ...]] = ("release",)
    """The safe behaviours the link's protocol carries (docs/devices.md, "Safe behaviours")."""

    def poll(self, now_s: float) -> int:
        """Take what arrived; return the number of feedback messages taken."""
        raise NotImplementedError

    def send(self, current_a: float, now_s: float, *, brake: bool = False, request: bool = True) -> int:
        """Send the current (or brake) command; return the bytes written."""
        raise NotImplementedError

    def send_safe(self, command: SafeCommand, now_s: float, *, request: bool = True) -> int:
        """Send one drive command of the safe state (one of ``SAFE_BEHAVIOURS``); return the bytes written."""
        raise NotImplementedError

    def send_stop(self, now_s: float, command: SafeCommand | float, timeout_s: float = 0.5) -> SafeStop:
        """The stop path: zero current, then the safe command (a number: the brake current), on the wire before
        returning."""
        raise NotImplementedError

    @property
    def crc_errors(self) -> int:
        """Frames rejected for a bad checksum (none on links that check in hardware)."""
        return 0

    def published(self) -> dict[str, object]:
        """Link-specific counters for the report (none by default)."""
        return {}
