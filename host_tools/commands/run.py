"""`pafp run`: the firmware on the virtual bench (the main job), or on serial ports in wall-clock time.

With ``--motor PORT --imu PORT`` the same firmware runs in serial mode (host_tools/serial_mode/serial_run.py):
ports not bound to ``sim://`` are opened with pyserial and the RTOS runs on the wall clock.
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path
from typing import TYPE_CHECKING

from host_tools.arguments import float_in, seed

if TYPE_CHECKING:
    from host_tools.outdir import RunDir
    from host_tools.runner import RunConfig

STRIDES = 10
"""A virtual run's length without --strides."""
DURATION_S = 10.0
"""Serial mode's run time without --duration."""
BODY_MASS_KG = 80.0
"""The walker's mass without --body-mass (the report's subject)."""

HELP = "run the firmware on the virtual bench, or on serial ports (--motor/--imu): tracking, deadlines, report"


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """Options of `pafp run` (the choices of --motor-link and --controller from their registries)."""
    from firmware.control.registry import CONTROLLERS
    from firmware.drivers.motor_links import MOTOR_LINKS

    parser.add_argument("--strides", type=int, default=None,
                        help=f"gait strides to run on the virtual bench (default {STRIDES})")
    parser.add_argument("--baud", type=int, default=921600, help="motor UART baud rate (default 921600)")
    parser.add_argument("--motor-link", default=None, metavar="NAME",
                        help=f"motor link on the virtual bench: {MOTOR_LINKS.spoken()} (CAN at 1 Mbit/s; "
                             "default: the firmware profile's [motor] link, uart)")
    parser.add_argument("--profile", type=Path, default=None,
                        help="firmware profile TOML (default profiles/firmware.toml); a design profile "
                             "(profiles/designs/, a [design] table) also sets the bench's plant (docs/design.md)")
    parser.add_argument("--board", default="stm32f4", help="board profile name (profiles/board_<name>.toml)")
    parser.add_argument("--reference", type=Path, default=None,
                        help="gait reference CSV (same columns as the normative one)")
    parser.add_argument("--seed", type=seed, default=0, help="seed of every random choice (default 0)")
    parser.add_argument("--plant-seed", type=int, default=None, metavar="N",
                        help="draw the plant's parameters from their tolerances (profiles/plant_tolerances.toml) "
                             "with seed N; default: the nominal plant. The firmware keeps its nominal model")
    parser.add_argument("--plant", type=Path, default=None, metavar="FILE",
                        help="plant profile TOML (keys of profiles/plant_ak60_6.toml, e.g. one `pafp fit` wrote) "
                             "instead of the packaged one; --plant-seed draws around it")
    parser.add_argument("--ideal", action="append", default=[], metavar="NAME",
                        help="switch one imperfection of the real bench off (profiles/bench_imperfections.toml: "
                             "imu_bias, imu_drift, imu_noise, encoder_offset, ...), or all; repeatable")
    parser.add_argument("--out", type=Path, default=None, help="output directory (default runs/<timestamp>)")
    parser.add_argument("--quiet", action="store_true", help="no progress bar")
    parser.add_argument("--controller", default=None, metavar="NAME|FILE.py:CLASS",
                        help=f"the control law: {CONTROLLERS.by_origin()}, or a class in a Python file "
                             "(docs/controllers.md); default: the profile's [controller], else cascade")
    parser.add_argument("--imu-model", default=None, metavar="NAME",
                        help="the IMU device model on the virtual bench: a name of the device registry "
                             "(hal/virtual/devices/registry.py, plug-ins of the pafp.devices group too; "
                             "docs/registries.md); default bno08x")
    parser.add_argument("--experiment", choices=("sysid",), default=None,
                        help="run the identification experiment (the shipped controller sysid, its [controller] "
                             "parameters from the profile when it names sysid) for its whole length instead of "
                             "gait strides; record.bin is written for `pafp fit` (docs/calibration.md)")
    parser.add_argument("--no-plot", action="store_true", help="do not draw tracking.png (saves about 1 s)")
    parser.add_argument("--no-trace", action="store_true", help="do not write trace.pftrace")
    parser.add_argument("--trace-seconds", type=float, default=None, metavar="S",
                        help="trace.pftrace keeps the last S simulated seconds (default 20; docs/telemetry.md)")
    parser.add_argument("--trace-strides", type=int, default=None, metavar="N",
                        help="trace.pftrace keeps the last N strides instead (N x the stride time)")
    parser.add_argument("--trace-wire", action="store_true",
                        help="virtual bench: add every UART frame and CAN frame to trace.pftrace, a track per port "
                             "and direction, each named by its decoded message")
    parser.add_argument("--capture", type=Path, default=None, metavar="DIR",
                        help="write the raw bytes of every port, each direction, with a time index, into DIR "
                             "(docs/serial_mode.md)")
    parser.add_argument("--record", action="store_true",
                        help="virtual bench: record every input the firmware saw into record.bin for `pafp replay` "
                             "(serial runs always record; docs/calibration.md)")
    walk = parser.add_argument_group("scenario (virtual bench)")
    walk.add_argument("--scenario", choices=("suspended", "walk"), default="suspended",
                      help="suspended foot (default) or walk: the ground's moment in stance, scaled to --body-mass "
                           "(docs/plant.md, 'Walking'); walk adds the actuator design check to summary.json")
    walk.add_argument("--body-mass", type=float, default=None, metavar="KG",
                      help=f"walk: body mass in kg, 20..200 (default {BODY_MASS_KG:g}, the report's subject)")
    walk.add_argument("--moment", type=Path, default=None, metavar="CSV",
                      help="walk: ankle moment per kg (columns percent_gait, ankle_moment_nm_per_kg_mean; "
                           "default: the packaged normative curve)")
    walk.add_argument("--speed", choices=("very-slow", "slow", "free", "fast", "very-fast"), default=None,
                      help="the gait (angle reference and, walking, moment) of that speed group of the packaged "
                           "normative data (Schwartz et al. 2008; default: free speed); the stride time stays "
                           "the profile's")
    walk.add_argument("--population", choices=("adult", "child"), default=None,
                      help="walk: whose ankle moment: the packaged children's curves (Schwartz et al. 2008) or "
                           "adult-shaped ones (scaled to an adult's 1.5 N·m/kg free-speed peak, an assumption: "
                           "host_tools/walk.py); default adult above 50 kg body mass, else child",)
    walk.add_argument("--ground-sensors", choices=("auto", "on", "off"), default="auto",
                      help="the pylon load cell and heel/toe FSRs on the ADC, gait events from them (docs/hardware.md, "
                           "'Ground sensors'): auto (default) fits them when walking")
    walk.add_argument("--sensor-fault", action="append", default=[], metavar="PART:MODE",
                      help="start with a ground sensor failed: fsr_heel:open|short, fsr_toe:open|short, "
                           "load_cell:open|stuck_high; repeatable (the firmware falls back to its motor-load estimate)")
    heat = parser.add_argument_group("winding temperature and battery (virtual bench)")
    heat.add_argument("--ambient-c", type=float, default=None, metavar="C",
                      help="ambient temperature in C, -40..80 (default 25): the winding starts at it and cools "
                           "towards it (docs/design.md, 'Winding temperature')")
    heat.add_argument("--battery", default=None, metavar="NAME|FILE",
                      help="supply the motor from this battery (profiles/batteries/ name or a profile file; default: "
                           "the design's, else an ideal supply): the bus sags, summary.json gains distance per charge")
    serial = parser.add_argument_group("serial mode (the firmware on real ports, wall-clock time)")
    serial.add_argument("--motor", metavar="PORT", help="motor port: device path, pyserial URL or sim://ak60-6")
    serial.add_argument("--imu", metavar="PORT", help="IMU port: device path, pyserial URL or sim://bno08x")
    serial.add_argument("--telemetry", metavar="PORT",
                        help="telemetry out port (always captured to telemetry.bin); 'pty' opens a new pty and "
                             "prints its path for `pafp monitor PATH`")
    serial.add_argument("--encoder", choices=("motor", "sim"), default="motor",
                        help="encoder from the motor's position feedback (default) or the in-process plant")
    serial.add_argument("--ground", metavar="PORT", default=None,
                        help="the ground sensors' Firmata board (load cell, heel/toe FSRs on A0..A3; docs/hardware.md, "
                             "'Ground sensors'): device path, pyserial URL or sim://ground-sensors")
    serial.add_argument("--duration", type=float_in(0.0, lo_open=True, unit="s"), default=None, metavar="S",
                        help=f"run time in s (default {DURATION_S:g}; with --experiment: the experiment's length "
                             "plus 2 s)")
    serial.add_argument("--imu-baud", type=int, default=115200, help="IMU baud rate (default 115200)")
    serial.add_argument("--reconnect", action="store_true",
                        help="after a lost port, wait for it and resume in the safe state instead of exiting")
    serial.add_argument("--no-record", action="store_true",
                        help="do not write record.bin (the inputs for `pafp replay`; recorded by default)")
    serial.add_argument("--no-realtime", action="store_true",
                        help="ask the OS for nothing (no GC freeze, core pinning, SCHED_FIFO, mlockall, spin)")


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
    beside --out and put in place whole (host_tools/outdir.py). SIGINT, SIGTERM or SIGHUP ends a virtual run at
    the next segment: what it has is written, marked ``"complete": false``, exit 128 + the signal's number.
    """
    ignored = _ignored_option(args)
    if ignored:
        print(f"pafp run: {ignored}", file=sys.stderr)
        return 2
    if args.motor or args.imu:
        from host_tools.commands.run_serial import run_serial_mode

        return run_serial_mode(args)
    args.strides = STRIDES if args.strides is None else args.strides
    args.body_mass = BODY_MASS_KG if args.body_mass is None else args.body_mass
    from dataclasses import replace

    from host_tools.command_errors import input_error, output_error
    from host_tools.outdir import EXIT_WRITE_FAILED, OutDirError, RunDir, check_capture_dir
    from host_tools.runner import RunConfig, board_profile

    out = args.out or Path("runs") / time.strftime("%Y%m%d-%H%M%S")
    try:
        fw_cfg = _firmware_config(args)
        if args.experiment is not None:  # the experiment's length, in whole strides of the run's clock
            args.strides = _experiment_strides(fw_cfg, _controller(fw_cfg, args))
            args.record = True
        cfg = RunConfig(strides=args.strides, baud=args.baud, seed=args.seed, board=args.board,
                        firmware=fw_cfg, reference_csv=args.reference, capture_dir=args.capture,
                        plant_seed=args.plant_seed, plant_file=args.plant, ideal=tuple(args.ideal),
                        controller=_controller(fw_cfg, args), scenario=args.scenario,
                        body_mass_kg=args.body_mass, moment_csv=args.moment, speed=args.speed,
                        population=args.population,
                        ground_sensors={"auto": None, "on": True, "off": False}[args.ground_sensors],
                        sensor_faults=tuple(args.sensor_fault), design=_design(args),
                        battery=args.battery,
                        ambient_c=25.0 if args.ambient_c is None else args.ambient_c,
                        bench_options={} if args.imu_model is None else {"imu_model": args.imu_model},
                        trace_window_s=_trace_window_s(args, fw_cfg.stride_s), trace_wire=args.trace_wire)
        if args.imu_model is not None:
            from hal.virtual.devices.registry import device_model_for

            device_model_for("imu", args.imu_model, "--imu-model")  # an unknown name or another role stops here
        if args.battery is not None:
            from hal.virtual.plant.battery import load_battery

            load_battery(args.battery)  # a bad name or profile stops here
        if args.scenario == "walk":
            from host_tools.walk import walking_load

            walking_load(args.body_mass, fw_cfg.stride_s, args.moment, args.speed,
                         args.population)  # a bad mass or CSV stops here
        board_profile(args.board)  # fail early with a clear message, before anything runs
        cfg.bench_setup()  # the plant draw and the imperfection names, checked before anything runs
        if args.reference is not None:
            from firmware.control.reference import GaitReference

            GaitReference.from_csv(args.reference, stride_s=fw_cfg.stride_s)
        # a capture inside --out is written into the staging directory and published with the run
        if args.capture is not None and not args.capture.absolute().is_relative_to(out.absolute()):
            check_capture_dir(args.capture)
        run_dir = RunDir(out)  # --out checked and the staging directory made: before the run
    except (OSError, ValueError) as e:  # a file that cannot be read, a bad value (OutDirError too)
        print(input_error("run", e), file=sys.stderr)
        return 2
    if args.capture is not None:
        cfg = replace(cfg, capture_dir=run_dir.staged(args.capture))
    try:
        return _run_virtual(args, cfg, run_dir)
    except (OSError, OutDirError) as e:  # a write failed (staging gone, --out untouched) or --out was taken meanwhile
        print(output_error("run", e, run_dir, "the run was stopped and nothing published"), file=sys.stderr)
        return EXIT_WRITE_FAILED
    finally:
        run_dir.discard()  # nothing left once published; everything staged if not


def _ignored_option(args: argparse.Namespace) -> str | None:
    """The message for an option given where it has no effect (None if there is none): the run it belongs to."""
    if args.motor or args.imu:
        if args.strides is not None:
            return (f"--strides {args.strides} is not allowed in serial mode (--motor/--imu): a serial run lasts "
                    f"--duration S, a number of seconds > 0 (default {DURATION_S:g})")
        for option, value in (("--ambient-c", args.ambient_c), ("--battery", args.battery)):
            if value is not None:
                return (f"{option} {value} is not allowed in serial mode (--motor/--imu): it sets the virtual "
                        "bench's motor model; a real motor reports its own temperature and supply")
        if args.imu_model is not None:
            return (f"--imu-model {args.imu_model} is not allowed in serial mode (--motor/--imu): it picks the "
                    "virtual bench's IMU model; --imu names the port of the real one (or sim://NAME)")
        for option, value in (("--trace-seconds", args.trace_seconds), ("--trace-strides", args.trace_strides)):
            if value is not None:
                return (f"{option} {value} is not allowed in serial mode (--motor/--imu): a serial run's trace "
                        "holds its last jobs (docs/serial_mode.md)")
        if args.trace_wire:
            return ("--trace-wire is not allowed in serial mode (--motor/--imu): use --capture DIR for the bytes of "
                    "real ports")
    elif args.duration is not None:
        return (f"--duration {args.duration:g} is not allowed on the virtual bench: it is serial mode's run time "
                f"(with --motor and --imu); a virtual run lasts --strides N, an integer in 1..10000")
    if getattr(args, "experiment", None) is not None:
        for option, value in (("--strides", args.strides), ("--controller", args.controller)):
            if value is not None:
                return (f"{option} {value} is not allowed with --experiment {args.experiment}: the experiment is "
                        f"its own controller and sets its own length (its [controller] table; docs/calibration.md)")
    if args.scenario != "walk":
        for option, value in (("--body-mass", args.body_mass), ("--moment", args.moment),
                              ("--population", args.population)):
            if value is not None:
                return (f"{option} {value} is not allowed without --scenario walk: it sets the walking load, "
                        f"and the foot is {args.scenario}")
    return None


def _run_virtual(args: argparse.Namespace, cfg: RunConfig, run_dir: RunDir) -> int:
    """The virtual run proper, streaming into run_dir, which is published at the end."""
    from dataclasses import replace

    from host_tools.reports.report import TRACE_FILE, readings_text, run_into, tracking_text
    from host_tools.stop_signals import StopSignals

    fw_cfg = cfg.firmware
    assert fw_cfg is not None
    out = run_dir.out
    plant = "nominal plant" if cfg.plant_seed is None else f"plant drawn with seed {cfg.plant_seed}"
    if cfg.plant_file is not None:
        plant = plant.replace("plant", f"plant {cfg.plant_file}", 1)
        if cfg.design is not None:
            print(f"pafp run: note: --plant {cfg.plant_file} wins over the profile's [design] "
                  f"(motor {cfg.design.motor}): the bench runs that plant, the firmware keeps the design's limits",
                  file=sys.stderr)
    elif cfg.design is not None:
        d = cfg.design
        plant = plant.replace("plant", f"plant of the design ({d.motor}, {d.belt_driven_teeth}/{d.belt_driver_teeth} "
                              f"belt{', spring' if d.has_spring else ''})", 1)
    ideal = f", ideal: {', '.join(cfg.ideal)}" if cfg.ideal else ", real-device imperfections"
    walking = f", walking at {cfg.body_mass_kg:g} kg" if cfg.scenario == "walk" else ""
    print(f"pafp run: {cfg.strides} strides at {cfg.baud} baud, seed {cfg.seed}, {plant}{ideal}{walking} -> {out}")
    _warn_link_budget(cfg.baud, fw_cfg.control_hz, fw_cfg.full_values_hz)
    if getattr(args, "record", False):  # record.bin beside the outputs, staged with them (`pafp replay`)
        cfg = replace(cfg, record_to=run_dir.path)
    bar = _Progress(not args.quiet)
    with StopSignals() as stop:  # the run ends at its next segment; a second signal interrupts
        result, s = run_into(cfg, run_dir, plot=not args.no_plot, trace=not args.no_trace, progress=bar,
                             should_stop=lambda: stop.name, on_run=bar.done)
    print(f"  simulated {s['sim_time_s']:.2f} s in {s['wall_time_s']:.2f} s (realtime factor {s['realtime_factor']}; "
          f"{s['build']}); whole process {s['process_wall_time_s']:.2f} s (factor {s['process_realtime_factor']})")
    for line in tracking_text(s["tracking"]):
        print(line)
    print(f"  {readings_text(s)}")
    print(f"  deadline misses {s['deadline_misses']}, faults {s['faults'] or 'none'}, "
          f"CPU {100 * s['cpu_utilisation']:.2f} %, motor feedback {s['motor_link']['feedback_rate_hz']} Hz")
    print(f"  {'task':<11}{'jobs':>8}{'worst us':>11}{'bound us':>11}{'deadline':>10}{'misses':>8}")
    for name, t in s["tasks"].items():
        print(f"  {name:<11}{t['jobs']:>8}{t['wcrt_us']!s:>11}{t['bound_us']!s:>11}{t['deadline_us']!s:>10}"
              f"{t['misses']:>8}")
    t = s.get("thermal")
    if t is not None:  # the winding model and the supply (docs/design.md, "Winding temperature and battery in a run")
        from host_tools.reports.thermal import supply_text

        supply = supply_text(s.get("battery"))
        print(f"  winding {t['winding_c_end']} C at the end (max {t['winding_c_max']}, steady state "
              f"{t['steady_state_c']}, emulation only), motor reported max {t['motor_reported_c_max']} C; {supply}")
    written = ["summary.json", "report.md", *(["tracking.png"] if (out / "tracking.png").exists() else []),
               *(["thermal.png"] if (out / "thermal.png").exists() else []),
               *([] if args.no_trace else [TRACE_FILE]), "telemetry.bin/.csv"]
    print(f"  outputs: {out}/{', '.join(written)}")
    _say_controller_error(result.firmware.controller_error)
    if stop.exit_code is not None:
        print(f"pafp run: stopped by {stop.name} after {s['sim_time_s']:.2f} s simulated; the outputs hold "
              "what the run had (\"complete\": false)", file=sys.stderr)
        return stop.exit_code
    return 0 if not s["deadline_misses"] and not s["faults"] else 1


def _say_controller_error(error: str) -> None:
    """The controller raised (anything, sys.exit included) or returned a bad value: one line on stderr."""
    if error:
        print(f"pafp run: {error}; the supervisor latched the safe state (CONTROLLER_ERROR) and every file was "
              "written", file=sys.stderr)


def _experiment_strides(fw_cfg, controller: object) -> int:  # FirmwareConfig, SysidExperiment
    """Strides of the run's clock that cover the experiment once the supervisor is in RUN."""
    import math

    return max(1, math.ceil((getattr(controller, "duration_s") + 0.5) / fw_cfg.stride_s))  # noqa: B009


def _design(args: argparse.Namespace):  # -> Design | None
    """The --profile's [design], checked (None without one or without --profile)."""
    if args.profile is None:
        return None
    from hal.virtual.plant.design import load_design

    return load_design(args.profile)


def _firmware_config(args: argparse.Namespace):  # -> FirmwareConfig
    """The profile, with --controller (or --experiment) replacing its controller (the profile's parameters go
    with its own name)."""
    from firmware.config import load_firmware_config

    fw_cfg = load_firmware_config(args.profile)
    experiment = getattr(args, "experiment", None)
    if experiment is not None:
        args.controller = experiment
    if getattr(args, "motor_link", None) is not None:
        from firmware.drivers.motor_links import MOTOR_LINKS

        MOTOR_LINKS.check(args.motor_link, "--motor-link")
        fw_cfg = fw_cfg.with_changes(motor_link=args.motor_link)
    if args.controller is not None and args.controller != fw_cfg.controller:
        fw_cfg = fw_cfg.with_changes(controller=args.controller, controller_params={})
    return fw_cfg


def _controller(fw_cfg, args: argparse.Namespace) -> object:  # FirmwareConfig -> the built controller
    """Build the configured controller now, so a bad name, file, class or parameter stops before the run."""
    return controller_for(fw_cfg, args.scenario, args.body_mass)


def _trace_window_s(args, stride_s: float) -> float:
    """The trace's window in seconds: --trace-strides N strides, else --trace-seconds, else RunConfig's default."""
    from host_tools.runner import RunConfig

    if args.trace_strides is not None and args.trace_seconds is not None:
        raise ValueError("--trace-seconds and --trace-strides both given: choose one window")
    if args.trace_strides is not None:
        if not 1 <= args.trace_strides <= 10_000:
            raise ValueError(f"--trace-strides {args.trace_strides} out of range: an int in 1..10000")
        return args.trace_strides * stride_s
    return RunConfig.trace_window_s if args.trace_seconds is None else args.trace_seconds


def controller_for(fw_cfg, scenario: str, body_mass_kg: float) -> object:  # FirmwareConfig -> the controller
    """The profile's controller for a scenario (walking with the shipped impedance controller: tuned for the
    body mass unless the profile says otherwise)."""
    from firmware.control.registry import build_controller

    params = dict(fw_cfg.controller_params)
    if fw_cfg.controller == "impedance" and scenario == "walk":
        params.setdefault("body_mass_kg", body_mass_kg)
    return build_controller(fw_cfg.controller, fw_cfg, params)
