"""How each motor link's virtual device is wired on the virtual bench, by link name (:data:`MOTOR_WIRING`).

The names are those of the firmware's motor-link table (the drivers; docs/hal.md, "Motor links"): a
link is a driver entry there and a wiring entry here. A wiring function gets the bench being built (its
MCU, world and motor UART exist) and the AK60-6 configuration; it builds the device and the MCU-side
port the link needs, records them on the bench, and returns the :class:`~hal.virtual.devices.ak60.Ak60`
whose plant, meter and faults the tests reach as ``bench.motor``. A package adds one through the
entry-point group ``pafp.motor_wiring``.
"""

from __future__ import annotations

from typing import Any

from hal.registry import Registry
from hal.virtual.can import VirtualBxCan
from hal.virtual.can_bus import VirtualCanBus
from hal.virtual.devices.ak60 import Ak60
from hal.virtual.devices.ak60_can import Ak60Can, Ak60CanConfig
from hal.virtual.devices.ak60_config import Ak60Config
from hal.virtual.devices.registry import device_model

__all__ = ["MOTOR_WIRING", "wire_can_mit", "wire_can_motor", "wire_can_servo", "wire_uart_motor"]

MOTOR_WIRING = Registry("motor link", {
    "uart": "hal.virtual.wiring:wire_uart_motor",
    "can-servo": "hal.virtual.wiring:wire_can_servo",
    "can-mit": "hal.virtual.wiring:wire_can_mit",
}, group="pafp.motor_wiring")
"""Motor link name -> wire(bench, motor_config) -> the AK60-6 model on the bench."""


def wire_uart_motor(bench: Any, config: Ak60Config | None) -> Ak60:
    """The AK60-6 on the motor UART (VESC servo mode)."""
    device: Ak60 = device_model("ak60-6").build(bench.world, bench.motor_uart, seed=bench.seed, config=config)
    bench.motor_uart.connect(device)
    bench.motor_device = device
    return device


def wire_can_motor(bench: Any, config: Ak60Config | None, mode: str) -> Ak60:
    """A CAN bus at ``bench.can_bitrate``, the MCU's bxCAN on it, the AK60-6 in mode (servo or mit)."""
    bench.can_bus = bus = VirtualCanBus(bench.world, bench.can_bitrate)
    bench.can = VirtualBxCan(bench.mcu.now, bus, "can")
    can_config = Ak60CanConfig(driver_id=bench.can_id, mode=mode, **bench.can_options)
    bench.motor_device = device = Ak60Can(bench.world, bus, can_config, config)
    return device.core


def wire_can_servo(bench: Any, config: Ak60Config | None) -> Ak60:
    """The AK60-6 on CAN in servo mode."""
    return wire_can_motor(bench, config, "servo")


def wire_can_mit(bench: Any, config: Ak60Config | None) -> Ak60:
    """The AK60-6 on CAN in MIT mode."""
    return wire_can_motor(bench, config, "mit")
