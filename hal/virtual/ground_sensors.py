"""Wiring of the ground sensors on the ADC: the load cell and the heel/toe FSRs, fed by the ground reaction.

THE ONE PLACE the ADC devices are wired (``ADC_CHANNELS`` and ``wire_ground_sensors``): the virtual bench
and the ``sim://ground-sensors`` acquisition board both call it. The channel order is the ADC's scan
order, which the firmware's driver reads by name (firmware/drivers/ground_sensors.py).

The heel and toe FSRs share the vertical force by where the centre of pressure is between them (all on
the heel sensor behind it, all on the toe sensor ahead of it, linearly in between). With no ground
(``NoGround``: the suspended bench) every sensor reads unloaded.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from hal.virtual.adc import VirtualAdc
from hal.virtual.checks import from_table
from hal.virtual.devices.fsr import Fsr, FsrParams
from hal.virtual.devices.load_cell import LoadCell, LoadCellParams
from profiles import profile_path, read_toml

__all__ = ["ADC_CHANNELS", "AdcSettings", "FootGeometry", "GroundSensors", "load_ground_profile",
           "wire_ground_sensors"]

ADC_CHANNELS = ("load_force", "load_moment", "fsr_heel", "fsr_toe")
"""The ADC's regular sequence, in scan order."""
DEFAULT_PROFILE = "ground_sensors.toml"


@dataclass(frozen=True)
class FootGeometry:
    """Where the FSRs sit and the sole's ends, m ahead of the ankle axis (profiles/ground_sensors.toml, [foot])."""

    heel_sensor_m: float = -0.04
    toe_sensor_m: float = 0.13
    ankle_height_m: float = 0.08
    heel_m: float = -0.06
    toe_m: float = 0.18

    def __post_init__(self) -> None:
        """ValueError unless heel_m <= heel sensor < toe sensor <= toe_m."""
        if not self.heel_m <= self.heel_sensor_m < self.toe_sensor_m <= self.toe_m:
            raise ValueError(f"[foot] needs heel_m <= heel_sensor_m < toe_sensor_m <= toe_m, got {self}")

    def toe_fraction(self, cop_m: float) -> float:
        """The share of the vertical force on the toe sensor for a CoP at cop_m."""
        x = (cop_m - self.heel_sensor_m) / (self.toe_sensor_m - self.heel_sensor_m)
        return min(1.0, max(0.0, x))


@dataclass(frozen=True)
class AdcSettings:
    """The board profile's [adc] table."""

    adc_clock_hz: float = 21e6
    sampling_cycles: float = 84.0
    conversion_cycles: float = 12.0
    sample_rate_hz: float = 1000.0
    bits: int = 12
    vref_v: float = 3.3
    noise_lsb_rms: float = 1.0

    @classmethod
    def from_board(cls, board: Mapping[str, Any]) -> AdcSettings:
        """From a board profile (its [adc] table; defaults when it has none)."""
        return from_table(cls, board.get("adc", {}), "adc")


def load_ground_profile(path: Path | None = None) -> tuple[LoadCellParams, FsrParams, FootGeometry]:
    """The load cell, FSR and foot parameters of profiles/ground_sensors.toml (or path)."""
    doc = read_toml(path or profile_path(DEFAULT_PROFILE), "ground sensor profile")
    return (LoadCellParams.from_table(doc.get("load_cell", {})), FsrParams.from_table(doc.get("fsr", {})),
            from_table(FootGeometry, doc.get("foot", {}), "foot"))


class GroundSensors:
    """The load cell, the two FSRs and the ADC reading them (fault-injection handles for tests)."""

    def __init__(self, adc: VirtualAdc, load_cell: LoadCell, heel: Fsr, toe: Fsr) -> None:
        """Hold the parts."""
        self.adc = adc
        self.load_cell = load_cell
        self.heel = heel
        self.toe = toe
        self.tick = 0  # the ADC's clock when the wiring was given none (codes_at sets it)

    def codes_at(self, t: int) -> list[int]:
        """The ADC's buffer at tick t (for a board that samples on its own schedule; wired with now=None)."""
        self.tick = t
        return self.adc.read()

    def set_fault(self, part: str, mode: str | None) -> None:
        """Fail one part (load_cell, fsr_heel, fsr_toe) in a mode its model knows."""
        parts: dict[str, LoadCell | Fsr] = {"load_cell": self.load_cell, "fsr_heel": self.heel, "fsr_toe": self.toe}
        if part not in parts:
            raise ValueError(f"ground sensor {part!r} unknown: one of {sorted(parts)}")
        parts[part].set_fault(mode)


def wire_ground_sensors(now: Callable[[], int] | None, f_hz: int, ground: Any, adc: AdcSettings, *, seed: int = 0,
                        profile: Path | None = None) -> GroundSensors:
    """The load cell and FSRs under ``ground`` (``at(t_s) -> (F_z, F_x, CoP)``) on a virtual ADC on clock ``now``
    (None: the clock ``GroundSensors.codes_at`` sets)."""
    cell_p, fsr_p, foot = load_ground_profile(profile)
    cell = LoadCell(cell_p, ground, f_hz, seed)

    def heel_force(t_s: float) -> float:
        fz, _, cop = ground.at(t_s)
        return fz * (1.0 - foot.toe_fraction(cop))

    def toe_force(t_s: float) -> float:
        fz, _, cop = ground.at(t_s)
        return fz * foot.toe_fraction(cop)

    heel, toe = Fsr(fsr_p, heel_force, f_hz), Fsr(fsr_p, toe_force, f_hz)
    pins = {**cell.outputs(), "fsr_heel": heel.volts, "fsr_toe": toe.volts}
    clock: list[GroundSensors] = []
    virtual = VirtualAdc(now if now is not None else lambda: clock[0].tick, f_hz, ADC_CHANNELS,
                         [pins[name] for name in ADC_CHANNELS],
                         sample_rate_hz=adc.sample_rate_hz, adc_clock_hz=adc.adc_clock_hz,
                         sampling_cycles=adc.sampling_cycles, conversion_cycles=adc.conversion_cycles,
                         bits=adc.bits, vref_v=adc.vref_v, noise_lsb_rms=adc.noise_lsb_rms, seed=seed)
    sensors = GroundSensors(virtual, cell, heel, toe)
    clock.append(sensors)
    return sensors
