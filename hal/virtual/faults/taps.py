"""Taps on the virtual bench's wires: where byte and frame faults act, and where the campaign's observer listens.

* :class:`LinkTap` sits between a device model and the MCU side of its UART (``device.connect(tap)``): the
  bytes the device sends pass each fault's ``filter`` before they are scheduled on the line.
* :class:`PeerTap` sits between the MCU's UART and the device (``uart.connect(tap)``): bytes towards the device
  are shown to listeners (the observer) with their stop-bit end times, then handed on unchanged.
* :class:`CanDeviceTap` stands for the motor on the virtual CAN bus: frames the motor sends and frames it
  receives pass the frame faults (destroyed, or delayed by a retransmission) and the listeners.

One tap per wire (:func:`tap_wire` finds or installs it), so the observer and any number of faults share it.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from typing import Any, Protocol

from hal.can import CanFrame

__all__ = ["CanDeviceTap", "FrameFault", "LinkTap", "PeerTap", "can_tap", "peer_tap", "tap_wire"]


class FrameFault(Protocol):
    """A fault on CAN frames: None when the frame is destroyed, else the extra delay in seconds (0: on time)."""

    def on_frame(self, frame: CanFrame, t_s: float) -> float | None:
        """What happens to frame, ending at t_s."""
        ...


class LinkTap:
    """The device's link to the MCU with byte filters in between (device -> MCU)."""

    def __init__(self, link: Any, f_hz: int) -> None:
        """Pass bytes on to link (the MCU side of a UART) after the filters; times in ticks of f_hz."""
        self.link, self.f_hz = link, f_hz
        self.filters: list[Any] = []

    def transmit_to_mcu(self, data: bytes, start_cycles: int) -> list[int]:
        """Filter data sent from start_cycles, then schedule what is left on the line."""
        t_s = start_cycles / self.f_hz
        for f in self.filters:
            data = f.filter(data, t_s)
        return self.link.transmit_to_mcu(data, start_cycles) if data else []


class PeerTap:
    """The device as the MCU's UART sees it, with listeners on the bytes towards it (MCU -> device)."""

    def __init__(self, device: Any) -> None:
        """Hand every byte on to device."""
        self.device = device
        self.listeners: list[Callable[[bytes, Sequence[int]], None]] = []

    def on_bytes(self, data: bytes, end_times_cycles: Sequence[int]) -> None:
        """Show the bytes to the listeners, then give them to the device."""
        for listen in self.listeners:
            listen(data, end_times_cycles)
        self.device.on_bytes(data, end_times_cycles)

    def advance_to(self, t_cycles: int) -> None:
        """Let the device catch up."""
        self.device.advance_to(t_cycles)


class CanDeviceTap:
    """The motor's place on the virtual CAN bus: it offers the motor's frames and receives frames for it."""

    def __init__(self, device: Any, bus: Any) -> None:
        """Stand between device (an Ak60Can on bus) and bus."""
        self.device, self.bus = device, bus
        self.f_hz = bus.world.f_hz
        self.rx_faults: list[FrameFault] = []  # motor -> MCU
        self.tx_faults: list[FrameFault] = []  # MCU -> motor
        self.listeners: list[Callable[[CanFrame, int], None]] = []

    def _fate(self, faults: list[FrameFault], frame: CanFrame, t: int) -> int | None:
        delay = 0.0
        for f in faults:
            d = f.on_frame(frame, t / self.f_hz)
            if d is None:
                return None
            delay += d
        return t + round(delay * self.f_hz)

    # the device's side (it calls bus.offer / bus.attach)
    def attach(self, node: Any) -> None:
        """The device attaches itself: already done through this tap."""

    def offer(self, node: Any, frame: CanFrame, ready: int) -> None:
        """The motor sends frame from tick ready on: through the faults, then on the bus as this tap."""
        at = self._fate(self.rx_faults, frame, max(ready, self.bus.world.now))
        if at is not None:
            self.bus.offer(self, frame, at)

    # the bus's side
    def on_frame(self, frame: CanFrame, t: int) -> None:
        """A frame from the MCU ended at t: through the faults to the motor, and to the listeners when delivered."""
        at = self._fate(self.tx_faults, frame, t)
        if at is not None:
            for listen in self.listeners:
                listen(frame, at)
            self.device.on_frame(frame, at)

    def tx_done(self, frame: CanFrame, t: int) -> None:
        """The motor's frame left."""
        self.device.tx_done(frame, t)


def can_tap(rig: Any) -> CanDeviceTap:
    """The rig's CAN tap on the motor (installed on first use); ValueError on a bench without a CAN motor."""
    taps = rig.taps
    if "can" not in taps:
        bench = rig.bench
        if bench.can_bus is None:
            raise ValueError(f"the bench's motor link {bench.motor_link!r} has no CAN bus")
        device, bus = bench.motor_device, bench.can_bus
        tap = CanDeviceTap(device, bus)
        nodes = bus._nodes  # the bus's node list: the tap takes the motor's place, the order kept
        nodes[nodes.index(device)] = tap
        device.bus = tap
        taps["can"] = tap
    tap: CanDeviceTap = taps["can"]
    return tap


class _ByteFrames:
    """A byte fault on CAN frames: a frame whose data the fault changes fails its CRC and is destroyed."""

    def __init__(self, fault: Any) -> None:
        self.fault = fault

    def on_frame(self, frame: CanFrame, t_s: float) -> float | None:
        return 0.0 if self.fault.filter(frame.data, t_s) == frame.data else None


def tap_wire(rig: Any, wire: str, fault: Any) -> None:
    """Put fault (a ByteFault) on wire: "motor_rx" (motor -> MCU, UART or CAN) or "imu_rx" (IMU -> MCU)."""
    bench = rig.bench
    if wire == "motor_rx" and bench.can_bus is not None:
        can_tap(rig).rx_faults.append(_ByteFrames(fault))
        return
    if wire not in ("motor_rx", "imu_rx"):
        raise ValueError(f"wire {wire!r} unknown: motor_rx or imu_rx")
    taps = rig.taps
    if wire not in taps:
        device = bench.motor_device if wire == "motor_rx" else bench.imu
        taps[wire] = tap = LinkTap(device.link, bench.f_cpu_hz)
        device.connect(tap)
    taps[wire].filters.append(fault)


def peer_tap(rig: Any) -> PeerTap:
    """The tap between the motor UART and the motor (installed on first use)."""
    taps = rig.taps
    if "motor_tx" not in taps:
        uart = rig.bench.motor_uart
        taps["motor_tx"] = tap = PeerTap(uart.peer)
        uart.connect(tap)
    tap: PeerTap = taps["motor_tx"]
    return tap
