"""How each motor link's virtual device is wired on the virtual bench (the ``bench`` entries of hal.links).

A wiring function gets the bench being built (its MCU, world and motor UART exist), the link's
registry entry and the AK60-6 configuration; it builds the device and the MCU-side port the link needs,
records them on the bench, and returns the :class:`~hal.virtual.devices.ak60.Ak60` whose plant,
meter and faults the tests reach as ``bench.motor``.
"""

from __future__ import annotations

from typing import Any

from hal.links import MotorLinkEntry
from hal.virtual.can import VirtualBxCan
from hal.virtual.can_bus import VirtualCanBus
from hal.virtual.devices.ak60 import Ak60
from hal.virtual.devices.ak60_can import Ak60Can, Ak60CanConfig
from hal.virtual.devices.ak60_config import Ak60Config

__all__ = ["wire_can_motor", "wire_uart_motor"]


def wire_uart_motor(bench: Any, entry: MotorLinkEntry, config: Ak60Config | None) -> Ak60:
    """The AK60-6 on the motor UART (VESC servo mode)."""
    device = Ak60(bench.world, config, link=bench.motor_uart)
    bench.motor_uart.connect(device)
    bench.motor_device = device
    return device


def wire_can_motor(bench: Any, entry: MotorLinkEntry, config: Ak60Config | None) -> Ak60:
    """A CAN bus at ``bench.can_bitrate``, the MCU's bxCAN on it, the AK60-6 in the entry's mode."""
    bench.can_bus = bus = VirtualCanBus(bench.world, bench.can_bitrate)
    bench.can = VirtualBxCan(bench.mcu.now, bus, "can")
    can_config = Ak60CanConfig(driver_id=bench.can_id, mode=entry.mode, **bench.can_options)
    bench.motor_device = device = Ak60Can(bench.world, bus, can_config, config)
    return device.core
