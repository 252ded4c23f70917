"""`pafp run`: the firmware on the virtual bench (the main job), or on serial ports in wall-clock time.

With ``--motor PORT --imu PORT`` the same firmware runs in serial mode (host_tools/serial_run.py):
ports not bound to ``sim://`` are opened with pyserial and the RTOS runs on the wall clock.
"""

from __future__ import annotations

import argparse
import contextlib
import math
import signal
import sys
import threading
import time
from collections.abc import Iterator
from pathlib import Path
from typing import TYPE_CHECKING

if TYPE_CHECKING:
    from host_tools.outdir import RunDir
    from host_tools.runner import RunConfig

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
    parser.add_argument("--out", type=Path, default=None, help="output directory (default runs/<timestamp>)")
    parser.add_argument("--quiet", action="store_true", help="no progress bar")
    parser.add_argument("--no-plot", action="store_true", help="do not draw tracking.png (saves about 1 s)")
    parser.add_argument("--no-trace", action="store_true", help="do not write trace.json")
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
    """Run, write the outputs, print the summary table; exit 1 if a deadline was missed or a fault latched.

    Every input is checked before the run (exit 2, one line, nothing written). The outputs are staged
    beside --out and put in place whole (host_tools/outdir.py). SIGINT or SIGTERM ends a virtual run at
    the next segment: what it has is written, marked ``"complete": false``, exit 128 + the signal's number.
    """
    if args.motor or args.imu:
        return _run_serial(args)
    from firmware.config import load_firmware_config
    from host_tools.outdir import OutDirError, RunDir
    from host_tools.runner import RunConfig, board_profile

    out = args.out or Path("runs") / time.strftime("%Y%m%d-%H%M%S")
    try:
        fw_cfg = load_firmware_config(args.profile)
        cfg = RunConfig(strides=args.strides, baud=args.baud, seed=args.seed, board=args.board,
                        firmware=fw_cfg, reference_csv=args.reference)
        board_profile(args.board)  # fail early with a clear message, before anything runs
        if args.reference is not None:
            from firmware.control.reference import GaitReference

            GaitReference.from_csv(args.reference, stride_s=fw_cfg.stride_s)
        run_dir = RunDir(out)  # --out checked and the staging directory made: before the run
    except OSError as e:
        print(f"pafp run: cannot read {e.filename}: {e.strerror}", file=sys.stderr)
        return 2
    except (ValueError, OutDirError) as e:
        print(f"pafp run: {e}", file=sys.stderr)
        return 2
    try:
        return _run_virtual(args, cfg, run_dir)
    except BaseException:
        run_dir.discard()
        raise


def _run_virtual(args: argparse.Namespace, cfg: RunConfig, run_dir: RunDir) -> int:
    """The virtual run proper, streaming into run_dir, which is published at the end."""
    from dataclasses import replace

    from host_tools.report import write_outputs
    from host_tools.runner import run_virtual

    fw_cfg = cfg.firmware
    assert fw_cfg is not None
    out = run_dir.out
    print(f"pafp run: {cfg.strides} strides at {cfg.baud} baud, seed {cfg.seed} -> {out}")
    _warn_link_budget(cfg.baud, fw_cfg.control_hz, fw_cfg.full_values_hz)
    cfg = replace(cfg, stream_to=run_dir.path, trace_capacity=0 if args.no_trace else cfg.trace_capacity)
    bar = _Progress(not args.quiet)
    stop: list[signal.Signals] = []
    with _stop_on_signals(stop):
        result = run_virtual(cfg, progress=bar, should_stop=lambda: bool(stop))
        bar.done()
        s = write_outputs(result, run_dir.path, plot=not args.no_plot, trace=not args.no_trace)
        run_dir.publish()
    print(f"  simulated {s['sim_time_s']:.2f} s in {s['wall_time_s']:.2f} s (realtime factor {s['realtime_factor']}; "
          f"{s['build']}); whole process {s['process_wall_time_s']:.2f} s (factor {s['process_realtime_factor']})")
    print(f"  tracking: RMS {_num(s['rms_error_deg'], 3)} deg, max {_num(s['max_error_deg'], 3)} deg, "
          f"lag {_num(s['lag_ms'], 1)} ms")
    print(f"  deadline misses {s['deadline_misses']}, faults {s['faults'] or 'none'}, "
          f"CPU {100 * s['cpu_utilisation']:.2f} %, motor feedback {s['motor_link']['feedback_rate_hz']} Hz")
    print(f"  {'task':<11}{'jobs':>8}{'worst us':>11}{'bound us':>11}{'deadline':>10}{'misses':>8}")
    for name, t in s["tasks"].items():
        print(f"  {name:<11}{t['jobs']:>8}{t['wcrt_us']!s:>11}{t['bound_us']!s:>11}{t['deadline_us']!s:>10}"
              f"{t['misses']:>8}")
    written = ["summary.json", "report.md", *(["tracking.png"] if (out / "tracking.png").exists() else []),
               *([] if args.no_trace else ["trace.json"]), "telemetry.bin/.csv"]
    print(f"  outputs: {out}/{', '.join(written)}")
    if stop:
        print(f"pafp run: stopped by {stop[0].name} after {s['sim_time_s']:.2f} s simulated; the outputs hold "
              "what the run had (\"complete\": false)", file=sys.stderr)
        return 128 + int(stop[0])
    return 0 if not s["deadline_misses"] and not s["faults"] else 1


@contextlib.contextmanager
def _stop_on_signals(stop: list[signal.Signals]) -> Iterator[None]:
    """SIGINT and SIGTERM append themselves to stop (the run ends at its next segment); a second one interrupts."""
    def handle(signum: int, frame: object) -> None:
        if stop:
            raise KeyboardInterrupt
        stop.append(signal.Signals(signum))

    if threading.current_thread() is not threading.main_thread():  # only the main thread can take signals
        yield
        return
    previous = {sig: signal.signal(sig, handle) for sig in (signal.SIGINT, signal.SIGTERM)}
    try:
        yield
    finally:
        for sig, handler in previous.items():
            signal.signal(sig, handler)


def _num(value: float | None, digits: int) -> str:
    """A summary figure for the terminal: rounded, or n/a when the run has none (null in summary.json)."""
    return "n/a" if value is None or not math.isfinite(value) else f"{value:.{digits}f}"


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
    from host_tools.outdir import OutDirError, check_out_dir

    try:
        check_out_dir(out)  # before any port is opened (serial mode writes into out itself, not staged)
    except OutDirError as e:
        print(f"pafp run: {e}", file=sys.stderr)
        return 2
    print(f"pafp run: serial mode, motor {cfg.motor}, imu {cfg.imu}, {cfg.duration_s:g} s -> {out}", flush=True)
    bar = _Progress(not args.quiet)
    try:
        result = run_serial(cfg, out, progress=bar)
    except (StartupError, ValueError, OSError) as e:
        bar.done()
        print(f"pafp run: {e}", file=sys.stderr)
        return 2
    bar.done()
    from host_tools.report import write_outputs  # matplotlib: imported after the run, not before it
    from host_tools.serial_report import serial_extra

    extra, md = serial_extra(result)
    s = write_outputs(result, out, extra, md)
    rt, j = s["realtime"], s["realtime"]["release_jitter_us"]
    print(f"  ran {s['sim_time_s']:.2f} s on the wall clock; {s['strides']} whole strides")
    print(f"  tracking ({s['angle_source']}): RMS {s['rms_error_deg']:.3f} deg, max {s['max_error_deg']:.3f} deg")
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
