"""The battery: open-circuit voltage against state of charge, internal resistance, sag and regeneration.

A pack of ``series`` x ``parallel`` identical cells is one voltage source E(SoC) = series * OCV_cell(SoC)
behind R = series * R_cell / parallel:

    V_bus = E(SoC) - R I            (I > 0 discharges, I < 0 is regeneration into the pack)
    dSoC/dt = -I / (3600 * parallel * Q_cell_Ah)

Given the electrical power the driver draws at the bus, P = V_bus I, the current is the smaller root of
R I^2 - E I + P = 0; above P_max = E^2 / (4 R) the pack cannot deliver (``deliverable`` is False and
the current is held at E / (2 R), the maximum-power point). Regeneration is accepted up to the pack's
charge-current limit and while the pack is below full charge; the rest is reported as rejected (the
driver burns it in its brake resistor or the motor windings), never stored.

Profiles: ``profiles/batteries/<name>.toml``, every value with its source (``hal.virtual.plant.sourced``).

>>> b = Battery(load_battery("molicel_p42a_6s1p"))
>>> round(b.open_circuit_v(), 2), round(b.params.capacity_wh, 1)
(25.16, 93.7)
"""

from __future__ import annotations

import math
from bisect import bisect_right
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from hal.virtual.plant.sourced import check_number, read_profile, read_sourced_table, resolve_profile, sourced_value

#: Directory of the battery profiles inside the packaged ``profiles``.
BATTERY_DIR = "batteries"

_CELL_SPEC: dict[str, tuple[float, float]] = {
    "capacity_ah": (0.05, 500.0),
    "resistance_ohm": (1e-4, 1.0),
    "max_charge_current_a": (0.0, 500.0),
    "mass_kg": (0.001, 5.0),
}
_PACK_SPEC: dict[str, tuple[float, float]] = {
    "series": (1.0, 30.0),
    "parallel": (1.0, 30.0),
}
#: Allowed cell open-circuit voltages (any lithium chemistry fits; catches mV written as V).
_OCV_RANGE = (1.5, 4.5)


@dataclass(frozen=True)
class BatteryParams:
    """One pack: cell data (capacity, resistance, OCV curve) and the series/parallel arrangement."""

    name: str
    series: int
    parallel: int
    cell_capacity_ah: float
    cell_resistance_ohm: float
    cell_max_charge_current_a: float
    cell_mass_kg: float
    soc_points: tuple[float, ...]
    ocv_points_v: tuple[float, ...]

    def __post_init__(self) -> None:
        """The OCV table: same length, SoC from 0 to 1 strictly rising, OCV non-decreasing."""
        if len(self.soc_points) != len(self.ocv_points_v) or len(self.soc_points) < 2:
            raise ValueError(
                f"battery {self.name}: ocv.soc and ocv.cell_v need the same length >= 2 "
                f"(got {len(self.soc_points)} and {len(self.ocv_points_v)})")
        if self.soc_points[0] != 0.0 or self.soc_points[-1] != 1.0:
            raise ValueError(f"battery {self.name}: ocv.soc must run from 0.0 to 1.0, got {self.soc_points!r}")
        for lo, hi in zip(self.soc_points[:-1], self.soc_points[1:], strict=True):
            if not hi > lo:
                raise ValueError(f"battery {self.name}: ocv.soc must rise strictly, got {lo!r} then {hi!r}")
        for lo, hi in zip(self.ocv_points_v[:-1], self.ocv_points_v[1:], strict=True):
            if hi < lo:
                raise ValueError(f"battery {self.name}: ocv.cell_v must not fall with SoC, got {lo!r} then {hi!r}")

    @property
    def capacity_ah(self) -> float:
        """Pack charge capacity."""
        return self.cell_capacity_ah * self.parallel

    @property
    def capacity_wh(self) -> float:
        """Pack energy from full to empty at open circuit: Q * integral of E over SoC (trapezoids)."""
        area = 0.0
        for i in range(len(self.soc_points) - 1):
            width = self.soc_points[i + 1] - self.soc_points[i]
            area += width * (self.ocv_points_v[i] + self.ocv_points_v[i + 1]) / 2.0
        return self.capacity_ah * self.series * area

    @property
    def resistance_ohm(self) -> float:
        """Pack internal resistance, series * R_cell / parallel."""
        return self.series * self.cell_resistance_ohm / self.parallel

    @property
    def max_charge_current_a(self) -> float:
        """Largest regeneration current the pack accepts."""
        return self.cell_max_charge_current_a * self.parallel

    @property
    def mass_kg(self) -> float:
        """Mass of the cells (no enclosure, wiring or BMS)."""
        return self.cell_mass_kg * self.series * self.parallel

    def open_circuit_v(self, soc: float) -> float:
        """Pack open-circuit voltage at state of charge ``soc`` (clamped to [0, 1]), linear in the table."""
        s = min(1.0, max(0.0, soc))
        i = min(bisect_right(self.soc_points, s), len(self.soc_points) - 1)
        s0, s1 = self.soc_points[i - 1], self.soc_points[i]
        v0, v1 = self.ocv_points_v[i - 1], self.ocv_points_v[i]
        return self.series * (v0 + (v1 - v0) * (s - s0) / (s1 - s0))


class Battery:
    """State of charge and energy bookkeeping of one pack."""

    def __init__(self, params: BatteryParams, soc: float = 1.0) -> None:
        """A pack at state of charge ``soc`` (default full)."""
        if not (math.isfinite(soc) and 0.0 <= soc <= 1.0):
            raise ValueError(f"battery state of charge {soc!r} is outside the allowed range [0, 1]")
        self.params = params
        self.soc = soc
        self.current_a = 0.0
        self.bus_v = params.open_circuit_v(soc)
        self.deliverable = True
        self.discharged_j = 0.0      # energy delivered at the terminals
        self.regenerated_j = 0.0     # energy accepted at the terminals from regeneration
        self.rejected_j = 0.0        # regeneration the pack could not take
        self.loss_j = 0.0            # I^2 R in the pack
        self.emf_limit_v: float | None = None
        """A supply sag (a weak cell, a loose lead): the pack's EMF is at most this; None: its OCV."""

    def open_circuit_v(self) -> float:
        """Open-circuit voltage at the present state of charge (at most ``emf_limit_v`` during a sag)."""
        e = self.params.open_circuit_v(self.soc)
        limit = self.emf_limit_v
        return e if limit is None or e <= limit else limit

    def sag(self, voltage_v: float | None) -> None:
        """From now on the pack's EMF is at most ``voltage_v`` (>= 0) behind its own resistance; None ends the sag."""
        if voltage_v is not None and not (math.isfinite(voltage_v) and voltage_v >= 0.0):
            raise ValueError(f"battery sag voltage {voltage_v!r} is outside the allowed range: a finite number >= 0")
        self.emf_limit_v = voltage_v

    @property
    def empty(self) -> bool:
        """Whether the pack is at zero state of charge."""
        return self.soc <= 0.0

    def step_current(self, dt_s: float, current_a: float) -> float:
        """Carry ``current_a`` (>0 discharge, <0 regeneration) for ``dt_s``; return the bus voltage."""
        p = self.params
        e = self.open_circuit_v()
        r = p.resistance_ohm
        if current_a < 0.0:
            limit = p.max_charge_current_a if self.soc < 1.0 else 0.0
            accepted = max(current_a, -limit)
            self.rejected_j += (e - r * current_a) * (accepted - current_a) * dt_s
            current_a = accepted
        v = e - r * current_a
        self.current_a = current_a
        self.bus_v = v
        if current_a >= 0.0:
            self.discharged_j += v * current_a * dt_s
        else:
            self.regenerated_j -= v * current_a * dt_s
        self.loss_j += r * current_a * current_a * dt_s
        self.soc = min(1.0, max(0.0, self.soc - current_a * dt_s / (3600.0 * p.capacity_ah)))
        return v

    def current_for_power(self, power_w: float) -> float:
        """Bus current drawing ``power_w`` at the terminals (>0 load, <0 regeneration), and the check.

        Sets ``deliverable`` False when the load exceeds E^2/(4R), and returns the maximum-power current.
        """
        e = self.open_circuit_v()
        r = self.params.resistance_ohm
        disc = e * e - 4.0 * r * power_w
        self.deliverable = disc >= 0.0
        if not self.deliverable:
            return e / (2.0 * r)
        return (e - math.sqrt(disc)) / (2.0 * r) if r > 0.0 else power_w / e

    def step_power(self, dt_s: float, power_w: float) -> float:
        """Draw (or accept) ``power_w`` at the terminals for ``dt_s``; return the bus voltage."""
        return self.step_current(dt_s, self.current_for_power(power_w))


def battery_path(name: str) -> Path:
    """Path of the packaged battery profile ``name``."""
    from profiles import profile_path

    return profile_path(f"{BATTERY_DIR}/{name}.toml")


def battery_names() -> list[str]:
    """Names of the packaged battery profiles, sorted."""
    from profiles import profile_paths

    return [p.stem for p in profile_paths(f"{BATTERY_DIR}/*.toml")]


def battery_from_mapping(data: dict[str, Any], path: Path) -> BatteryParams:
    """Build BatteryParams from a parsed profile; ValueError names the file, key, value and range."""
    where = str(path)
    unknown = sorted(set(data) - {"cell", "pack", "ocv"})
    if unknown:
        raise ValueError(f"{where}: unknown table {unknown[0]} (allowed: cell, pack, ocv)")
    for table in ("cell", "pack", "ocv"):
        if not isinstance(data.get(table), dict):
            raise ValueError(f"{where}: missing table [{table}]")
    cell = read_sourced_table(data["cell"], _CELL_SPEC, "cell", where)
    pack = read_sourced_table(data["pack"], _PACK_SPEC, "pack", where)
    for key in ("series", "parallel"):
        if pack[key] != int(pack[key]):
            raise ValueError(f"{where}: pack.{key} = {pack[key]!r} must be a whole number in [1, 30]")
    unknown = sorted(set(data["ocv"]) - {"soc", "cell_v"})
    if unknown:
        raise ValueError(f"{where}: unknown key ocv.{unknown[0]} (allowed: cell_v, soc)")
    columns: dict[str, tuple[float, ...]] = {}
    for key, (lo, hi) in (("soc", (0.0, 1.0)), ("cell_v", _OCV_RANGE)):
        if key not in data["ocv"]:
            raise ValueError(f"{where}: missing key ocv.{key}")
        values, _ = sourced_value(data["ocv"][key], key, "ocv", where)
        if not isinstance(values, list):
            raise ValueError(f"{where}: ocv.{key} = {values!r} must be a list of numbers in [{lo}, {hi}]")
        columns[key] = tuple(check_number(v, key, "ocv", where, lo, hi) for v in values)
    try:
        return BatteryParams(
            name=path.stem, series=int(pack["series"]), parallel=int(pack["parallel"]),
            cell_capacity_ah=cell["capacity_ah"], cell_resistance_ohm=cell["resistance_ohm"],
            cell_max_charge_current_a=cell["max_charge_current_a"], cell_mass_kg=cell["mass_kg"],
            soc_points=columns["soc"], ocv_points_v=columns["cell_v"])
    except ValueError as exc:
        raise ValueError(f"{where}: {exc}") from None


def load_battery(name_or_path: str | Path) -> BatteryParams:
    """Load a packaged battery by name or a battery profile by path, fully checked."""
    path = resolve_profile(name_or_path, BATTERY_DIR, "battery")
    return battery_from_mapping(read_profile(path, "battery profile"), path)
