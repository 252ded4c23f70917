"""CAN ports on real buses through python-can (socketcan, USB adapters, udp_multicast, ...), and can:// URLs.

``can://INTERFACE/CHANNEL?id=N&mode=servo|mit[&bitrate=B]`` names a python-can interface, its channel,
the motor's driver id and the AK-series CAN mode, e.g. ``can://socketcan/can0?id=1&mode=mit`` or
``can://udp_multicast/239.74.163.2?id=1&mode=servo``. :class:`PythonCanPort` adapts a ``can.BusABC`` to
:class:`~hal.can.CanPort`: ``send`` hands the frame to the bus without blocking (a full transmit queue
is a refusal), ``receive`` polls without waiting, ``flush`` waits for the interface's transmit queue
where python-can can tell (``flush_tx_buffer`` is not a wait, so it sleeps one frame time per frame
sent in the last call at most); a python-can error latches as :class:`~hal.errors.HalError`.
"""

from __future__ import annotations

import time
from dataclasses import dataclass
from typing import Any
from urllib.parse import parse_qs, urlsplit

from hal.can import CanFrame, CanPort
from hal.errors import HalError

__all__ = ["CanUrl", "PythonCanPort", "is_can_url", "open_can", "parse_can_url"]

MODES = ("servo", "mit")


@dataclass(frozen=True)
class CanUrl:
    """A parsed can:// URL."""

    interface: str
    channel: str
    driver_id: int = 1
    mode: str = "servo"
    bitrate: int = 1_000_000


def is_can_url(text: str | None) -> bool:
    """Whether text is a can:// URL."""
    return bool(text) and str(text).startswith("can://")


def parse_can_url(text: str, where: str = "--motor") -> CanUrl:
    """The parts of a can:// URL; ValueError naming the value, where it came from and what is allowed."""
    u = urlsplit(text)
    if u.scheme != "can" or not u.netloc or not u.path.strip("/"):
        raise ValueError(f"{where} {text!r} is not can://INTERFACE/CHANNEL?id=N&mode=servo|mit")
    q = {k: v[-1] for k, v in parse_qs(u.query).items()}
    unknown = sorted(set(q) - {"id", "mode", "bitrate"})
    if unknown:
        raise ValueError(f"{where} {text!r}: unknown parameter {unknown[0]!r} (id, mode, bitrate)")
    try:
        driver_id = int(q.get("id", "1"))
        bitrate = int(q.get("bitrate", "1000000"))
    except ValueError:
        raise ValueError(f"{where} {text!r}: id and bitrate must be integers") from None
    if not 0 <= driver_id <= 127:
        raise ValueError(f"{where} {text!r}: id={driver_id} out of range 0..127")
    if not 10_000 <= bitrate <= 1_000_000:
        raise ValueError(f"{where} {text!r}: bitrate={bitrate} out of range 10000..1000000")
    mode = q.get("mode", "servo")
    if mode not in MODES:
        raise ValueError(f"{where} {text!r}: mode={mode!r} not one of {MODES}")
    return CanUrl(u.netloc, u.path.lstrip("/"), driver_id, mode, bitrate)


class PythonCanPort(CanPort):
    """A python-can bus as a CanPort (see the module docstring)."""

    def __init__(self, bus: Any, bitrate: int = 1_000_000, name: str = "can") -> None:
        """Wrap an open ``can.BusABC``; the port owns it (close closes it)."""
        super().__init__(bitrate, name)
        self.bus = bus
        self._last_burst = 0

    def _send(self, frame: CanFrame) -> bool:
        import can

        msg = can.Message(arbitration_id=frame.arbitration_id, data=frame.data, is_extended_id=frame.extended)
        try:
            self.bus.send(msg, timeout=0.0)
        except can.CanOperationError as exc:
            if "buffer" in str(exc).lower() or "timed out" in str(exc).lower():
                return False
            raise HalError(f"{self.name}: {exc}") from exc
        except (can.CanError, OSError) as exc:
            raise HalError(f"{self.name}: {exc}") from exc
        self._last_burst += 1
        return True

    def _receive(self) -> CanFrame | None:
        import can

        try:
            msg = self.bus.recv(0.0)
        except (can.CanError, OSError) as exc:
            raise HalError(f"{self.name}: {exc}") from exc
        if msg is None or msg.is_error_frame or msg.is_remote_frame:
            return None
        return CanFrame(msg.arbitration_id, bytes(msg.data), msg.is_extended_id)

    def _drain(self, timeout_s: float) -> bool:
        wait = min(timeout_s, self._last_burst * 160 / self.bitrate)  # worst-case 8-byte extended frames
        self._last_burst = 0
        if wait > 0:
            time.sleep(wait)
        return True

    def _close(self) -> None:
        try:
            self.bus.shutdown()
        except Exception:  # noqa: BLE001 (closing a failed bus must not hide the first error)
            pass


def open_can(url: CanUrl, *, receive_own_messages: bool = False) -> PythonCanPort:
    """Open the python-can bus a can:// URL names (HalError naming it when python-can cannot)."""
    try:
        import can
    except ImportError as exc:  # pragma: no cover - a dependency
        raise HalError(f"can://{url.interface}/{url.channel}: python-can is not installed") from exc
    try:
        bus = can.Bus(interface=url.interface, channel=url.channel, bitrate=url.bitrate,
                      receive_own_messages=receive_own_messages)
    except Exception as exc:  # noqa: BLE001 (python-can raises many kinds: name the URL)
        raise HalError(f"can://{url.interface}/{url.channel}: cannot open ({type(exc).__name__}: {exc})") from exc
    return PythonCanPort(bus, url.bitrate, f"can://{url.interface}/{url.channel}")
