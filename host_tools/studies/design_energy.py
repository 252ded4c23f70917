"""Where a walking design's regenerated energy comes from, stride by stride (issue 38's regeneration bound).

`walk_energy(profile, speed, strides)` runs `pafp run --scenario walk --controller <the profile's> --profile PROFILE
--speed SPEED` in-process with a sampler on the plant (SAMPLE_HZ) and returns, per completed stride, the ledger of
the energy that reaches the battery against the motion:

* ``joint_negative_j``: the ground's work on the ankle, its moment times the ankle's velocity where they agree (the
  walk's negative ankle work; a bench measures it with the pylon load cell's moment and the encoder);
* ``spring_release_j``: the parallel spring's work on the ankle where it gives back what it stored;
* ``actuator_absorbed_j``: the actuator's moment at the ankle times the velocity where they oppose (backdriven);
* ``rotor_absorbed_j``: Kt i times the rotor's speed where they oppose (the motor's current sensor and its encoder);
* ``regenerated_j``: what the battery accepted (its terminals, after the winding's, the switches' and the pack's own
  losses; summary.json's ``battery.regenerated_per_stride_j`` is the same count, on its own stride boundaries).

The chain the physics must obey: regenerated <= rotor absorbed = eta_back x actuator absorbed, and what the actuator
absorbs came from the ground, the spring, or the motion the motor itself put in. The plant's truth (moments,
velocity, current) is sampled: emulation only, the bench's equivalents named above. The issue's bound, the curve's
negative work / eta_back, counts the angle the curve has; the emulated walk's ankle does not follow it in stance
(docs/design.md, "Regeneration against the issue's bound").
"""

from __future__ import annotations

from dataclasses import dataclass, fields
from pathlib import Path
from typing import Any

from hal.virtual.events import EventDevice

__all__ = ["ADULT_PROFILE", "SAMPLE_HZ", "SPEEDS", "TABLE_STRIDES", "StrideEnergy", "WalkEnergy", "energy_table",
           "run_table", "stride_energies", "walk_energy", "walk_tables"]

SAMPLE_HZ = 2000
"""The sampler's rate: 100 samples a period of the fastest stance ringing seen (8-20 Hz); at it the rotor's absorbed
work comes out eta_back x the actuator's within 0.1 % over the 20-stride walks (the trapezoid on the clipped
powers)."""


@dataclass(frozen=True)
class StrideEnergy:
    """One stride's energy against the motion, J (module docstring)."""

    joint_negative_j: float
    spring_release_j: float
    actuator_absorbed_j: float
    rotor_absorbed_j: float
    regenerated_j: float


@dataclass(frozen=True)
class WalkEnergy:
    """A walk's per-stride ledger and what bounds it."""

    strides: list[StrideEnergy]
    faults: list[str]
    complete: bool
    eta_back: float
    curve_negative_j: float  # the packaged curve's negative ankle work per stride (host_tools/walk.py)
    run: dict[str, Any]  # the run's summary.json figures (host_tools/reports): encoder RMS, thermal, battery, events

    def mean(self, name: str) -> float:
        """The mean over the strides of one StrideEnergy field."""
        return sum(getattr(s, name) for s in self.strides) / len(self.strides)

    def means(self) -> dict[str, float]:
        """Every field's mean over the strides."""
        return {f.name: self.mean(f.name) for f in fields(StrideEnergy)}


class _Sampler(EventDevice):
    """The plant's truth and the battery's regenerated total every ``period`` cycles."""

    def __init__(self, bench: Any, period: int, out: list[tuple[float, ...]]) -> None:
        super().__init__()
        self.world, self.plant, self.meter = bench.world, bench.plant.raw, bench.motor.meter
        self.kt = self.plant.params.kt_nm_per_a
        self.period, self.out = period, out
        self.next_event = period
        self.world.add(self)

    def run_event(self) -> None:
        t = self.next_event
        t_s = t / self.world.f_hz
        s = self.plant.state_at(t_s)
        battery = self.meter.battery
        self.out.append((t_s, s.output_angle_rad, s.output_velocity_rad_s, s.output_torque_nm, s.external_torque_nm,
                         self.kt * s.current_q_a * s.motor_velocity_rad_s,
                         battery.regenerated_j if battery is not None else self.meter.watt_seconds_charged))
        self.next_event = t + self.period


def stride_energies(samples: list[tuple[float, ...]], start_s: float, stride_s: float,
                    spring_nm: Any) -> list[StrideEnergy]:
    """The ledger of every stride completed in ``samples`` (t, angle, velocity, actuator moment, ground moment,
    rotor power, battery's regenerated total), strides from ``start_s``; ``spring_nm(angle)`` the spring's moment."""
    out = []
    n = 0
    while True:
        lo, hi = start_s + n * stride_s, start_s + (n + 1) * stride_s
        rows = [r for r in samples if lo <= r[0] <= hi]
        if not samples or samples[-1][0] < hi or len(rows) < 2:
            return out
        sums = [0.0, 0.0, 0.0, 0.0]
        prev = None
        for t, th, w, actuator, ground, rotor, _ in rows:
            powers = (max(0.0, ground * w), max(0.0, spring_nm(th) * w), max(0.0, -actuator * w), max(0.0, -rotor))
            if prev is not None:
                dt = t - prev[0]
                for k in range(4):
                    sums[k] += 0.5 * (powers[k] + prev[1][k]) * dt
            prev = (t, powers)
        out.append(StrideEnergy(*sums, regenerated_j=rows[-1][6] - rows[0][6]))
        n += 1


def walk_energy(profile: str | Path, speed: str | None, strides: int, body_mass_kg: float = 80.0,
                seed: int = 0) -> WalkEnergy:
    """Walk the design profile ``strides`` strides at ``speed`` (its own controller, adult curves) and ledger it."""
    from firmware.config import load_firmware_config
    from hal.virtual.plant.design import load_design
    from host_tools.runner import RunConfig, run_virtual
    from host_tools.walk import curve_negative_work_j

    fw = load_firmware_config(profile)
    samples: list[tuple[float, ...]] = []
    holder: list[Any] = []

    def setup(bench: Any, firmware: Any) -> None:
        holder.append(bench.plant.raw.params)
        _Sampler(bench, int(bench.world.f_hz) // SAMPLE_HZ, samples)

    cfg = RunConfig(strides=strides, seed=seed, firmware=fw, scenario="walk", body_mass_kg=body_mass_kg, speed=speed,
                    population="adult", design=load_design(profile), setup=setup)
    result = run_virtual(cfg)
    params = holder[0]
    ledger = stride_energies(samples, result.gait_start_s, fw.stride_s, params.parallel_spring_torque_nm) \
        if result.gait_start_s is not None else []
    eta_back = params.efficiency_backdriven if params.efficiency_backdriven is not None else params.efficiency
    reason = result.firmware.supervisor.reason
    faults = [] if reason.value == 0 else [reason.name]
    return WalkEnergy(ledger, faults, result.complete, eta_back,
                      curve_negative_work_j(body_mass_kg, fw.stride_s, speed, "adult"), _run_figures(result, speed))


def _run_figures(result: Any, speed: str | None) -> dict[str, Any]:
    """What `pafp run` writes into summary.json of the figures docs/design.md quotes, from the same functions."""
    from host_tools.reports.gait_latency import event_summary
    from host_tools.reports.report import summarise
    from host_tools.reports.thermal import battery_summary, thermal_summary

    fw = result.firmware.config
    events = event_summary(result) or {}
    return {"encoder_rms_error_deg": summarise(result)["encoder_rms_error_deg"], "thermal": thermal_summary(result),
            "battery": battery_summary(result, fw.stride_s, speed), "detector": events.get("detector"),
            "derate_start_c": fw.thermal.derate_start_c}


SPEEDS = ("free", "fast")
ADULT_PROFILE = "designs/adult_80kg.toml"  # profiles/ (profile_path)
TABLE_STRIDES = 20


def _table_head(head: str) -> list[str]:
    """A markdown table's header row and its separator."""
    return [head, "|" + "---|" * (head.count("|") - 1)]


def energy_table(walks: dict[str, WalkEnergy]) -> str:
    """The markdown table of the walks' mean ledgers (J per stride) against the bounds."""
    head = ("| speed | strides | faults | negative ankle work: curve / walk | spring gives back | actuator absorbs "
            "| rotor absorbs | regenerated | bound: curve / eta_back | bound: eta_back x walk's |")
    lines = _table_head(head)
    for speed, w in walks.items():
        m = w.means()
        lines.append(
            f"| {speed} | {len(w.strides)} | {', '.join(w.faults) or 'none'} | {w.curve_negative_j:.2f} / "
            f"{m['joint_negative_j']:.2f} | {m['spring_release_j']:.2f} | {m['actuator_absorbed_j']:.2f} | "
            f"{m['rotor_absorbed_j']:.2f} | {m['regenerated_j']:.2f} | {w.curve_negative_j / w.eta_back:.2f} | "
            f"{w.eta_back * m['joint_negative_j']:.2f} |")
    return "\n".join(lines) + "\n"


def run_table(walks: dict[str, WalkEnergy]) -> str:
    """The markdown table of the walks' summary.json figures (`pafp run`'s, from the same run)."""
    head = ("| speed | strides | faults | gait events from | encoder RMS ° | steady °C nominal / pessimistic R_ha "
            "(margin to derating) | J/stride (motor alone) | regenerated J/stride | km/charge |")
    lines = _table_head(head)
    for speed, w in walks.items():
        run, th, b = w.run, w.run["thermal"], w.run["battery"]
        hot = th["steady_state_pessimistic_c"]
        lines.append(
            f"| {speed} | {len(w.strides)} | {', '.join(w.faults) or 'none'} | {run['detector']} | "
            f"{run['encoder_rms_error_deg']:.2f} | {th['steady_state_c']:.1f} / {hot:.1f} "
            f"({run['derate_start_c'] - hot:.1f}) | {b['energy_per_stride_j']:.2f} "
            f"({b['motor_energy_per_stride_j']:.2f}) | {b['regenerated_per_stride_j']:.2f} | "
            f"{b['distance_per_charge_km']:.1f} |")
    return "\n".join(lines) + "\n"


def walk_tables(walks: dict[str, WalkEnergy]) -> str:
    """docs/design.md's design_energy block: the runs' figures, then their energy ledgers."""
    return run_table(walks) + "\n" + energy_table(walks)
