"""A force-sensing resistor under the heel or the toes, read through a voltage divider.

Interlink FSR 402 (datasheet "FSR 400 Series", PDS-10004): open above 10 MOhm below the actuation force
(about 0.2 N), then a resistance that falls as a power of the force over the sensitivity range (to about
20 N, where it stops falling: saturation); hysteresis +10 % average, (R_F+ - R_F-)/R_F+, i.e. the
resistance while the force falls is 10 % below the one while it rises (modelled on the sign of the force's
change over 1 ms, so the model keeps no state and a lazy reader sees the same values). The divider (the
datasheet's "FSR voltage divider"): FSR from the supply to the output, R_M to ground,
V = V+ R_M / (R_M + R_FSR).

The sensor sees ``load_share`` of the force of its region of the sole (its active area over the region's
contact area: a design estimate). ``fault``: None, ``"open"`` (a broken lead: 0 V) or ``"short"`` (V+).
Parameters (fsr_config.py) and sources: profiles/ground_sensors.toml. Compiled (setup.py): the ADC
samples it every scan.
"""

from __future__ import annotations

from collections.abc import Callable

from hal.virtual.devices.fsr_config import FsrParams

__all__ = ["Fsr", "FsrParams"]

FAULTS = (None, "open", "short")
_DT_S = 0.001  # the step over which the force's change is judged (hysteresis)


class Fsr:
    """One FSR on the force of its region of the sole, ``region_force_n(t_s)``; its divider's output voltage."""

    def __init__(self, params: FsrParams, region_force_n: Callable[[float], float], f_hz: int) -> None:
        """Bind the sensor to its region's force and the tick rate."""
        self.params = params
        self.region_force_n = region_force_n
        self.f_hz = f_hz
        self.fault: str | None = None
        self._dt = round(_DT_S * f_hz)  # the hysteresis step in ticks
        self._memo = (-1, 0.0)  # (tick, force): the last force computed (a reader every 1 ms asks for it again)

    def set_fault(self, mode: str | None) -> None:
        """Inject a fault (FAULTS) from now on; None clears it."""
        if mode not in FAULTS:
            raise ValueError(f"FSR fault {mode!r} unknown: one of {list(FAULTS)}")
        self.fault = mode

    def force_n(self, t_s: float) -> float:
        """The force on the active area at t_s (emulation truth)."""
        return self.params.load_share * self.region_force_n(t_s)

    def _force_at(self, t: int) -> float:
        tick, force = self._memo
        if tick != t:
            force = self.force_n(t / self.f_hz)
            self._memo = (t, force)
        return force

    def volts(self, t: int) -> float:
        """The divider's output at tick t."""
        p = self.params
        if self.fault == "open":
            return 0.0
        if self.fault == "short":
            return p.supply_v
        before = self._force_at(t - self._dt)
        f = self._force_at(t)
        return p.volts(p.resistance_ohm(f, f < before))
