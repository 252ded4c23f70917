"""CAN ports on real buses through python-can (socketcan, USB adapters, udp_multicast, ...), and can:// URLs.

``can://INTERFACE/CHANNEL?id=N&mode=servo|mit[&bitrate=B]`` names a python-can interface, its channel,
the motor's driver id and the AK-series CAN mode, e.g. ``can://socketcan/can0?id=1&mode=mit`` or
``can://udp_multicast/239.74.163.2?id=1&mode=servo``; ``id`` and ``mode`` are required (a wrong guess
drives another motor, or this one in the other mode). :class:`PythonCanPort` adapts a ``can.BusABC`` to
:class:`~hal.can.CanPort`: ``send`` hands the frame to the bus without blocking (a full transmit queue
is a refusal), ``receive`` polls without waiting, ``flush`` waits until the frames sent could have left
the wire (python-can cannot report a frame as sent: each frame is taken to occupy the bus for its
worst-case length after the previous one, so the wait is at most the wire time of the frames still
possibly queued, not one frame time per frame since the last flush); a python-can error latches as
:class:`~hal.errors.HalError`. On interfaces that hand a bus its own frames back (``udp_multicast``:
multicast loopback) the echoes of what this port sent are dropped and counted (``echoes``, :class:`OwnFrames`), not
received;
a ``udp_multicast`` bus hears its own group only (Linux delivers every joined group's datagrams otherwise).
"""

from __future__ import annotations

import time
from collections import deque
from dataclasses import dataclass
from typing import Any
from urllib.parse import parse_qs, urlsplit

from hal.can import CanFrame, CanPort
from hal.errors import HalError

__all__ = ["CanUrl", "OwnFrames", "PythonCanPort", "is_can_url", "open_can", "own_group_only", "parse_can_url"]

MODES = ("servo", "mit")
FRAME_BITS = 160  # a worst-case 8-byte extended data frame with bit stuffing and the interframe space
ECHOING_INTERFACES = frozenset({"udp_multicast"})  # python-can interfaces whose buses receive their own frames
MAX_PENDING_ECHOES = 1 << 16
"""Own frames whose echo is awaited, at most. A receive buffer (4 MiB asked, hal.pycan callers; Linux grants up to
twice net.core.rmem_max) holds far fewer datagrams than this, so an echo still awaited beyond it was dropped."""


@dataclass(frozen=True)
class CanUrl:
    """A parsed can:// URL."""

    interface: str
    channel: str
    driver_id: int
    mode: str
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
        driver_id = int(q.get("id", "0"))
        bitrate = int(q.get("bitrate", "1000000"))
    except ValueError:
        raise ValueError(f"{where} {text!r}: id and bitrate must be integers") from None
    if not 0 <= driver_id <= 127:
        raise ValueError(f"{where} {text!r}: id={driver_id} out of range 0..127")
    if not 10_000 <= bitrate <= 1_000_000:
        raise ValueError(f"{where} {text!r}: bitrate={bitrate} out of range 10000..1000000")
    mode = q.get("mode", "")
    if "mode" in q and mode not in MODES:
        raise ValueError(f"{where} {text!r}: mode={mode!r} not one of {MODES}")
    missing = [k for k in ("id", "mode") if k not in q]
    if missing:
        raise ValueError(f"{where} {text!r}: {' and '.join(missing)} missing: the motor's driver id (id=0..127) "
                         "and its CAN mode (mode=servo|mit) are both required")
    return CanUrl(u.netloc, u.path.lstrip("/"), driver_id, mode, bitrate)


class OwnFrames:
    """The frames a bus sent whose echo has not come back yet, to tell the echoes from other nodes' frames.

    A multicast loopback hands a socket its own datagrams back in the order they were sent, among the others'. A
    received frame equal to one awaited is taken for the oldest such echo; the echoes awaited before it were lost
    (the receive buffer overflowed): forgotten and counted in ``lost``. Every step is O(1) however many are
    awaited (at most ``limit``; beyond it the oldest is forgotten, counted in ``lost`` too). A frame of another
    node equal to one of ours still awaited is taken for its echo: nodes on one bus do not send the same ID.
    """

    def __init__(self, limit: int = MAX_PENDING_ECHOES) -> None:
        """Nothing awaited."""
        self.limit = limit
        self._order: deque[tuple[int, bytes, bool]] = deque()
        self._awaited: dict[tuple[int, bytes, bool], int] = {}
        self.echoes = 0  # echoes recognised
        self.lost = 0  # echoes awaited that never came

    def sent(self, key: tuple[int, bytes, bool]) -> None:
        """Frame key (id, data, extended) went out: await its echo."""
        self._order.append(key)
        self._awaited[key] = self._awaited.get(key, 0) + 1
        if len(self._order) > self.limit:
            self._forget(self._order.popleft())
            self.lost += 1

    def is_echo(self, key: tuple[int, bytes, bool]) -> bool:
        """Whether a received frame is the echo of one sent (then no longer awaited)."""
        if not self._awaited.get(key):
            return False
        order = self._order
        while True:
            oldest = order.popleft()
            self._forget(oldest)
            if oldest == key:
                self.echoes += 1
                return True
            self.lost += 1

    def _forget(self, key: tuple[int, bytes, bool]) -> None:
        n = self._awaited[key] - 1
        if n:
            self._awaited[key] = n
        else:
            del self._awaited[key]


class PythonCanPort(CanPort):
    """A python-can bus as a CanPort (see the module docstring)."""

    def __init__(self, bus: Any, bitrate: int = 1_000_000, name: str = "can", *, echoes: bool = False,
                 clock_s: Any = time.perf_counter) -> None:
        """Wrap an open ``can.BusABC``; the port owns it (close closes it). ``echoes``: the bus hands its own
        frames back (drop them)."""
        super().__init__(bitrate, name)
        self.bus = bus
        self.clock_s = clock_s
        self.frame_s = FRAME_BITS / bitrate
        self._busy_until = 0.0  # when the frames sent so far have left the wire at the latest
        self._own = OwnFrames() if echoes else None

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
        now = self.clock_s()
        self._busy_until = max(now, self._busy_until) + self.frame_s
        if self._own is not None:
            self._own.sent((frame.arbitration_id, frame.data, frame.extended))
        return True

    @property
    def echoes(self) -> int:
        """Own frames the bus handed back, dropped."""
        return self._own.echoes if self._own is not None else 0

    def _receive(self) -> CanFrame | None:
        import can

        while True:
            try:
                msg = self.bus.recv(0.0)
            except (can.CanError, OSError) as exc:
                raise HalError(f"{self.name}: {exc}") from exc
            if msg is None or msg.is_error_frame or msg.is_remote_frame:
                return None
            frame = CanFrame(msg.arbitration_id, bytes(msg.data), msg.is_extended_id)
            own = self._own
            if own is None or not own.is_echo((frame.arbitration_id, frame.data, frame.extended)):
                return frame
            # our own frame handed back: dropped, take the next

    def _drain(self, timeout_s: float) -> bool:
        wait = self._busy_until - self.clock_s()
        if wait > timeout_s:
            time.sleep(timeout_s)
            return False
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
    if url.interface == "udp_multicast":
        own_group_only(bus)
    return PythonCanPort(bus, url.bitrate, f"can://{url.interface}/{url.channel}",
                         echoes=url.interface in ECHOING_INTERFACES and not receive_own_messages)


def own_group_only(bus: Any) -> None:
    """Make a udp_multicast bus hear its own group only.

    python-can binds the socket to the port on every address, and Linux then delivers to it the datagrams
    of every group any socket of the host joined on that port (``IP_MULTICAST_ALL`` is on by default, ip(7)):
    two buses on two groups would hear each other. Best effort: where the option or the socket is missing,
    nothing changes.
    """
    import socket

    sock = getattr(getattr(bus, "_multicast", None), "_socket", None)
    if sock is None:
        return
    v6 = sock.family == socket.AF_INET6
    level = socket.IPPROTO_IPV6 if v6 else socket.IPPROTO_IP
    option = getattr(socket, "IPV6_MULTICAST_ALL" if v6 else "IP_MULTICAST_ALL", 29 if v6 else 49)  # Linux values
    try:
        sock.setsockopt(level, option, 0)
    except OSError:
        pass
