"""`pafp fit RUN_DIR`: identify the plant from a recorded run (commands sent, encoder, IMU, motor current); `pafp fit
LOG.csv`: a motor's own parameters from a bench log another tool wrote (docs/csv_fit.md).

Writes into --out (default RUN_DIR/fit): plant_fitted.toml (`pafp run --plant` takes it), fit.json, fit.md,
fit.png and correlations.png. ``--validate OTHER_RUN`` adds the fitted plant's fit percentages on another
recording. Bad input (no record, a damaged one, too short a run, an unknown --params name): one line, exit 2.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

HELP = "identify the plant (grey-box least squares) from a recorded run; writes a plant profile with intervals"


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """Options of `pafp fit`."""
    parser.add_argument("run_dir", type=Path, metavar="RUN_DIR",
                        help="a run directory with record.bin and telemetry.csv (pafp run --experiment sysid), or a "
                        "CSV bench log (a file ending .csv: docs/csv_fit.md)")
    parser.add_argument("--out", type=Path, default=None, help="output directory (default RUN_DIR/fit)")
    parser.add_argument("--params", default=None, metavar="NAME,...",
                        help="the parameters to fit (default: all but torque_constant_scale; see docs/calibration.md)")
    parser.add_argument("--base", type=Path, default=None, metavar="FILE",
                        help="plant profile the fit starts from and whose other keys it keeps (default: packaged)")
    parser.add_argument("--validate", type=Path, default=None, metavar="RUN_DIR",
                        help="another recording: report the fitted plant's fit percentages on it")
    parser.add_argument("--no-plot", action="store_true", help="do not draw fit.png and correlations.png")
    csv = parser.add_argument_group("a CSV bench log (docs/csv_fit.md)")
    csv.add_argument("--columns", default=None, metavar="ROLE=HEADER[:unit],...",
                     help="map the log's columns: roles time, command, current, position, speed, torque")
    csv.add_argument("--preset", default=None, help="the column names an SDK's logger writes: tmotor-servo, "
                     "tmotor-mit, opensourceleg (default: the one whose columns the header has most of)")
    csv.add_argument("--gear-ratio", type=float, default=1.0, metavar="N",
                     help="the log's position, speed and torque are at the output of an N:1 gearbox (default 1: "
                     "the rotor's)")
    csv.add_argument("--kt", type=float, default=None, metavar="NM_PER_A",
                     help="without a torque column: the Kt that turns the per-ampere figures into N m")
    csv.add_argument("--window-ms", type=float, default=10.0, help="integration window (default 10 ms)")
    csv.add_argument("--min-speed", type=float, default=None, metavar="RAD_S",
                     help="windows slower than this are left out (default 5 %% of the 95th percentile speed)")


def run(args: argparse.Namespace) -> int:
    """Check the inputs, fit, write the outputs, print the table."""
    from host_tools.calibration.fit_data import load_experiment
    from host_tools.calibration.fit_model import DEFAULT_FIT, load_base
    from host_tools.calibration.fit_report import figure as _g
    from host_tools.calibration.fit_report import validate, verdict, write_fit_outputs
    from host_tools.calibration.plant_fit import check_params, fit_parts, fit_plant
    from host_tools.command_errors import input_error, output_error
    from host_tools.outdir import EXIT_WRITE_FAILED, OutDirError, RunDir
    from host_tools.studies.interrupt import Interrupted, interrupting
    from profiles import profile_path

    if args.run_dir.suffix.lower() == ".csv":
        return _run_csv(args)
    csv_only = [o for o, v in (("--columns", args.columns), ("--preset", args.preset), ("--kt", args.kt),
                               ("--min-speed", args.min_speed)) if v is not None]
    if csv_only or args.gear_ratio != 1.0 or args.window_ms != 10.0:
        print(f"pafp fit: {(csv_only or ['--gear-ratio/--window-ms'])[0]} applies to a CSV log (a file ending .csv), "
              f"not to the run directory {args.run_dir}", file=sys.stderr)
        return 2
    try:
        names = DEFAULT_FIT if args.params is None else tuple(n.strip() for n in args.params.split(",") if n.strip())
        check_params(names, args.params or "")
        base = load_base(args.base)
        base_text = (args.base or profile_path("plant_ak60_6.toml")).read_text(encoding="utf-8")
        exp = load_experiment(args.run_dir)
        fit_parts(exp)  # a recording a stall spoiled throughout: refused before the fit
        other = load_experiment(args.validate) if args.validate is not None else None
        run_dir = RunDir(args.out or args.run_dir / "fit")
    except (OSError, ValueError) as e:  # a file that cannot be read, a bad value (OutDirError, RecordError too)
        print(input_error("fit", e), file=sys.stderr)
        return 2
    print(f"pafp fit: {args.run_dir}: {len(exp.t)} samples, {len(exp.t_cmd)} commands, fitting {len(names)} "
          f"parameters -> {run_dir.out}", flush=True)
    try:
        with interrupting(), run_dir.filling() as staged:  # a stop signal: nothing published
            r = fit_plant(base, exp, names)
            extra = {"validation": validate(base, r, other)} if other is not None else {}
            s = write_fit_outputs(staged, base, base_text, r, exp, extra, plot=not args.no_plot)
    except Interrupted as stop:
        print(f"pafp fit: stopped by {stop.signal} after {stop.elapsed_s:.1f} s of fitting: nothing written, "
              f"{run_dir.out} keeps what it held", file=sys.stderr)
        return stop.exit_code
    except (OSError, OutDirError) as e:  # a write failed (nothing published) or --out was taken meanwhile
        print(output_error("fit", e, run_dir), file=sys.stderr)
        return EXIT_WRITE_FAILED
    print(f"  {r.nfev} simulations in {r.wall_s:.1f} s ({r.message})")
    print(f"  {'parameter':<28}{'value':>12}{'95 % ±':>12}{'rotor side':>12}{'timing':>10}{'stuck':>10}  verdict")
    for n, p in s["params"].items():
        print(f"  {n:<28}{_g(p['value'], '.5g'):>12}{_g(p['ci95_half_width'], '.3g'):>12}"
              f"{_g(p['ci95_rotor_side'], '.2g'):>12}{_g(p['ci95_timing'], '.2g'):>10}"
              f"{_g(p['ci95_stuck_starts'], '.2g'):>10}  "
              f"{verdict(p)}")
    for n in s["fixed"]:
        print(f"  {n:<28}{'fixed':>12}{'':>44}  NOT IDENTIFIABLE (fixed: see fit.md)")
    for seg, d in s["fit_percent"].items():
        print(f"  fit % on the {seg.replace('_', '-')} part: angle {_g(d['angle'], '.1f')}, current "
              f"{_g(d['current'], '.1f')}, IMU {_g(d['imu'], '.1f')}")
    adequacy = s["adequacy"]
    print(f"  model adequacy: {adequacy['verdict']}" + ("" if not adequacy["failing"] else
          " (the intervals are conditional on the model: " + "; ".join(adequacy["failing"]) + ")"))
    if other is not None:
        v = s["validation"]["fit_percent"]
        print(f"  fit % on {args.validate}: angle {_g(v['angle'], '.1f')}, current {_g(v['current'], '.1f')}, "
              f"IMU {_g(v['imu'], '.1f')}")
    return 0


def _run_csv(args: argparse.Namespace) -> int:
    """`pafp fit LOG.csv`: check the log and options, fit the motor, write fit.json and fit.md."""
    import json
    import math

    from host_tools.calibration.csv_log import read_log
    from host_tools.calibration.motor_fit import fit_motor, report
    from host_tools.command_errors import input_error, output_error
    from host_tools.outdir import EXIT_WRITE_FAILED, OutDirError, RunDir, write_atomic

    try:
        not_csv = [o for o, v in (("--params", args.params), ("--base", args.base), ("--validate", args.validate))
                   if v is not None]
        if not_csv:
            raise ValueError(f"{not_csv[0]} applies to a run directory, not to a CSV log ({args.run_dir})")
        for name, v, lo, hi in (("--gear-ratio", args.gear_ratio, 1.0, 1000.0), ("--kt", args.kt, 1e-3, 10.0),
                                ("--window-ms", args.window_ms, 0.1, 1000.0),
                                ("--min-speed", args.min_speed, 0.0, 5000.0)):
            if v is not None and not (math.isfinite(v) and lo <= v <= hi):
                raise ValueError(f"{name} {v!r} outside the allowed range [{lo:g}, {hi:g}]")
        log = read_log(args.run_dir, args.columns, args.preset)
        if args.kt is not None and log.torque is not None:
            raise ValueError(f"--kt applies to a log without a torque column: {args.run_dir} has one "
                             f"({log.where('torque')}), from which Kt is fitted")
        run_dir = RunDir(args.out or args.run_dir.with_name(args.run_dir.stem + "-fit"))
    except (OSError, ValueError) as e:
        print(input_error("fit", e), file=sys.stderr)
        return 2
    print(f"pafp fit: {args.run_dir}: {len(log.t)} rows, columns "
          + ", ".join(f"{c.role}={c.header}[{c.unit}]" for c in log.columns.values()) + f" -> {run_dir.out}",
          flush=True)
    try:
        with run_dir.filling() as staged:
            r = fit_motor(log, gear_ratio=args.gear_ratio, kt_nm_per_a=args.kt, window_s=args.window_ms * 1e-3,
                          min_speed_rad_s=args.min_speed)
            doc, md = report(log, r, args.gear_ratio)
            write_atomic(staged / "fit.json", json.dumps(doc, indent=2) + "\n")
            write_atomic(staged / "fit.md", md)
    except (OSError, OutDirError) as e:  # a write failed (nothing published) or --out was taken meanwhile
        print(output_error("fit", e, run_dir), file=sys.stderr)
        return EXIT_WRITE_FAILED
    except ValueError as e:  # too little motion: said before anything is written
        print(input_error("fit", e), file=sys.stderr)
        return 2
    print(f"  {'parameter':<32}{'value':>12}{'95 % ±':>12}  unit / verdict")
    for k, p in doc["params"].items():
        verdict = "" if p["identifiable"] else "  NOT IDENTIFIABLE"
        print(f"  {k:<32}{p['value']:>12.5g}{p['ci95_half_width']:>12.2g}  {p['unit']}{verdict}")
    for k, why in doc["not_in_the_data"].items():
        print(f"  {k:<32}{'—':>12}{'':>12}  {why}")
    print("  fit %: " + ", ".join(f"{k} {v:.1f}" for k, v in r.fit_pct.items()))
    return 0
