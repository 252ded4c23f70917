"""Wall-clock RTOS at 1 kHz for 10 s (the firmware on in-process sim:// devices) vs a naive sleep loop."""

from __future__ import annotations

import time
from pathlib import Path

from host_tools.serial_report import serial_extra
from host_tools.serial_run import SerialRunConfig, run_serial

DURATION_S = 10.0


def _naive(duration_s: float, work_s: float) -> dict:
    """`work(); time.sleep(period)` at 1 kHz: how many ticks in duration_s and how late the last one is."""
    t0 = time.perf_counter()
    ticks = 0
    while time.perf_counter() - t0 < duration_s:
        t = time.perf_counter()
        while time.perf_counter() - t < work_s:
            pass
        ticks += 1
        time.sleep(0.001)
    return {"ticks": ticks, "expected": int(duration_s * 1000), "drift_ms": round(duration_s * 1000 - ticks, 1)}


def test_wallclock_vs_naive(benchmark, tmp_path: Path) -> None:  # type: ignore[no-untyped-def]
    def both() -> dict:
        r = run_serial(SerialRunConfig("sim://ak60-6", "sim://bno08x", encoder="sim", duration_s=DURATION_S,
                                       trace_capacity=0), tmp_path)
        rt = serial_extra(r)[0]["realtime"]
        work_s = (rt["host_time_per_tick_us"] or 0) * 1e-6
        return {"rtos": rt, "naive": _naive(DURATION_S, work_s)}

    out = benchmark.pedantic(both, rounds=1, iterations=1)
    rt, naive = out["rtos"], out["naive"]
    j = rt["release_jitter_us"]
    print(f"\nRTOS wall clock: {rt['control_releases']} releases (ideal {rt['control_releases_expected']}), "
          f"jitter p50 {j['p50_us']} p99 {j['p99_us']} max {j['max_us']} us, host {rt['host_time_per_tick_us']} "
          f"us/tick; naive sleep loop: {naive['ticks']} ticks of {naive['expected']}")
    benchmark.extra_info.update({"rtos": {k: v for k, v in rt.items() if k != "tasks"}, "naive": naive})
    assert abs(rt["control_releases"] - 10_000) <= 1
    assert naive["ticks"] < rt["control_releases"]  # sleeping after the work drifts
