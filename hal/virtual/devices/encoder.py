"""The quadrature encoder on the ankle's output pulley, bound to the plant through the world.

The encoder is incremental: its zero is wherever the foot was at power-up. The timer in encoder mode
(:class:`~hal.virtual.timer.VirtualEncoderTimer`) asks for the shaft angle at the instant the firmware
reads CNT; this mount answers with the plant's ankle angle then, after running every device event
before that instant (so the plant's time never goes back), relative to the power-up angle plus a
mounting offset.
"""

from __future__ import annotations

import logging
import math

from hal.virtual.devices.world import World

__all__ = ["EncoderMount"]

log = logging.getLogger(__name__)


class EncoderMount:
    """Shaft angle of the output encoder: ``theta(t) - theta(power-up) + offset_rad``, in radians.

    >>> from hal.virtual.plant import Plant
    >>> mount = EncoderMount(World(Plant(initial_angle_rad=0.3), 1000))
    >>> mount.angle_rad(0)
    0.0
    """

    def __init__(self, world: World, offset_rad: float = 0.0) -> None:
        """Mount on world's plant; the angle reads offset_rad at the plant's present time."""
        if not math.isfinite(offset_rad):
            raise ValueError(f"offset_rad = {offset_rad!r} must be finite")
        self.world = world
        self.offset_rad = offset_rad
        plant = world.plant
        self.zero_rad = plant.output_angle_rad(plant.latest_time_s)
        self.late_queries = 0

    def angle_rad(self, t_cycles: int) -> float:
        """The encoder shaft angle at tick t_cycles (the callable a VirtualEncoderTimer takes).

        A time the plant has already passed (only the timer's wrap-interrupt counter asks for one,
        when a window start lies behind the world) is answered with the angle at the plant's latest
        time and counted in ``late_queries``.
        """
        world = self.world
        world.advance_to(t_cycles)
        plant = world.plant
        t_s = t_cycles / world.f_hz
        if t_s < plant.latest_time_s:
            self.late_queries += 1
            log.debug("encoder angle asked for %.9f s, plant already at %.9f s", t_s, plant.latest_time_s)
            t_s = plant.latest_time_s
        return plant.output_angle_rad(t_s) - self.zero_rad + self.offset_rad
