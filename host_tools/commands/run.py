"""`pafp run`: the firmware on the virtual bench (the main job), with a progress bar and a report."""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

HELP = "run the firmware on the virtual bench (the main job): tracking, deadlines, report"


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


def run(args: argparse.Namespace) -> int:
    """Run, write the outputs, print the summary table; exit 1 if a deadline was missed or a fault latched."""
    from firmware.config import load_firmware_config
    from host_tools.report import write_outputs
    from host_tools.runner import RunConfig, run_virtual

    try:
        fw_cfg = load_firmware_config(args.profile)
        cfg = RunConfig(strides=args.strides, baud=args.baud, seed=args.seed, board=args.board,
                        firmware=fw_cfg, reference_csv=args.reference)
        if args.reference is not None:
            from firmware.control.reference import GaitReference

            GaitReference.from_csv(args.reference)  # fail early with a clear message
    except (ValueError, OSError) as e:
        print(f"pafp run: {e}", file=sys.stderr)
        return 2
    out = args.out or Path("runs") / time.strftime("%Y%m%d-%H%M%S")
    print(f"pafp run: {cfg.strides} strides at {cfg.baud} baud, seed {cfg.seed} -> {out}")
    bar = _Progress(not args.quiet)
    result = run_virtual(cfg, progress=bar)
    bar.done()
    s = write_outputs(result, out)
    print(f"  simulated {s['sim_time_s']:.2f} s in {s['wall_time_s']:.2f} s (realtime factor {s['realtime_factor']})")
    print(f"  tracking: RMS {s['rms_error_deg']:.3f} deg, max {s['max_error_deg']:.3f} deg, lag {s['lag_ms']:.1f} ms")
    print(f"  deadline misses {s['deadline_misses']}, faults {s['faults'] or 'none'}, "
          f"CPU {100 * s['cpu_utilisation']:.2f} %, motor feedback {s['motor_link']['feedback_rate_hz']} Hz")
    print(f"  {'task':<11}{'jobs':>8}{'worst us':>11}{'bound us':>11}{'deadline':>10}{'misses':>8}")
    for name, t in s["tasks"].items():
        print(f"  {name:<11}{t['jobs']:>8}{t['wcrt_us']!s:>11}{t['bound_us']!s:>11}{t['deadline_us']!s:>10}"
              f"{t['misses']:>8}")
    print(f"  outputs: {out}/summary.json, report.md, tracking.png, trace.json, telemetry.bin/.csv")
    return 0 if not s["deadline_misses"] and not s["faults"] else 1
