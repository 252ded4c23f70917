"""summary.json's ``thermal`` and ``battery``, report.md's section on them and thermal.png.

``thermal``: the two-node winding model's temperatures (emulation only: a bench has no sensor in the copper), the
temperature the motor reported in its status replies (the bench figure), the steady state the walk tends to
(the model's steady state at the RMS current of the strides completed before any trip) and when the firmware
began derating or latched OVER_TEMPERATURE. ``battery`` (null on the ideal supply): energy per stride at the pack's
terminals (the motor's, plus the electronics' quiescent load hal/virtual/plant/battery.py QUIESCENT_W x the stride),
regeneration, the lowest bus voltage and strides and distance per charge at the speed group's walking
speed. The energy figures are a walking run's, over the strides completed before any fault latched; a suspended
foot, or a walk that completed none, has none (``energy_figures_left_out`` says why).

Walking speed: Schwartz et al. 2008 give each speed group's dimensionless speed v* = v / sqrt(g L)
(0.17, 0.29, 0.43 free, 0.56, 0.69; /work/shared/data/gait/README.md); v = v* sqrt(g L) with the leg length
L = 0.530 H (Winter, Biomechanics and Motor Control of Human Movement, 4th ed., Fig. 4.1: greater trochanter
height) of the report's 1.88 m subject, 0.996 m, whatever the body mass: free speed is 1.34 m/s. A stride is
``stride_s`` of the firmware profile at that speed.
"""

from __future__ import annotations

import math
from pathlib import Path
from typing import Any

from host_tools.reports.heat_log import HeatLog
from protocol.telemetry import FaultReason

__all__ = ["DIMENSIONLESS_SPEED", "LEG_LENGTH_M", "battery_summary", "plot_thermal", "supply_text", "thermal_lines",
           "thermal_summary", "walking_speed_m_s"]

DIMENSIONLESS_SPEED = {"very-slow": 0.17, "slow": 0.29, "free": 0.43, "fast": 0.56, "very-fast": 0.69}
"""Each --speed group's dimensionless walking speed v / sqrt(g L) (Schwartz et al. 2008)."""
LEG_LENGTH_M = 0.530 * 1.88
"""Leg length of the report's subject: greater-trochanter height 0.530 H (Winter) of H = 1.88 m."""
GRAVITY_M_S2 = 9.81


def walking_speed_m_s(speed: str | None) -> float:
    """Walking speed of a --speed group (None: free speed, the packaged default curve's group)."""
    return DIMENSIONLESS_SPEED[speed or "free"] * math.sqrt(GRAVITY_M_S2 * LEG_LENGTH_M)


def _finite(x: float, digits: int) -> float | None:
    return round(x, digits) if math.isfinite(x) else None


def thermal_summary(r: Any) -> dict:
    """summary.json's ``thermal`` of a run (runner.RunResult with its ``heat`` record)."""
    heat: dict = r.heat
    log: HeatLog = heat["log"]
    winding = heat.get("winding")
    sup = r.firmware.supervisor
    over = sup.tripped_at_s if sup.reason is FaultReason.OVER_TEMPERATURE else None
    derating = r.firmware.thermal.derating_since_s
    end_w, end_h = (winding.winding_c, winding.housing_c) if winding is not None else \
        (log.meter.temp_motor_c, math.nan)
    steady = math.nan
    tripped = sup.tripped_at_s if sup.tripped_at_s is not None else math.inf
    rms = log.rms_current_a(tripped)  # the walk's, not the safe state's after a trip
    steady_hot = math.nan
    if winding is not None and math.isfinite(rms):
        steady = winding.steady_state_c(rms)[0]  # depends on the ambient only, not the state
        steady_hot = _pessimistic_steady_c(heat["motor"], heat["ambient_c"], rms)
    fast, slow = winding.params.time_constants_s() if winding is not None else (math.nan, math.nan)
    return {
        "emulation_only": True,
        "model": "two-node" if winding is not None else "single-node",
        "motor": heat["motor"],
        "ambient_c": heat["ambient_c"],
        "winding_c_max": _finite(max(log.winding_c_max, end_w), 2),
        "winding_c_end": _finite(end_w, 2),
        "housing_c_end": _finite(end_h, 2),
        "winding_c_by_stride": [round(row.winding_c, 2) for row in log.strides],
        "housing_c_by_stride": [_finite(row.housing_c, 2) for row in log.strides],
        "rms_current_a": _finite(rms, 3),
        "steady_state_c": _finite(steady, 1) if not math.isinf(steady) else "runaway",
        # the same with the housing-to-ambient resistance at the upper end of its range (the design bound)
        "steady_state_pessimistic_c": _finite(steady_hot, 1) if not math.isinf(steady_hot) else "runaway",
        "time_constants_s": [_finite(fast, 1), _finite(slow, 1)],
        "derating_started_s": None if derating is None else round(derating, 4),
        "over_temperature_at_s": None if over is None else round(over, 4),
        "motor_reported_c_max": _finite(log.reported_c_max, 1),
        "motor_reported_c_by_stride": [_finite(row.reported_c, 1) for row in log.strides],
    }


def _pessimistic_steady_c(motor: str, ambient_c: float, rms_a: float) -> float:
    """The winding's steady state at rms_a with the motor's housing resistance at its pessimistic end."""
    from hal.virtual.plant.motors import load_motor
    from hal.virtual.plant.thermal import ThermalParams, WindingThermal

    params = ThermalParams.from_motor(load_motor(motor), "pessimistic")
    return WindingThermal(params, ambient_c).steady_state_c(rms_a)[0]


def _walked_strides(r: Any, log: HeatLog) -> tuple[int, str | None]:
    """(how many strides walked count, why none does): only a walking run's strides completed before the supervisor
    latched a fault count (after it the foot stands in its safe state, spending next to nothing, which would make
    any distance per charge)."""
    if getattr(r.config, "scenario", "suspended") != "walk":
        return 0, "the foot was not walking: --scenario walk measures them"
    tripped = r.firmware.supervisor.tripped_at_s
    done = [row for row in log.strides if tripped is None or row.end_s <= tripped]
    if not done:
        return 0, ("no stride completed" + (f" before the fault at {tripped:.3f} s" if tripped is not None else ""))
    return len(done), None


def supply_text(battery: dict | None) -> str:
    """One line on the supply for a command's printout: the ideal supply, or the pack with its walking figures.

    >>> supply_text({"name": "p", "energy_per_stride_j": None, "energy_figures_left_out": "no stride completed"})
    'p: no energy per stride or distance per charge (no stride completed)'
    """
    if battery is None:
        return "ideal supply"
    if battery["energy_per_stride_j"] is None:
        return (f"{battery['name']}: no energy per stride or distance per charge "
                f"({battery.get('energy_figures_left_out') or 'not measured'})")
    return (f"{battery['name']}: {battery['energy_per_stride_j']} J/stride over {battery.get('energy_strides')} "
            f"strides, {battery['distance_per_charge_km']} km per charge at {battery['speed_m_s']} m/s")


def battery_summary(r: Any, stride_s: float, speed: str | None) -> dict | None:
    """summary.json's ``battery`` of a run (None on the ideal supply)."""
    heat: dict = r.heat
    battery = heat.get("battery")
    if battery is None:
        return None
    log: HeatLog = heat["log"]
    from hal.virtual.plant.battery import QUIESCENT_W

    walked, why_not = _walked_strides(r, log)
    energies = log.stride_energies_j()[:walked]
    regenerated = log.stride_regenerations_j()[:walked]
    motor_per_stride = sum(energies) / len(energies) if energies else math.nan
    per_stride = motor_per_stride + QUIESCENT_W * stride_s  # the electronics draw whatever the motor does
    walked_s = len(energies) * stride_s
    p = battery.params
    strides = p.capacity_wh * 3600.0 / per_stride if per_stride > 0 else math.nan
    speed_m_s = walking_speed_m_s(speed)
    return {
        "name": p.name,
        "capacity_wh": round(p.capacity_wh, 2),
        "mass_kg": round(p.mass_kg, 3),
        "energy_per_stride_j": _finite(per_stride, 3),
        "motor_energy_per_stride_j": _finite(motor_per_stride, 3),
        "quiescent_w": round(QUIESCENT_W, 3),
        "energy_strides": len(energies),
        "energy_figures_left_out": why_not,
        "regenerated_j": round(battery.regenerated_j, 3),
        # regeneration the pack accepted within the strides counted (the start-up ramp and the safe state left out)
        "regenerated_per_stride_j": _finite(sum(regenerated) / walked, 3) if walked else None,
        "walked_s": round(walked_s, 3),
        "rejected_regeneration_j": round(battery.rejected_j, 3),
        "min_bus_v": _finite(log.bus_v_min, 3),
        "bus_v_by_stride": [round(row.bus_v, 3) for row in log.strides],
        "bus_v_min_by_stride": [round(row.bus_v_min, 3) for row in log.strides],
        "soc_end": round(battery.soc, 6),
        "strides_per_charge": _finite(strides, 0),
        "speed_m_s": round(speed_m_s, 3),
        "stride_length_m": round(speed_m_s * stride_s, 3),
        "distance_per_charge_km": _finite(strides * speed_m_s * stride_s / 1000.0, 2),
    }


def thermal_lines(thermal: dict, battery: dict | None) -> list[str]:
    """report.md's section on the winding temperature and the battery."""
    def fig(v: Any, unit: str) -> str:
        return "n/a" if v is None else f"{v}{unit}"

    by_stride = thermal["winding_c_by_stride"]
    first, last = (by_stride[0], by_stride[-1]) if by_stride else (None, None)
    lines = ["", "## Winding temperature and battery", "",
             f"Motor {thermal['motor']} at {thermal['ambient_c']:g} °C ambient; winding and housing from the "
             f"{thermal['model']} thermal model (emulation only), the reported temperature from the motor's status "
             "replies (what a bench reads). thermal.png: per stride.", "",
             "| figure | value |", "|---|---|",
             f"| winding, end / max (emulation only) | {fig(thermal['winding_c_end'], ' °C')} / "
             f"{fig(thermal['winding_c_max'], ' °C')} |",
             f"| winding after stride 1 / last ({len(by_stride)}) | "
             f"{fig(first, ' °C')} / {fig(last, ' °C')} |",
             f"| steady state at the walk's RMS current {fig(thermal['rms_current_a'], ' A')} | "
             f"{fig(thermal['steady_state_c'], ' °C')} (time constants {thermal['time_constants_s']} s) |",
             f"| motor-reported max | {fig(thermal['motor_reported_c_max'], ' °C')} |",
             f"| derating started | {fig(thermal['derating_started_s'], ' s')} |",
             f"| OVER_TEMPERATURE latched | {fig(thermal['over_temperature_at_s'], ' s')} |"]
    if battery is None:
        lines += ["", "Supply: ideal (no battery profile: `--battery NAME`)."]
        return lines
    why_not = battery["energy_figures_left_out"]
    lines += [f"| battery | {battery['name']}, {battery['capacity_wh']} Wh |",
              f"| energy per stride at the battery | {fig(battery['energy_per_stride_j'], ' J')} (motor "
              f"{fig(battery['motor_energy_per_stride_j'], ' J')}, electronics {battery['quiescent_w']} W)"
              f"{'' if why_not is None else f' ({why_not})'} |",
              f"| regenerated per stride | {fig(battery['regenerated_per_stride_j'], ' J')} |",
              f"| regenerated into the battery | {battery['regenerated_j']} J |",
              f"| lowest bus voltage | {fig(battery['min_bus_v'], ' V')} |",
              f"| strides / distance per charge at {battery['speed_m_s']} m/s | "
              f"{fig(battery['strides_per_charge'], '')} / {fig(battery['distance_per_charge_km'], ' km')} |"]
    return lines


def plot_thermal(path: Path, thermal: dict, battery: dict | None) -> None:
    """thermal.png: winding, housing and motor-reported temperature per stride; the bus voltage per stride."""
    from host_tools.reports.plots import plot_per_stride

    series = {"winding (emulation only)": thermal["winding_c_by_stride"],
              "housing (emulation only)": thermal["housing_c_by_stride"],
              "motor-reported": thermal["motor_reported_c_by_stride"]}
    lower = ({"bus voltage at the stride's end": battery["bus_v_by_stride"],
              "lowest in the stride": battery["bus_v_min_by_stride"]} if battery is not None else {})
    plot_per_stride(path, series, "temperature (°C)", lower, "bus voltage (V)",
                    f"Winding temperature, {thermal['motor']} at {thermal['ambient_c']:g} °C ambient")
