"""Every frame on the virtual bench's wires for the trace (``pafp run --trace-wire``): port, direction, time, name.

Taps on the bench side of each wire see the bytes with the times their stop bits end (the virtual UART's line
model), after any fault on the wire: towards a device a :class:`~hal.virtual.faults.taps.PeerTap`, towards the MCU
a wrapper of the device's link (under a fault's ``LinkTap`` when there is one). Each write or transmission is one
slice, from its first byte's start bit to its last byte's stop bit, named by what it decodes to (VESC messages,
an RVC frame, a telemetry record). On a CAN motor link, the frames the motor receives are traced (the tap on the
motor's node), each named by its servo packet or MIT command; the motor's replies are not.
"""

from __future__ import annotations

from collections import deque
from collections.abc import Callable, Sequence
from typing import Any

from hal.can import CanFrame
from hal.virtual.can_bits import frame_bits
from hal.virtual.faults.taps import LinkTap, PeerTap, can_tap, peer_tap
from protocol import can_mit, can_servo, vesc

__all__ = ["WireTrace"]


class _ToMcu:
    """A device's link to the MCU that shows each transmission (bytes, stop-bit end times) before passing it on."""

    def __init__(self, link: Any, seen: Callable[[bytes, Sequence[int]], None]) -> None:
        self.link, self.seen = link, seen

    def transmit_to_mcu(self, data: bytes, start_cycles: int) -> list[int]:
        ends = self.link.transmit_to_mcu(data, start_cycles)
        if ends:
            self.seen(data[:len(ends)], ends)
        return ends

    def __getattr__(self, name: str) -> Any:
        return getattr(self.link, name)


def _vesc_names(direction: str) -> Callable[[bytes], str]:
    decoder = vesc.Decoder(direction)  # type: ignore[arg-type]

    def name(data: bytes) -> str:
        return ", ".join(type(m).__name__ for m in decoder.feed(data)) or "VESC bytes"
    return name


def _rvc_name(data: bytes) -> str:
    return "RVC frame" if data[:2] == b"\xaa\xaa" else "RVC bytes"


def _telemetry_name(data: bytes) -> str:
    return "telemetry record" if data.endswith(b"\x00") else "telemetry bytes"


def _can_name(mode: str) -> Callable[[CanFrame], str]:
    def name(frame: CanFrame) -> str:
        if mode == "mit":
            return can_mit.special_frame(frame.data) or "MIT command"
        try:
            return can_servo.decode_command(frame.arbitration_id, frame.data).packet.name
        except ValueError:
            return f"CAN 0x{frame.arbitration_id:x}"
    return name


class WireTrace:
    """The frames of every wire as (start cycles, end cycles, name) per track name, oldest first."""

    def __init__(self) -> None:
        """Nothing traced yet."""
        self.frames: dict[str, deque[tuple[int, int, str]]] = {}

    def _uart(self, track: str, byte_cycles: float, namer: Callable[[bytes], str]
              ) -> Callable[[bytes, Sequence[int]], None]:
        frames = self.frames.setdefault(track, deque())

        def seen(data: bytes, ends: Sequence[int]) -> None:
            frames.append((ends[0] - int(byte_cycles), ends[-1], namer(bytes(data))))
        return seen

    def arm(self, rig: Any) -> None:
        """Tap every wire of the rig's bench (call after the faults are armed, so their taps are shared)."""
        bench = rig.bench
        uarts = bench.board.uarts()
        for port, device_name, to_device, from_device in (("motor", "motor_device", "to-motor", "from-motor"),
                                                          ("imu", "imu", None, None), ("telemetry", None, None, None)):
            uart = uarts.get(port)
            if uart is None or (port == "motor" and bench.can_bus is not None):
                continue
            cycles = uart.byte_cycles
            out = (_vesc_names(to_device) if to_device else _telemetry_name if port == "telemetry" else _rvc_name)
            if port == "motor":
                peer_tap(rig).listeners.append(self._uart(f"wire {port} tx", cycles, out))
            elif uart.peer is not None:
                tap = PeerTap(uart.peer)
                tap.listeners.append(self._uart(f"wire {port} tx", cycles, out))
                uart.connect(tap)
            device = getattr(bench, device_name) if device_name else None
            if device is not None and getattr(device, "link", None) is not None:
                seen = self._uart(f"wire {port} rx", cycles, _vesc_names(from_device) if from_device else _rvc_name)
                holder = device.link if isinstance(device.link, LinkTap) else None
                if holder is not None:  # a fault's filter is on this wire: trace what passes it
                    holder.link = _ToMcu(holder.link, seen)
                else:
                    device.connect(_ToMcu(device.link, seen))
        if bench.can_bus is not None:
            frames = self.frames.setdefault("wire motor can (to the motor)", deque())
            name, bitrate, f = _can_name(bench.motor_device.mode), bench.can_bus.bitrate, rig.f_cpu_hz

            def on_frame(frame: CanFrame, t: int) -> None:
                bits = frame_bits(frame.arbitration_id, frame.data, frame.extended)
                frames.append((t - bits * f // bitrate, t, name(frame)))
            can_tap(rig).listeners.append(on_frame)

    def prune_before(self, t: int) -> None:
        """Forget the frames that ended before cycle t."""
        for frames in self.frames.values():
            while frames and frames[0][1] < t:
                frames.popleft()
