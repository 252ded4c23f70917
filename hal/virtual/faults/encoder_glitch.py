"""Encoder count glitch: a burst of noise pulses on A/B adds N counts at the onset; the count stays off."""

from __future__ import annotations

import math

from hal.virtual.faults.encoder_fault import EncoderFault

__all__ = ["EncoderGlitch"]

COUNTS_PER_REV = 4000  # the 1000-line encoder in x4 mode (DESIGN.md)


class EncoderGlitch(EncoderFault):
    """From the onset the counter is ``counts`` off (the duration is not used: lost counts never come back)."""

    NAME = "encoder_glitch"
    HAZARD = "the angle the loop closes on jumps: the foot is driven by the jump"
    PARAMS = {"counts": (40.0, -4000.0, 4000.0)}

    def angle(self, t_s: float, true_rad: float) -> float:
        """The true angle plus the glitch."""
        return true_rad + round(self.params["counts"]) * math.tau / COUNTS_PER_REV
