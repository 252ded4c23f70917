"""Controller returning NaN: the control law's output is not a number (a 0/0 in a gain schedule)."""

from __future__ import annotations

import math
from typing import Any

from hal.virtual.faults.controller_fault import ControllerFault

__all__ = ["ControllerNan"]


class ControllerNan(ControllerFault):
    """``update`` returns NaN in the window."""

    NAME = "controller_nan"
    HAZARD = "a NaN current command reaches the motor driver"

    def misbehave(self, obs: Any) -> object:
        """NaN."""
        self.note(obs.t_s, "controller returned NaN")
        return math.nan
