"""Encoder direction reversed: A and B swapped (a wiring fault): the count runs backwards from the onset."""

from __future__ import annotations

from hal.virtual.faults.encoder_fault import EncoderFault

__all__ = ["EncoderReversed"]


class EncoderReversed(EncoderFault):
    """In the window the count mirrors the motion about the onset angle; afterwards it counts forwards again."""

    NAME = "encoder_reversed"
    HAZARD = "positive feedback: the loop drives the foot away from the reference, towards a stop"
    DANGEROUS = True

    def __init__(self, *args: object, **kwargs: object) -> None:
        """See Injector."""
        super().__init__(*args, **kwargs)  # type: ignore[arg-type]
        self.after: float | None = None

    def angle(self, t_s: float, true_rad: float) -> float:
        """Mirrored about the onset angle in the window; forwards from where it got to afterwards."""
        a0 = self.at_onset if self.at_onset is not None else true_rad
        if t_s < self.end_s:
            return 2.0 * a0 - true_rad
        if self.after is None:
            self.after = (2.0 * a0 - true_rad) - true_rad
        return true_rad + self.after
