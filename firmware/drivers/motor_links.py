"""The motor links by name (the firmware's side): the driver class of each link, as python-can picks an
interface by name.

``--motor-link NAME`` (``pafp run``) and the firmware profile's ``[motor] link`` pick an entry; each entry
names a driver class with a ``from_board(board, config)`` constructor, imported only when the link is
used. The virtual bench's side of a link (how its device is wired) is the entry of the same name in
:data:`hal.virtual.wiring.MOTOR_WIRING`. A package adds a link through the entry-point group
``pafp.motor_links`` (docs/hal.md, "Motor links").
"""

from __future__ import annotations

from typing import TYPE_CHECKING, Any

from firmware.drivers.motor_link import MotorLink
from hal.interfaces import Board
from hal.registry import Registry

if TYPE_CHECKING:  # firmware.config checks its motor_link against MOTOR_LINKS
    from firmware.config import FirmwareConfig

__all__ = ["MOTOR_LINKS", "make_motor_driver"]

MOTOR_LINKS = Registry("motor link", {
    "uart": "firmware.drivers.motor:MotorDriver",
    "can-servo": "firmware.drivers.can_servo:CanServoDriver",
    "can-mit": "firmware.drivers.can_mit:CanMitDriver",
}, group="pafp.motor_links")
"""Motor link name -> the firmware's driver class (VESC servo mode on the UART; servo or MIT mode on CAN)."""


def make_motor_driver(board: Board, config: FirmwareConfig) -> MotorLink:
    """The registered driver of ``config.motor_link`` built on the board's port for it."""
    cls: Any = MOTOR_LINKS.load(config.motor_link, "motor_link")
    driver: MotorLink = cls.from_board(board, config)
    return driver
