"""The firmware's motor driver, chosen by the link its configuration names (``FirmwareConfig.motor_link``)."""

from __future__ import annotations

from typing import Any

from firmware.config import FirmwareConfig
from firmware.drivers.motor_link import MotorLink
from hal.interfaces import Board
from hal.links import link_entry, resolve

__all__ = ["make_motor_driver"]


def make_motor_driver(board: Board, config: FirmwareConfig) -> MotorLink:
    """The registered driver of ``config.motor_link`` built on the board's port for it."""
    cls: Any = resolve(link_entry(config.motor_link, "motor_link").driver)
    driver: MotorLink = cls.from_board(board, config)
    return driver
