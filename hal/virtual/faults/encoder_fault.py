"""What the encoder faults share: they stand between the encoder timer and the shaft angle it counts."""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

from hal.virtual.faults.base import FaultRig, Injector

__all__ = ["EncoderFault"]


class EncoderFault(Injector):
    """Replaces the angle the encoder timer counts with ``angle(t_s, true)`` in and after the window."""

    WHERE = "encoder lines (A/B into the timer in encoder mode)"

    def arm(self, rig: FaultRig) -> None:
        """Wrap the bench encoder timer's angle source."""
        timer: Any = rig.bench.encoder
        true: Callable[[int], float] = timer._angle_rad  # the timer's angle source (the encoder mount)
        f = rig.f_cpu_hz
        self.at_onset: float | None = None  # the angle counted at the first read in the window

        def counted(t_cycles: int) -> float:
            a = true(t_cycles)
            t_s = t_cycles / f
            if t_s < self.onset_s:
                return a
            if self.at_onset is None:
                self.at_onset = a
            b = self.angle(t_s, a)
            if b != a:
                self.note(t_s, f"counted {b:.5f} rad instead of {a:.5f} rad")
            return b
        timer._angle_rad = counted

    def angle(self, t_s: float, true_rad: float) -> float:
        """The angle counted at t_s (>= onset) when the shaft is at true_rad (subclasses)."""
        raise NotImplementedError
