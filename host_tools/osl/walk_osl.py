"""Walk the example OSL controller on the virtual leg and write pafp's outputs (telemetry.csv, summary.json).

``python -m host_tools.osl.walk_osl OUT [--strides N] [--seed S] [--clock virtual|wall]``: the adult design at
80 kg, free speed, the example state machine (host_tools/osl/example_controller.py) at 200 Hz. Tracking figures
are pafp's (host_tools.reports.metrics.tracking_metrics) against the normative ankle curve of the same stride, over
the strides after the first; the joint encoder's angle is the measured one, the plant's the emulation-only truth.
telemetry.csv depends only on the seed (virtual clock); summary.json adds the wall time.
"""

from __future__ import annotations

import argparse
import json
import math
import os
import sys
import time
from pathlib import Path

import numpy as np

from host_tools.osl.example_controller import AnkleStateMachine
from host_tools.osl.virtual_leg import GAIT_START_S, VirtualActuator, VirtualEncoder, VirtualLeg, VirtualLoadcell
from host_tools.reports.metrics import tracking_metrics
from host_tools.runner import gait_reference

__all__ = ["FREQUENCY_HZ", "walk_osl"]

FREQUENCY_HZ = 200
COLUMNS = ("t_s", "phase", "encoder_deg", "truth_deg", "reference_deg", "current_a", "case_c", "winding_c", "fz_n")


def walk_osl(out: Path, *, strides: int = 10, seed: int = 0, clock: str = "virtual",
             body_mass_kg: float = 80.0) -> dict:
    """Run, write out/telemetry.csv and out/summary.json, return the summary."""
    if isinstance(strides, bool) or not isinstance(strides, int) or not 2 <= strides <= 1000:
        raise ValueError(f"strides {strides!r} out of range: an int in 2..1000")
    leg = VirtualLeg(seed=seed, body_mass_kg=body_mass_kg, frequency_hz=FREQUENCY_HZ, clock=clock)
    actuator, encoder, loadcell = VirtualActuator(leg), VirtualEncoder(leg), VirtualLoadcell(leg)
    reference = gait_reference({"csv": None, "speed": "free"}, leg.stride_s)
    rows: list[tuple] = []
    dt = 1.0 / FREQUENCY_HZ
    end_s = GAIT_START_S + strides * leg.stride_s
    wall0, cpu0 = time.perf_counter(), time.process_time()
    with actuator, encoder, loadcell:
        fsm = AnkleStateMachine(actuator, encoder, loadcell)
        while leg.t_s < end_s:
            actuator.update()
            encoder.update()
            loadcell.update()
            phase = fsm.step(dt)
            t = leg.t_s
            rows.append((t, phase, encoder.position, leg.joint_angle_rad(),
                         reference.angle_rad(max(0.0, t - GAIT_START_S)), actuator.motor_current,
                         actuator.case_temperature, actuator.winding_temperature, loadcell.fz))
    wall_s, cpu_s = time.perf_counter() - wall0, time.process_time() - cpu0
    out.mkdir(parents=True, exist_ok=True)
    _write_telemetry(out / "telemetry.csv", rows)
    summary = _summary(rows, leg, fsm, strides, seed, clock, wall_s, cpu_s)
    tmp = out / "summary.json.tmp"
    tmp.write_text(json.dumps(summary, indent=1) + "\n", encoding="utf-8")
    tmp.replace(out / "summary.json")
    return summary


def _write_telemetry(path: Path, rows: list[tuple]) -> None:
    tmp = path.with_suffix(".csv.tmp")
    with tmp.open("w", encoding="ascii", newline="\n") as f:
        f.write(",".join(COLUMNS) + "\n")
        for t, phase, enc, truth, ref, cur, case, wind, fz in rows:
            f.write(f"{t:.6f},{phase},{math.degrees(enc):.6f},{math.degrees(truth):.6f},{math.degrees(ref):.6f},"
                    f"{cur:.6f},{case:.1f},{wind:.4f},{fz:.3f}\n")
    tmp.replace(path)


def _summary(rows: list[tuple], leg: VirtualLeg, fsm: AnkleStateMachine, strides: int, seed: int, clock: str,
             wall_s: float, cpu_s: float) -> dict:
    t = np.array([r[0] for r in rows])
    ref = np.array([r[4] for r in rows])

    def track(col: int) -> dict:
        m = tracking_metrics(t, ref, np.array([r[col] for r in rows]), start_s=GAIT_START_S + leg.stride_s,
                             stride_s=leg.stride_s, strides=strides - 1)
        return {"rms_deg": round(m.rms_error_deg, 4), "max_deg": round(m.max_error_deg, 4),
                "lag_ms": round(m.lag_ms, 2)}

    core = leg.drive.core
    sim_s = float(t[-1])
    return {"strides": strides, "seed": seed, "clock": clock, "sim_time_s": round(sim_s, 6),
            "wall_time_s": round(wall_s, 3), "realtime_factor": round(sim_s / wall_s, 2) if wall_s > 0 else None,
            "cpu_time_s": round(cpu_s, 3), "cpu_realtime_factor": round(sim_s / cpu_s, 2) if cpu_s > 0 else None,
            "load_average_1min": _load_average(),
            "controller": "host_tools/osl/example_controller.py (opensourceleg API only)",
            "design": leg.motor.name, "body_mass_kg": leg.load.body_mass_kg, "phase_transitions": fsm.transitions,
            "tracking": {"encoder": track(2), "truth": {**track(3), "emulation_only": True}},
            "faults": {"drive_fault": core.fault, "drive_faults_raised": core.stats.faults,
                       "command_timeouts": core.stats.timeouts},
            "current_a": {"max_abs": round(max(abs(r[5]) for r in rows), 3), "peak_a": leg.params.peak_current_a},
            "thermal": {"case_max_c": max(r[6] for r in rows), "winding_max_c": round(max(r[7] for r in rows), 3),
                        "winding_emulation_only": True}}


def _load_average() -> float | None:
    """The host's one-minute load average (the wall-clock factor depends on it; None where the OS has none)."""
    try:
        return round(os.getloadavg()[0], 2)
    except (AttributeError, OSError):
        return None


def main(argv: list[str] | None = None) -> int:
    """Command line: one line per figure; 2 on a bad value."""
    parser = argparse.ArgumentParser(prog="python -m host_tools.osl.walk_osl", description=__doc__.split("\n")[0])
    parser.add_argument("out", type=Path)
    parser.add_argument("--strides", type=int, default=10)
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--clock", default="virtual", choices=("virtual", "wall"))
    args = parser.parse_args(argv)
    try:
        s = walk_osl(args.out, strides=args.strides, seed=args.seed, clock=args.clock)
    except ValueError as exc:
        print(f"walk_osl: {exc}", file=sys.stderr)
        return 2
    enc = s["tracking"]["encoder"]
    print(f"{s['strides']} strides in {s['wall_time_s']} s (realtime factor {s['realtime_factor']} at load "
          f"{s['load_average_1min']}; {s['cpu_realtime_factor']} per CPU second); encoder RMS "
          f"{enc['rms_deg']} deg, max {enc['max_deg']} deg, lag {enc['lag_ms']} ms; faults {s['faults']}; "
          f"winding max {s['thermal']['winding_max_c']} C -> {args.out}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
