"""Wiring of the ground sensors on the ADC: the load cell and the heel/toe FSRs, fed by the ground reaction.

THE ONE PLACE the ADC devices are wired (``wire_ground_sensors``): the virtual bench and the
``sim://ground-sensors`` acquisition board both call it. It puts every ADC sensor of the device registry
(kind ``adc``: the shipped ``load-cell``, ``fsr-heel`` and ``fsr-toe``, then any a package adds through the
entry-point group ``pafp.devices``) on the ADC, in registry order, each sensor's channels in the order its
``outputs()`` gives them. That order is the ADC's scan order; the firmware's driver reads its channels by
name (firmware/drivers/ground_sensors.py), so a sensor added after the shipped ones changes none of theirs.

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
from hal.virtual.devices.load_cell import LoadCellParams
from profiles import profile_path, read_toml

__all__ = ["ADC_CHANNELS", "AdcSettings", "FootFsr", "FootGeometry", "GroundSensors", "foot_fsr",
           "load_ground_profile", "wire_ground_sensors"]

ADC_CHANNELS = ("load_force", "load_moment", "fsr_heel", "fsr_toe")
"""The shipped sensors' channels, the start of the ADC's regular sequence in scan order."""
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
    """The load cell, FSR and foot parameters of profiles/ground_sensors.toml (or path).

    A profile with ``base = "NAME.toml"`` (a packaged profile) is that profile with its own keys in place of the
    base's, table by table (a design's load cell, profiles/ground_sensors/: only what differs is written)."""
    doc = read_toml(path or profile_path(DEFAULT_PROFILE), "ground sensor profile")
    if "base" in doc:
        base = doc.pop("base")
        if not isinstance(base, str) or base == "":
            raise ValueError(f"{path}: base = {base!r} must name a packaged ground sensor profile, e.g. "
                             f"{DEFAULT_PROFILE!r}")
        merged = read_toml(profile_path(base), "ground sensor profile")
        for table, values in doc.items():
            if not isinstance(values, Mapping):
                raise ValueError(f"{path}: {table} must be a table ([{table}])")
            merged[table] = {**merged.get(table, {}), **values}
        doc = merged
    return (LoadCellParams.from_table(doc.get("load_cell", {})), FsrParams.from_table(doc.get("fsr", {})),
            from_table(FootGeometry, doc.get("foot", {}), "foot"))


class FootFsr:
    """An FSR at its place under the sole, on the ADC channel named after that place."""

    def __init__(self, fsr: Fsr, channel: str) -> None:
        """Hold the sensor and its channel name."""
        self.fsr = fsr
        self.channel = channel

    def outputs(self) -> dict[str, Callable[[int], float]]:
        """The output pin by ADC channel name."""
        return {self.channel: self.fsr.volts}

    def set_fault(self, mode: str | None) -> None:
        """Fail the FSR (hal/virtual/devices/fsr.py FAULTS)."""
        self.fsr.set_fault(mode)


def foot_fsr(ground: Any, f_hz: int, channel: str, profile: Path | None = None) -> FootFsr:
    """The heel (channel ``fsr_heel``) or toe (``fsr_toe``) FSR under ``ground``, from the ground sensor profile."""
    _, fsr_p, foot = load_ground_profile(profile)
    toe = {"fsr_heel": False, "fsr_toe": True}[channel]

    def force(t_s: float) -> float:
        fz, _, cop = ground.at(t_s)
        share = foot.toe_fraction(cop)
        return fz * (share if toe else 1.0 - share)

    return FootFsr(Fsr(fsr_p, force, f_hz), channel)


class GroundSensors:
    """The ADC sensors and the ADC reading them (``parts``: registry name with ``_`` for ``-`` -> sensor)."""

    def __init__(self, adc: VirtualAdc, parts: Mapping[str, Any]) -> None:
        """Hold the parts."""
        self.adc = adc
        self.parts = dict(parts)
        self.tick = 0  # the ADC's clock when the wiring was given none (codes_at sets it)

    @property
    def load_cell(self) -> Any:
        """The shipped load cell (hal/virtual/devices/load_cell.py)."""
        return self.parts["load_cell"]

    def codes_at(self, t: int) -> list[int]:
        """The ADC's buffer at tick t (for a board that samples on its own schedule; wired with now=None)."""
        self.tick = t
        return self.adc.read()

    def set_fault(self, part: str, mode: str | None) -> None:
        """Fail one part (load_cell, fsr_heel, fsr_toe, ...) in a mode its model knows."""
        if part not in self.parts:
            raise ValueError(f"ground sensor {part!r} unknown: one of {sorted(self.parts)}")
        self.parts[part].set_fault(mode)


def wire_ground_sensors(now: Callable[[], int] | None, f_hz: int, ground: Any, adc: AdcSettings, *, seed: int = 0,
                        profile: Path | None = None) -> GroundSensors:
    """Every registered ADC sensor under ``ground`` (``at(t_s) -> (F_z, F_x, CoP)``) on a virtual ADC on clock
    ``now`` (None: the clock ``GroundSensors.codes_at`` sets); ``profile`` goes to each sensor's build."""
    from hal.virtual.devices.registry import adc_sensor_models

    parts: dict[str, Any] = {}
    pins: dict[str, Callable[[int], float]] = {}
    for name, model in adc_sensor_models():
        part = model.build(ground, f_hz, seed=seed, config=profile)
        for channel, volts in part.outputs().items():
            if channel in pins:
                raise ValueError(f"ADC sensor {name!r}: channel {channel!r} is already taken: channels so far "
                                 f"{list(pins)}")
            pins[channel] = volts
        parts[name.replace("-", "_")] = part
    clock: list[GroundSensors] = []
    virtual = VirtualAdc(now if now is not None else lambda: clock[0].tick, f_hz, list(pins), list(pins.values()),
                         sample_rate_hz=adc.sample_rate_hz, adc_clock_hz=adc.adc_clock_hz,
                         sampling_cycles=adc.sampling_cycles, conversion_cycles=adc.conversion_cycles,
                         bits=adc.bits, vref_v=adc.vref_v, noise_lsb_rms=adc.noise_lsb_rms, seed=seed)
    sensors = GroundSensors(virtual, parts)
    clock.append(sensors)
    return sensors
