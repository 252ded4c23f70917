"""The shared plant as seen from outside the device world (a bench probe, a test, a fixture).

Kept apart from world.py, which is compiled: this wrapper builds its timed methods on the fly and caches
them in the instance ``__dict__`` (docs/compiled.md, "Dynamic attributes").
"""

from __future__ import annotations

from typing import Any

from hal.virtual.devices.world import World
from hal.virtual.plant import Plant

__all__ = ["PlantView"]


class PlantView:
    """The shared plant as seen from outside the world: every query or input first advances the world.

    A bench probe or a test may read ``plant.output_angle_rad(t_s)`` directly; through this view the
    device events before ``t_s`` run first, so the plant never sees a device input in its past.
    Everything else (``params``, ``fixture``, ``latest_time_s``, ...) is passed through unchanged, looked
    up again at every access; the wrapper of a timed method is built once per view.
    """

    _TIMED = frozenset({
        "advance_to", "state_at", "output_angle_rad", "output_velocity_rad_s", "output_accel_rad_s2",
        "motor_angle_rad", "motor_velocity_rad_s", "current_q_a", "motor_sample", "energy_j",
        "set_current_command", "set_brake_current", "set_powered", "set_external_torque",
    })

    def __init__(self, world: World) -> None:
        """View the plant of ``world``."""
        self._world = world

    @property
    def raw(self) -> Plant:
        """The plant itself (bypasses the ordering: only for code that already advanced the world)."""
        return self._world.plant

    def __getattr__(self, name: str) -> Any:
        """Pass attributes through; wrap the timed methods so that the world advances first."""
        attr = getattr(self._world.plant, name)
        if name not in self._TIMED:
            return attr
        world = self._world

        def timed(*args: Any, **kwargs: Any) -> Any:
            """Advance the world to the call's time, then call the plant."""
            t_s = kwargs["t_s"] if "t_s" in kwargs else args[-1]
            world.advance_to(world.ticks(t_s))
            return attr(*args, **kwargs)

        timed.__doc__ = attr.__doc__
        self.__dict__[name] = timed  # built once: later lookups find it without __getattr__
        return timed
