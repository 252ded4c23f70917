"""`pafp fit RUN_DIR`: identify the plant from a recorded run (commands sent, encoder, IMU, motor current).

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
                        help="a run directory with record.bin and telemetry.csv (pafp run --experiment sysid)")
    parser.add_argument("--out", type=Path, default=None, help="output directory (default RUN_DIR/fit)")
    parser.add_argument("--params", default=None, metavar="NAME,...",
                        help="the parameters to fit (default: all but torque_constant_scale; see docs/calibration.md)")
    parser.add_argument("--base", type=Path, default=None, metavar="FILE",
                        help="plant profile the fit starts from and whose other keys it keeps (default: packaged)")
    parser.add_argument("--validate", type=Path, default=None, metavar="RUN_DIR",
                        help="another recording: report the fitted plant's fit percentages on it")
    parser.add_argument("--no-plot", action="store_true", help="do not draw fit.png and correlations.png")


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
        with interrupting():  # a stop signal: nothing published, the staging directory removed
            r = fit_plant(base, exp, names)
            extra = {"validation": validate(base, r, other)} if other is not None else {}
            s = write_fit_outputs(run_dir.path, base, base_text, r, exp, extra, plot=not args.no_plot)
            run_dir.publish()
    except Interrupted as stop:
        run_dir.discard()
        print(f"pafp fit: stopped by {stop.signal} after {stop.elapsed_s:.1f} s of fitting: nothing written, "
              f"{run_dir.out} keeps what it held", file=sys.stderr)
        return stop.exit_code
    except (OSError, OutDirError) as e:  # a write failed (nothing published) or --out was taken meanwhile
        run_dir.discard()
        print(output_error("fit", e, run_dir), file=sys.stderr)
        return EXIT_WRITE_FAILED
    except BaseException:
        run_dir.discard()
        raise
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
    if other is not None:
        v = s["validation"]["fit_percent"]
        print(f"  fit % on {args.validate}: angle {_g(v['angle'], '.1f')}, current {_g(v['current'], '.1f')}, "
              f"IMU {_g(v['imu'], '.1f')}")
    return 0
