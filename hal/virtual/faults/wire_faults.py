"""Byte faults on a wire: bit errors at a given rate from a seeded generator, and bytes lost."""

from __future__ import annotations

import random

from hal.virtual.faults.base import ByteFault

__all__ = ["BitErrors", "flip_bits"]


def flip_bits(data: bytes, rate: float, rng: random.Random) -> bytes:
    """data with each of its bits flipped with probability rate (at least one bit of the chunk flipped)."""
    out = bytearray(data)
    flipped = False
    for k in range(len(out)):
        for bit in range(8):
            if rng.random() < rate:
                out[k] ^= 1 << bit
                flipped = True
    if not flipped:
        out[rng.randrange(len(out))] ^= 1 << rng.randrange(8)
    return bytes(out)


class BitErrors(ByteFault):
    """Each bit sent in the window flips with probability ``bit_error_rate`` (at least one per chunk sent)."""

    PARAMS = {"bit_error_rate": (0.01, 1e-6, 0.5)}

    def __init__(self, *args: object, **kwargs: object) -> None:
        """See Injector; the errors come from random.Random of (seed, name)."""
        super().__init__(*args, **kwargs)  # type: ignore[arg-type]
        self.rng = random.Random(f"{self.seed}:{self.NAME}")

    def change(self, data: bytes, t_s: float) -> bytes:
        """The bytes with bit errors."""
        return flip_bits(data, self.params["bit_error_rate"], self.rng)


class Lost(ByteFault):
    """Every byte sent in the window is lost on the wire."""

    def change(self, data: bytes, t_s: float) -> bytes:
        """Nothing arrives."""
        return b""
