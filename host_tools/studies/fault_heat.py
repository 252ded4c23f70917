"""The hazard table's OVER_TEMPERATURE row (docs/safety.md): no injector makes it, the winding's own heat does.

The hot walk of tests/test_run_heat.py: the shipped firmware profile with ``[thermal] derate_start_c`` 41 °C
and ``fault_c`` 43 °C, walking at 20 kg and 40 °C ambient for 12 strides, seed 0. It is instrumented as a
campaign point (hal/virtual/faults/observer.py) against its pair, the same run with ``fault_c`` at the top of
its range (180 °C: OVER_TEMPERATURE cannot latch, the derating acts as in the hot run). The onset is the first
1 kHz sample at which the winding model is above ``fault_c`` (emulation only: the bench sees the temperature
the motor reports, at 10 Hz in 0.1 °C steps); the figures are the campaign's (`fault_point.figures`): detection
and the safe command on the wire after the onset, the unintended excursion until then, the safe state's own
excursion over the next 0.3 s, the speed entering a stop.

``python -m host_tools.studies.fault_heat`` prints the row; docs/safety.md holds it as a generated block
(host_tools/reports/doc_figures.py, checked by tests/test_doc_figures.py).
"""

from __future__ import annotations

import functools
import logging
import math
import tomllib
from typing import Any

from hal.virtual.events import EventDevice

__all__ = ["HOT_WALK", "SETTLE_S", "hot_walk_row", "hot_walk_table"]

HOT_WALK: dict[str, Any] = {"strides": 12, "body_mass_kg": 20.0, "ambient_c": 40.0, "seed": 0,
                            "derate_start_c": 41.0, "fault_c": 43.0}
"""The hot walk (tests/test_run_heat.py's): thresholds a few kelvin above the ambient, reached within a few strides."""
SETTLE_S = 0.3
"""How long the hot run goes on after the trip: the safe state's own motion is measured over it."""
_PAIR_FAULT_C = 180.0  # the top of [thermal]'s range (firmware.safety_limits.TEMPERATURE_RANGE_C)
HAZARD = "the winding overheats under a long or hot walk; the stop then releases the motor mid-stride"
CONTROL = "the motor's reported winding temperature above [thermal] fault_c (derating from derate_start_c first)"


class _WindingSampler(EventDevice):
    """The winding model's temperature at 1 kHz (emulation only), as the meter last computed it."""

    def __init__(self, world: Any, meter: Any, period: int, out: list[tuple[float, float]]) -> None:
        """Append (t_s, winding C) to out every period ticks of world."""
        super().__init__()
        self.world, self.meter, self.period, self.out = world, meter, period, out
        self.next_event = period
        world.add(self)

    def run_event(self) -> None:
        """Take a sample."""
        t = self.next_event
        self.out.append((t / self.world.f_hz, float(self.meter.temp_motor_c)))
        self.next_event = t + self.period


class _WindingProbe:
    """Armed like a fault (on the run's FaultRig): samples the winding temperature."""

    NAME = "winding_probe"

    def __init__(self) -> None:
        """No samples yet."""
        self.samples: list[tuple[float, float]] = []

    def arm(self, rig: Any) -> None:
        """Start the sampler on the bench's motor."""
        bench = rig.bench
        _WindingSampler(bench.world, bench.motor.meter, rig.f_cpu_hz // 1000, self.samples)


def _run(fault_c: float, duration_s: float | None) -> tuple[Any, Any, _WindingProbe]:
    from firmware.config import load_firmware_config
    from firmware.safety_limits import ThermalLimits
    from hal.virtual.faults.observer import Observer
    from host_tools.runner import RunConfig, run_virtual

    fw = load_firmware_config()
    fw = fw.with_changes(thermal=ThermalLimits(derate_start_c=HOT_WALK["derate_start_c"], fault_c=fault_c,
                                               derate_end_c=fw.thermal.derate_end_c, max_age_s=fw.thermal.max_age_s))
    obs, probe = Observer(), _WindingProbe()
    cfg = RunConfig(strides=HOT_WALK["strides"], scenario="walk", body_mass_kg=HOT_WALK["body_mass_kg"],
                    ambient_c=HOT_WALK["ambient_c"], seed=HOT_WALK["seed"], firmware=fw, trace_capacity=0,
                    faults=(obs, probe), duration_s=duration_s)
    return run_virtual(cfg), obs, probe


def _until(a: dict[str, Any], end_s: float) -> dict[str, Any]:
    """The observer's arrays up to end_s."""
    keep, cmd = a["t_s"] <= end_s, a["cmd_t_s"] <= end_s
    return {k: v[cmd] if k.startswith("cmd_") else v[keep] for k, v in a.items()}


@functools.lru_cache(maxsize=1)
def hot_walk_row() -> dict[str, Any]:
    """The hot walk's figures as a campaign row (fault_point.figures' names) with the onset, trip and safe times.

    As in a campaign point, the figures end SETTLE_S after the safe command (the trip when none came).
    """
    from host_tools.studies.fault_point import figures

    logging.getLogger("firmware.safety").setLevel(logging.ERROR)  # the trip is the row, not a console line
    r, obs, probe = _run(HOT_WALK["fault_c"], None)
    sup = r.firmware.supervisor
    if sup.reason.name != "OVER_TEMPERATURE" or sup.tripped_at_s is None:
        raise RuntimeError(f"the hot walk latched {sup.reason.name}, not OVER_TEMPERATURE")
    onset_s = next(t for t, c in probe.samples if c > HOT_WALK["fault_c"])
    trip_s = sup.tripped_at_s
    safe_s = obs.safe_on_wire_s(trip_s)
    end_s = (trip_s if safe_s is None else safe_s) + SETTLE_S
    base, base_obs, _ = _run(_PAIR_FAULT_C, end_s + 0.01)
    if base.firmware.supervisor.reason.name != "NONE":
        raise RuntimeError(f"the hot walk's pair latched {base.firmware.supervisor.reason.name}")
    row = figures(onset_s, _until(obs.arrays(), end_s), _until(base_obs.arrays(), end_s), trip_s, sup.reason.name,
                  safe_s)
    winding_at_trip_c = [c for t, c in probe.samples if t <= trip_s][-1]
    row.update(onset_s=onset_s, trip_s=trip_s, safe_s=safe_s, winding_at_trip_c=winding_at_trip_c)
    return row


def _fmt(v: Any, digits: str) -> str:
    return "–" if v is None or (isinstance(v, float) and math.isnan(v)) else format(v, digits)


def hot_walk_table() -> str:
    """The row in docs/safety.md's hazard-table columns, under its own header."""
    from host_tools.studies.fault_report import load_criteria
    from profiles import profile_path

    h = hot_walk_row()
    path = profile_path("faults/criteria.toml")
    load_criteria(path)  # checked as a campaign checks it; heat has no [fault.<name>] table: the defaults apply
    limits = tomllib.loads(path.read_text(encoding="utf-8"))["default"]
    checks = {"excursion_deg": h["excursion_deg"], "velocity_dps": h["velocity_dps"], "torque_nm": h["torque_nm"],
              "time_to_safe_ms": h["safe_ms"], "impact_dps": h["impact_dps"],
              "safe_excursion_deg": h["safe_excursion_deg"], "safe_impact_dps": h["safe_impact_dps"]}
    missed = ", ".join(k for k, v in checks.items() if k in limits and not v <= limits[k]) or "none"
    return "\n".join([
        "| fault | hazard | detection (runs) | risk control | detect [ms] | time to safe [ms] | excursion to safe "
        "[deg] | safe state's own excursion [deg] | stop impact [deg/s] | criteria not met |",
        "|---|---|---|---|---|---|---|---|---|---|",
        f"| `OVER_TEMPERATURE` (heat, no injector) | {HAZARD} | {h['reason']} 1/1 (onset {h['onset_s']:.3f} s, "
        f"trip {h['trip_s']:.3f} s, winding {h['winding_at_trip_c']:.2f} °C then) | {CONTROL} | "
        f"{_fmt(h['detect_ms'], '.1f')} | {_fmt(h['safe_ms'], '.1f')} | "
        f"{_fmt(h['excursion_deg'], '.2f')} | {_fmt(h['safe_excursion_deg'], '.1f')} | "
        f"{_fmt(h['impact_dps'], '.0f')} | {missed} |"])


if __name__ == "__main__":
    print(hot_walk_table())
