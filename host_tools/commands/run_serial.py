"""`pafp run --motor PORT --imu PORT`: the same firmware on serial ports, in wall-clock time.

The ports are checked before any is opened, the run (host_tools/serial_mode/serial_run.py) stops the motor safely on
every exit path, and the outputs are those of a virtual run, written in place (exit codes: docs/hardware.md).
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

from host_tools.commands.run import DURATION_S, _controller, _firmware_config, _Progress, _say_controller_error


def _remove_partial(path: Path, size: int) -> None:
    """Remove path unless it holds size bytes (serial mode's telemetry.bin, appended as the run went)."""
    try:
        if path.stat().st_size != size:
            path.unlink()
    except OSError:
        pass


def run_serial_mode(args: argparse.Namespace) -> int:
    """Serial mode: check the ports, run on the wall clock, stop safely, write the same outputs (exit codes:
    docs/hardware.md)."""
    from host_tools.serial_mode.realtime import RealtimeSettings
    from host_tools.serial_mode.serial_run import SerialRunConfig

    if not (args.motor and args.imu):
        print("pafp run: serial mode needs both --motor PORT and --imu PORT", file=sys.stderr)
        return 2
    from host_tools.outdir import OutDirError, check_capture_dir, check_out_dir, mark_outputs

    out = args.out or Path("runs") / time.strftime("%Y%m%d-%H%M%S")
    try:
        check_out_dir(out)  # before any port is opened (serial mode writes into it, not staged)
        if args.capture is not None:
            check_capture_dir(args.capture)
    except OutDirError as e:
        print(f"pafp run: {e}", file=sys.stderr)
        return 2
    telemetry_pty = None
    try:
        fw_cfg = _firmware_config(args)
        duration = args.duration
        if duration is None:
            duration = (getattr(_controller(fw_cfg, args), "duration_s") + 2.0  # noqa: B009
                        if args.experiment is not None else DURATION_S)
        cfg = SerialRunConfig(motor=args.motor, imu=args.imu, telemetry=args.telemetry, encoder=args.encoder,
                              duration_s=duration, baud=args.baud, imu_baud=args.imu_baud, seed=args.seed,
                              board=args.board, firmware=fw_cfg,
                              reference_csv=args.reference, reconnect=args.reconnect, capture_dir=args.capture,
                              record=not args.no_record,
                              realtime=RealtimeSettings.none() if args.no_realtime else RealtimeSettings(),
                              ground=args.ground)
        if args.telemetry == "pty":
            from host_tools.serial_mode.telemetry_pty import TelemetryPty

            telemetry_pty = TelemetryPty()
            cfg.telemetry = telemetry_pty.url
    except (ValueError, OSError) as e:
        print(f"pafp run: {e}", file=sys.stderr)
        return 2
    try:
        return _serial_outputs(args, cfg, out, telemetry_pty)
    finally:
        if out.is_dir():  # written in place, not staged: marked as pafp's outputs (a later run may replace them)
            mark_outputs(out)


def _serial_outputs(args: argparse.Namespace, cfg, out: Path, telemetry_pty) -> int:  # SerialRunConfig, TelemetryPty
    """Run in serial mode into ``out``, write the outputs, print the summary; the exit code."""
    from host_tools.outdir import EXIT_WRITE_FAILED, write_failed
    from host_tools.serial_mode.serial_run import StartupError, run_serial
    from host_tools.stop_signals import StopSignals

    print(f"pafp run: serial mode, motor {cfg.motor}, imu {cfg.imu}, {cfg.duration_s:g} s -> {out}", flush=True)
    if telemetry_pty is not None:
        print(f"telemetry: {telemetry_pty.path}  (watch it: pafp monitor {telemetry_pty.path})", flush=True)
    bar = _Progress(not args.quiet)
    with StopSignals() as signals:  # from the first port opened to the last file written
        try:
            result = run_serial(cfg, out, progress=bar, telemetry_uart=telemetry_pty, signals=signals)
        except (StartupError, ValueError, OSError) as e:
            bar.done()
            if telemetry_pty is not None:
                telemetry_pty.close()
            print(f"pafp run: {e}", file=sys.stderr)
            return signals.exit_code or 2
        bar.done()
        from host_tools.reports.report import write_outputs  # matplotlib: imported after the run, not before it
        from host_tools.serial_mode.serial_report import serial_extra

        extra, md = serial_extra(result)
        try:  # telemetry.bin is rewritten from memory: a capture that failed mid-run is complete if this works
            s = write_outputs(result, out, extra, md, plot=not args.no_plot, trace=not args.no_trace)
        except OSError as e:
            _remove_partial(out / "telemetry.bin", len(result.telemetry))
            safe = result.stop.safe
            stopped = ("the safe frames on the wire" if safe is not None and safe.on_wire
                       else "the safe frames NOT confirmed on the wire")
            print(write_failed("run", e, f"the motor was stopped first ({stopped}); the files complete in {out} "
                               "are kept, partial ones removed"), file=sys.stderr)
            return EXIT_WRITE_FAILED
    if result.record_error is not None:
        print(write_failed("run", result.record_error, f"the motor was stopped first; record.bin was removed, the "
                           f"other files in {out} are complete"), file=sys.stderr)
        return EXIT_WRITE_FAILED
    from host_tools.reports.report import TRACE_FILE, tracking_text

    rt, j, stop = s["realtime"], s["realtime"]["release_jitter_us"], s["stop"]
    print(f"  ran {s['sim_time_s']:.2f} s on the wall clock, {s['time_in_run_s']:.2f} s of it with the supervisor in "
          f"RUN; {s['strides']} whole strides")
    for line in tracking_text(s["tracking"]):
        print(line)
    if "encoder_headline" in s:
        print(f"  encoder figures {s['encoder_headline']}")
    print(f"  control released {rt['control_releases']} times (ideal {rt['control_releases_expected']}), jitter "
          f"p50 {j['p50_us']} us p99 {j['p99_us']} us max {j['max_us']} us, host {rt['host_time_per_tick_us']} us/tick")
    w = s["host_warnings"]
    print(f"  host stalls: {rt['late_releases']} late releases, {rt['overruns']} overruns, "
          f"{w['deadline_miss_streaks']} miss streaks, {w['watchdog_expiries']} watchdog expiries (warnings)")
    print(f"  faults {s['faults'] or 'none'}")
    print(f"  stop ({stop['reason']}{' ' + stop['signal'] if stop['signal'] else ''}): "
          f"{', '.join(stop['safe_frames']) or 'nothing sent'}; "
          f"{'on the wire' if stop['safe_on_wire'] else 'NOT confirmed on the wire'} {stop['latency_ms']} ms "
          f"after the stop began (goal {stop['goal_ms']} ms)")
    files = ["summary.json", "report.md", *([] if args.no_plot else ["tracking.png"]),
             *([] if args.no_trace else [TRACE_FILE]), "telemetry.bin/.csv"]
    print(f"  outputs: {out}/{', '.join(files)}"
          + (f"; wire capture in {args.capture}" if args.capture else ""))
    link = s["link_lost"]
    if link is not None:
        print(f"pafp run: {link['role']} port {link['port']!r} lost ({link['reason']}); the supervisor saw it "
              f"{link['detection_ms']} ms after the first failed read or write; files complete up to the fault",
              file=sys.stderr)
    _say_controller_error(result.firmware.controller_error)
    if stop["reason"] == "watchdog":
        print(f"pafp run: the host watchdog fired: {stop['error']} (task {stop['task']!r} running); it sent zero "
              "current and the brake, the stop path followed and every file was written", file=sys.stderr)
    capture_error = result.capture_error
    if capture_error is not None:  # the capture's write failed in a task: the stop path ran, the files are written
        print(write_failed("run", capture_error, f"the motor was stopped first; the capture in {args.capture} holds "
                           f"what was written before, the run's files in {out} are complete"), file=sys.stderr)
        return EXIT_WRITE_FAILED
    if stop["reason"] == "exception":
        print(result.stop.traceback, file=sys.stderr, end="")
        print(f"pafp run: task {stop['task']!r} raised {stop['error']}; the motor was stopped and every file "
              f"written", file=sys.stderr)
    if not stop["safe_on_wire"]:
        print(f"pafp run: the stop path could not confirm the safe frames left the motor port "
              f"({stop['safe_error'] or 'not drained'})", file=sys.stderr)
    return result.exit_code

