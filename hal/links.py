"""The motor links by name: one table, as python-can picks an interface by name.

Each entry names (as ``"module:attribute"`` strings, imported only when the link is used, so the
firmware importing this table imports no backend) the firmware's driver class (with a
``from_board(board, config)`` constructor), the function that wires the virtual device on the
virtual bench (``wire(bench, motor_config) -> device``), the port kind the board must carry and the
mode on that port. ``--motor-link NAME`` (``pafp run``) and the firmware profile's ``motor_link`` pick
an entry. docs/hal.md says how to add one.
"""

from __future__ import annotations

import importlib
from dataclasses import dataclass

__all__ = ["MOTOR_LINKS", "MotorLinkEntry", "link_entry", "resolve"]


@dataclass(frozen=True)
class MotorLinkEntry:
    """Where a link's pieces live."""

    driver: str
    bench: str
    port: str
    mode: str = ""


MOTOR_LINKS: dict[str, MotorLinkEntry] = {
    "uart": MotorLinkEntry("firmware.drivers.motor:MotorDriver", "hal.virtual.wiring:wire_uart_motor", "uart"),
    "can-servo": MotorLinkEntry("firmware.drivers.can_servo:CanServoDriver", "hal.virtual.wiring:wire_can_motor",
                                "can", "servo"),
    "can-mit": MotorLinkEntry("firmware.drivers.can_mit:CanMitDriver", "hal.virtual.wiring:wire_can_motor",
                              "can", "mit"),
}


def link_entry(name: str, where: str = "motor link") -> MotorLinkEntry:
    """The entry called name; ValueError naming where it came from and the choices otherwise."""
    try:
        return MOTOR_LINKS[name]
    except (KeyError, TypeError):
        raise ValueError(f"{where} {name!r} unknown: one of {sorted(MOTOR_LINKS)}") from None


def resolve(ref: str) -> object:
    """The attribute a ``"module:attribute"`` reference names."""
    module, _, attr = ref.partition(":")
    return getattr(importlib.import_module(module), attr)
