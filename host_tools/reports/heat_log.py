"""The winding temperature and the supply over a run, one row per stride: bounded memory for 1000-stride walks.

The bench probe calls :meth:`HeatLog.sample` at every tenth of its samples (50 Hz; the lowest bus voltage comes
from the meter's every sample in between). The log keeps running extremes
and, at each stride boundary of the firmware's gait clock (``gait_start_s + k * stride_s``), one row: the
winding and housing temperatures of the thermal model (emulation only), the temperature the motor last
reported to the firmware (the bench figure), the bus voltage and the energy drawn at, and regenerated into, the
supply so far. A
1000-stride walk keeps 1000 rows, whatever its length in samples.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any

__all__ = ["HeatLog", "StrideHeat"]


@dataclass(frozen=True)
class StrideHeat:
    """The state at the end of one stride."""

    end_s: float
    winding_c: float
    housing_c: float
    reported_c: float
    bus_v: float
    bus_v_min: float  # the lowest bus voltage within the stride (the sag under its peak load)
    supply_energy_j: float  # net energy drawn at the supply since the start (regeneration subtracted)
    regenerated_j: float  # energy regenerated into the supply since the start (accepted by the pack, with one)
    amp2_s: float  # integral of the q current squared since the start (the two-node model's; NaN without it)


@dataclass
class HeatLog:
    """Running extremes and one :class:`StrideHeat` per stride of a run; see the module docstring."""

    meter: Any  # the motor model's meter (hal.virtual.devices.ak60_meter.Ak60Meter)
    feedback: Any  # the firmware's motor feedback (firmware.drivers.motor_link.MotorFeedback)
    gait_start: Any  # () -> the firmware's gait start in s, or None before it
    stride_s: float
    strides: list[StrideHeat] = field(default_factory=list)
    winding_c_max: float = -math.inf
    reported_c_max: float = math.nan
    bus_v_min: float = math.inf
    _stride_bus_v_min: float = math.inf
    gait_energy_j: float | None = None  # supply energy when the gait started (the start-up ramp is no stride)
    gait_regenerated_j: float = 0.0  # the regenerated energy then
    gait_amp2_s: float = math.nan  # the current-squared integral then
    gait_t_s: float = math.nan  # the time of that sample

    def supply_energy_j(self) -> float:
        """Net energy drawn at the supply so far: the pack's terminals with a battery, else the fixed supply's."""
        battery = self.meter.battery
        if battery is not None:
            return float(battery.discharged_j - battery.regenerated_j)
        return float(self.meter.watt_seconds - self.meter.watt_seconds_charged)

    def regenerated_j(self) -> float:
        """Energy regenerated into the supply so far: what the pack accepted with a battery, else the fixed supply's."""
        battery = self.meter.battery
        return float(battery.regenerated_j if battery is not None else self.meter.watt_seconds_charged)

    def _winding(self) -> tuple[float, float]:
        w = self.meter.winding
        if w is None:
            return float(self.meter.temp_motor_c), math.nan
        return float(w.winding_c), float(w.housing_c)

    def sample(self, t_s: float) -> None:
        """Take the state at t_s; close every stride that ended by then."""
        winding_c, housing_c = self._winding()
        if winding_c > self.winding_c_max:
            self.winding_c_max = winding_c
        reported = float(self.feedback.temp_motor_c)
        if math.isfinite(reported) and not reported <= self.reported_c_max:
            self.reported_c_max = reported
        bus_v = float(self.meter.v_in_v)
        lowest = float(self.meter.reset_v_in_min())  # the meter's every sample since the previous call
        if lowest < self.bus_v_min:
            self.bus_v_min = lowest
        if lowest < self._stride_bus_v_min:
            self._stride_bus_v_min = lowest
        start = self.gait_start()
        if start is None or t_s < start:
            return
        if self.gait_energy_j is None:
            self.gait_energy_j = self.supply_energy_j()
            self.gait_regenerated_j = self.regenerated_j()
            self.gait_amp2_s = self._amp2_s()
            self.gait_t_s = t_s
        while t_s >= start + (len(self.strides) + 1) * self.stride_s:
            self.strides.append(StrideHeat(t_s, winding_c, housing_c, reported, bus_v, self._stride_bus_v_min,
                                           self.supply_energy_j(), self.regenerated_j(), self._amp2_s()))
            self._stride_bus_v_min = bus_v

    def _amp2_s(self) -> float:
        w = self.meter.winding
        return math.nan if w is None else float(w.amp2_seconds)

    def rms_current_a(self, until_s: float = math.inf) -> float:
        """RMS q current over the strides completed by until_s (NaN without one or without the two-node model)."""
        done = [row for row in self.strides if row.end_s <= until_s]
        if not done:
            return math.nan
        span = done[-1].end_s - self.gait_t_s
        return math.sqrt((done[-1].amp2_s - self.gait_amp2_s) / span) if span > 0 else math.nan

    def stride_energies_j(self) -> list[float]:
        """Net supply energy of each completed stride (the first counted from the gait's start)."""
        out: list[float] = []
        before = self.gait_energy_j or 0.0
        for row in self.strides:
            out.append(row.supply_energy_j - before)
            before = row.supply_energy_j
        return out

    def stride_regenerations_j(self) -> list[float]:
        """Energy regenerated into the supply in each completed stride (the first counted from the gait's start)."""
        out: list[float] = []
        before = self.gait_regenerated_j
        for row in self.strides:
            out.append(row.regenerated_j - before)
            before = row.regenerated_j
        return out
