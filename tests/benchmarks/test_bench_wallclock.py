"""Wall-clock RTOS at 1 kHz for 10 s (the firmware on in-process sim:// devices) vs a naive sleep loop."""

from __future__ import annotations

import time
from pathlib import Path

from host_tools.serial_mode.serial_report import serial_extra
from host_tools.serial_mode.serial_run import SerialRunConfig, run_serial

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


def test_serial_against_emulator_tracks_like_virtual(benchmark, tmp_path: Path) -> None:  # type: ignore[no-untyped-def]
    """The firmware on the ptys of `pafp emulate bench` (another process) against the ideal virtual bench.

    The emulated devices have no IMU bias, drift or encoder offset, so the virtual run is `--ideal all`. The
    figure is the fused estimate's RMS (what the firmware tracks; no plant in this process) over the RUN
    time, serial against virtual: how much the wall clock and the emulator process cost the tracking.
    """
    import json
    import signal
    import subprocess
    import sys

    from host_tools.cli import main
    from host_tools.reports.report import summarise
    from host_tools.runner import RunConfig, run_virtual

    root = Path(__file__).resolve().parents[2]

    def run() -> dict:
        emu = subprocess.Popen([sys.executable, "-m", "host_tools", "emulate", "bench", "--pty", "--duration", "20"],
                               cwd=root, stdout=subprocess.PIPE, text=True)
        paths = dict(emu.stdout.readline().strip().split(": ") for _ in range(2))  # type: ignore[union-attr]
        time.sleep(0.5)  # the foot comes to rest on its stop
        try:
            main(["run", "--motor", paths["motor"], "--imu", paths["imu"], "--duration", "5", "--out",
                  str(tmp_path / "serial"), "--quiet"])
        finally:
            emu.send_signal(signal.SIGTERM)
            emu.communicate(timeout=10)
        s = json.loads((tmp_path / "serial" / "summary.json").read_text())
        v = summarise(run_virtual(RunConfig(strides=max(1, s["strides"]), trace_capacity=0, ideal=("all",))))
        return {"serial_fused_rms_deg": s["tracking"]["fused"]["rms_deg"], "faults": s["faults"],
                "virtual_fused_rms_deg": v["tracking"]["fused"]["rms_deg"], "strides": s["strides"]}

    out = benchmark.pedantic(run, rounds=1, iterations=1)
    ratio = (out["serial_fused_rms_deg"] / out["virtual_fused_rms_deg"]
             if out["serial_fused_rms_deg"] is not None else None)
    out["ratio"] = None if ratio is None else round(ratio, 2)
    print(f"\nserial (emulator process) vs virtual, fused RMS over RUN: {out}")
    benchmark.extra_info.update(out)
