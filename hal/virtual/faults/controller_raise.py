"""Controller raising: the control law throws (a division by zero, an index error) in the window."""

from __future__ import annotations

from typing import Any

from hal.virtual.faults.controller_fault import ControllerFault

__all__ = ["ControllerRaise", "InjectedControllerError"]


class InjectedControllerError(RuntimeError):
    """The exception the faulty controller raises."""


class ControllerRaise(ControllerFault):
    """``update`` raises in the window."""

    NAME = "controller_raise"
    HAZARD = "no valid current command: the motor holds its last one"

    def misbehave(self, obs: Any) -> object:
        """Raise."""
        self.note(obs.t_s, "controller raised InjectedControllerError")
        raise InjectedControllerError(f"injected at {obs.t_s:.4f} s")
