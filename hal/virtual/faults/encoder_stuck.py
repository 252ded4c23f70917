"""Encoder stuck: the A/B lines stop changing (a loose connector); the counts of the motion meanwhile are lost."""

from __future__ import annotations

from hal.virtual.faults.encoder_fault import EncoderFault

__all__ = ["EncoderStuck"]


class EncoderStuck(EncoderFault):
    """In the window the count holds its onset value; afterwards it counts again, off by the motion it missed."""

    NAME = "encoder_stuck"
    HAZARD = "the loop sees no motion: it pushes on while the foot moves"

    def __init__(self, *args: object, **kwargs: object) -> None:
        """See Injector."""
        super().__init__(*args, **kwargs)  # type: ignore[arg-type]
        self.missed: float | None = None

    def angle(self, t_s: float, true_rad: float) -> float:
        """The onset angle in the window; the true angle less the missed motion after it."""
        held = self.at_onset if self.at_onset is not None else true_rad
        if t_s < self.end_s:
            return held
        if self.missed is None:
            self.missed = true_rad - held
        return true_rad - self.missed
