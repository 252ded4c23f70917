"""`pafp run`: the firmware on the virtual bench (the main job), or on serial ports in wall-clock time.

With ``--motor PORT --imu PORT`` the same firmware runs in serial mode (host_tools/serial_run.py):
ports not bound to ``sim://`` are opened with pyserial and the RTOS runs on the wall clock.
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

HELP = "run the firmware on the virtual bench, or on serial ports (--motor/--imu): tracking, deadlines, report"


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """Options of `pafp run`."""
    parser.add_argument("--strides", type=int, default=10, help="gait strides to run (default 10)")
    parser.add_argument("--baud", type=int, default=921600, help="motor UART baud rate (default 921600)")
    parser.add_argument("--profile", type=Path, default=None,
                        help="firmware profile TOML (default profiles/firmware.toml)")
    parser.add_argument("--board", default="stm32f4", help="board profile name (profiles/board_<name>.toml)")
    parser.add_argument("--reference", type=Path, default=None,
                        help="gait reference CSV (same columns as the normative one)")
    parser.add_argument("--seed", type=int, default=0, help="seed of every random choice (default 0)")
    parser.add_argument("--plant-seed", type=int, default=None, metavar="N",
                        help="draw the plant's parameters from their tolerances (profiles/plant_tolerances.toml) "
                             "with seed N; default: the nominal plant. The firmware keeps its nominal model")
    parser.add_argument("--ideal", action="append", default=[], metavar="NAME",
                        help="switch one imperfection of the real bench off (profiles/bench_imperfections.toml: "
                             "imu_bias, imu_drift, imu_noise, encoder_offset, ...), or all; repeatable")
    parser.add_argument("--out", type=Path, default=None, help="output directory (default runs/<timestamp>)")
    parser.add_argument("--quiet", action="store_true", help="no progress bar")
    serial = parser.add_argument_group("serial mode (the firmware on real ports, wall-clock time)")
    serial.add_argument("--motor", metavar="PORT", help="motor port: device path, pyserial URL or sim://ak60-6")
    serial.add_argument("--imu", metavar="PORT", help="IMU port: device path, pyserial URL or sim://bno08x")
    serial.add_argument("--telemetry", metavar="PORT", help="telemetry out port (always captured to telemetry.bin)")
    serial.add_argument("--encoder", choices=("motor", "sim"), default="motor",
                        help="encoder from the motor's position feedback (default) or the in-process plant")
    serial.add_argument("--duration", type=float, default=10.0, metavar="S", help="run time in s (default 10)")
    serial.add_argument("--imu-baud", type=int, default=115200, help="IMU baud rate (default 115200)")
    serial.add_argument("--reconnect", action="store_true",
                        help="after a lost port, wait for it and resume in the safe state instead of exiting")


class _Progress:
    """A one-line progress bar on stderr."""

    def __init__(self, enabled: bool) -> None:
        self.enabled = enabled and sys.stderr.isatty()
        self.last = -1

    def __call__(self, fraction: float) -> None:
        pct = int(fraction * 100)
        if self.enabled and pct != self.last:
            self.last = pct
            bar = "#" * (pct // 4)
            sys.stderr.write(f"\r[{bar:<25}] {pct:3d}%")
            sys.stderr.flush()

    def done(self) -> None:
        if self.enabled:
            sys.stderr.write("\n")


def _warn_link_budget(baud: int, control_hz: int, full_values_hz: int) -> None:
    """Say before running when the motor link cannot carry command + request + reply every period."""
    from host_tools.benchtests.baud_study import analytic_max_hz

    max_hz, _ = analytic_max_hz(baud, "selective", full_values_hz)
    if control_hz > max_hz:
        print(f"  warning: at {baud} baud the motor link carries command + request + reply at most "
              f"{max_hz:.0f} times per second, below the {control_hz} Hz control rate: expect missing "
              f"replies and a MOTOR_TIMEOUT; `pafp bench baud-study` finds the rate this link allows")


def run(args: argparse.Namespace) -> int:
    """Run, write the outputs, print the summary table; exit 1 if a deadline was missed or a fault latched."""
    if args.motor or args.imu:
        return _run_serial(args)
    from firmware.config import load_firmware_config
    from host_tools.report import tracking_text, write_outputs
    from host_tools.runner import RunConfig, board_profile, run_virtual

    try:
        fw_cfg = load_firmware_config(args.profile)
        cfg = RunConfig(strides=args.strides, baud=args.baud, seed=args.seed, board=args.board,
                        firmware=fw_cfg, reference_csv=args.reference, plant_seed=args.plant_seed,
                        ideal=tuple(args.ideal))
        board_profile(args.board)  # fail early with a clear message, before anything runs
        cfg.bench_setup()  # the plant draw and the imperfection names, checked before anything runs
        if args.reference is not None:
            from firmware.control.reference import GaitReference

            GaitReference.from_csv(args.reference)
    except OSError as e:
        print(f"pafp run: cannot read {e.filename}: {e.strerror}", file=sys.stderr)
        return 2
    except ValueError as e:
        print(f"pafp run: {e}", file=sys.stderr)
        return 2
    out = args.out or Path("runs") / time.strftime("%Y%m%d-%H%M%S")
    plant = "nominal plant" if cfg.plant_seed is None else f"plant drawn with seed {cfg.plant_seed}"
    ideal = f", ideal: {', '.join(cfg.ideal)}" if cfg.ideal else ", real-device imperfections"
    print(f"pafp run: {cfg.strides} strides at {cfg.baud} baud, seed {cfg.seed}, {plant}{ideal} -> {out}")
    _warn_link_budget(cfg.baud, fw_cfg.control_hz, fw_cfg.full_values_hz)
    bar = _Progress(not args.quiet)
    result = run_virtual(cfg, progress=bar)
    bar.done()
    s = write_outputs(result, out)
    print(f"  simulated {s['sim_time_s']:.2f} s in {s['wall_time_s']:.2f} s (realtime factor {s['realtime_factor']}; "
          f"{s['build']})")
    for line in tracking_text(s["tracking"]):
        print(line)
    print(f"  deadline misses {s['deadline_misses']}, faults {s['faults'] or 'none'}, "
          f"CPU {100 * s['cpu_utilisation']:.2f} %, motor feedback {s['motor_link']['feedback_rate_hz']} Hz")
    print(f"  {'task':<11}{'jobs':>8}{'worst us':>11}{'bound us':>11}{'deadline':>10}{'misses':>8}")
    for name, t in s["tasks"].items():
        print(f"  {name:<11}{t['jobs']:>8}{t['wcrt_us']!s:>11}{t['bound_us']!s:>11}{t['deadline_us']!s:>10}"
              f"{t['misses']:>8}")
    print(f"  outputs: {out}/summary.json, report.md, tracking.png, trace.json, telemetry.bin/.csv")
    return 0 if not s["deadline_misses"] and not s["faults"] else 1


def _run_serial(args: argparse.Namespace) -> int:
    """Serial mode: check the ports, run on the wall clock, write the same outputs; 2 if a port fails."""
    from firmware.config import load_firmware_config
    from host_tools.serial_run import SerialRunConfig, StartupError, run_serial

    if not (args.motor and args.imu):
        print("pafp run: serial mode needs both --motor PORT and --imu PORT", file=sys.stderr)
        return 2
    try:
        cfg = SerialRunConfig(motor=args.motor, imu=args.imu, telemetry=args.telemetry, encoder=args.encoder,
                              duration_s=args.duration, baud=args.baud, imu_baud=args.imu_baud, seed=args.seed,
                              board=args.board, firmware=load_firmware_config(args.profile),
                              reference_csv=args.reference, reconnect=args.reconnect)
    except (ValueError, OSError) as e:
        print(f"pafp run: {e}", file=sys.stderr)
        return 2
    out = args.out or Path("runs") / time.strftime("%Y%m%d-%H%M%S")
    print(f"pafp run: serial mode, motor {cfg.motor}, imu {cfg.imu}, {cfg.duration_s:g} s -> {out}", flush=True)
    bar = _Progress(not args.quiet)
    try:
        result = run_serial(cfg, out, progress=bar)
    except (StartupError, ValueError, OSError) as e:
        bar.done()
        print(f"pafp run: {e}", file=sys.stderr)
        return 2
    bar.done()
    from host_tools.report import tracking_text, write_outputs  # matplotlib: imported after the run
    from host_tools.serial_report import serial_extra

    extra, md = serial_extra(result)
    s = write_outputs(result, out, extra, md)
    rt, j = s["realtime"], s["realtime"]["release_jitter_us"]
    print(f"  ran {s['sim_time_s']:.2f} s on the wall clock; {s['strides']} whole strides")
    for line in tracking_text(s["tracking"]):
        print(line)
    print(f"  control released {rt['control_releases']} times (ideal {rt['control_releases_expected']}), jitter "
          f"p50 {j['p50_us']} us p99 {j['p99_us']} us max {j['max_us']} us, host {rt['host_time_per_tick_us']} us/tick")
    print(f"  deadline misses {s['deadline_misses']}, faults {s['faults'] or 'none'}")
    print(f"  outputs: {out}/summary.json, report.md, tracking.png, trace.json, telemetry.bin/.csv")
    link = s["link_lost"]
    if link is not None:
        print(f"pafp run: {link['role']} port {link['port']!r} lost ({link['reason']}); safe state LINK_LOST "
              f"{link['detection_ms']} ms after the loss was seen; files complete up to the fault", file=sys.stderr)
        if not cfg.reconnect:
            return 4
    if result.interrupted:
        return 130
    return 0 if not s["deadline_misses"] and not s["faults"] else 1
