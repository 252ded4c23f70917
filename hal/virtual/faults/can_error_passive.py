"""CAN error-passive: errors on the bus (EMI, a bad termination) destroy frames, which are sent again."""

from __future__ import annotations

import random

from hal.can import CanFrame
from hal.virtual.can_bits import frame_bits
from hal.virtual.faults.can_fault import CanFault

__all__ = ["CanErrorPassive"]

# passive error flag 6 + error delimiter 8 + intermission 3 + suspend transmission 8 bits (ISO 11898-1)
ERROR_FRAME_BITS = 25


class CanErrorPassive(CanFault):
    """Each frame in the window is hit with probability ``error_rate`` and sent again after an error frame and
    the suspend-transmission time of an error-passive node: its delivery is late by that much per hit."""

    NAME = "can_error_passive"
    HAZARD = "late commands and feedback: the loop runs on delayed data"
    PARAMS = {"error_rate": (0.5, 0.0, 0.95)}

    def __init__(self, *args: object, **kwargs: object) -> None:
        """See Injector; hits come from random.Random of (seed, name)."""
        super().__init__(*args, **kwargs)  # type: ignore[arg-type]
        self.rng = random.Random(f"{self.seed}:{self.NAME}")

    def fate(self, frame: CanFrame, t_s: float) -> float | None:
        """The delay of the retransmissions."""
        hits = 0
        while hits < 16 and self.rng.random() < self.params["error_rate"]:
            hits += 1
        bits = frame_bits(frame.arbitration_id, frame.data, frame.extended) + ERROR_FRAME_BITS
        return hits * bits / self.bitrate
