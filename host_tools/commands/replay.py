"""`pafp replay RUN_DIR`: re-execute the firmware on a run's recorded inputs; byte-identical or the first divergence.

Writes into --out (default runs/<timestamp>-replay): telemetry.bin/.csv (what the replayed firmware logged),
summary.json (per port: recorded and replayed items and SHA-256, identical or not; jobs; the first
divergence), divergence.json and replay.md. Exit 0 when every output matched, 1 when the replay diverged,
2 for a bad input (a missing, truncated or damaged record: one line naming the byte offset).
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

HELP = "re-execute the firmware on a run's recorded inputs: byte-identical outputs, or the first divergence"


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """Options of `pafp replay`."""
    parser.add_argument("run_dir", type=Path, metavar="RUN_DIR", help="a run directory holding record.bin "
                        "(or the record file itself)")
    parser.add_argument("--profile", type=Path, default=None,
                        help="firmware profile TOML to replay with instead of the recorded configuration")
    parser.add_argument("--controller", default=None, metavar="NAME|FILE.py:CLASS",
                        help="controller to replay with instead of the recorded one")
    parser.add_argument("--out", type=Path, default=None, help="output directory (default runs/<timestamp>-replay)")


def _message_line(msgs: list[dict]) -> str:
    if not msgs:
        return "nothing"
    m = msgs[0]
    fields = ", ".join(f"{k}={v:.6g}" if isinstance(v, float) else f"{k}={v}" for k, v in m.items() if k != "type")
    return f"{m.get('type')}({fields})" + (f" and {len(msgs) - 1} more" if len(msgs) > 1 else "")


def run(args: argparse.Namespace) -> int:
    """Check the inputs, replay, write the outputs, print the verdict."""
    from hal.record.format import RecordError
    from host_tools.calibration.replay_run import find_record, replay_record
    from host_tools.command_errors import input_error, output_error
    from host_tools.outdir import EXIT_WRITE_FAILED, OutDirError, RunDir, write_atomic
    from host_tools.recording import read_record_header

    out = args.out or Path("runs") / (time.strftime("%Y%m%d-%H%M%S") + "-replay")
    try:
        path = find_record(args.run_dir)
        # every key the replay uses checked, one line naming it (the recorded controller unless another is given)
        header, fw_cfg = read_record_header(path, args.controller is None and args.profile is None)
        if args.profile is not None:
            from firmware.config import load_firmware_config

            fw_cfg = load_firmware_config(args.profile)
        if args.controller is not None and args.controller != fw_cfg.controller:
            fw_cfg = fw_cfg.with_changes(controller=args.controller, controller_params={})
        controller = None
        if args.controller is not None:
            from firmware.control.registry import build_controller

            controller = build_controller(fw_cfg.controller, fw_cfg, dict(fw_cfg.controller_params))
        changed = args.profile is not None or args.controller is not None
        run_dir = RunDir(out)
    except (OSError, ValueError) as e:  # a file that cannot be read, a bad value (OutDirError, RecordError too)
        print(input_error("replay", e), file=sys.stderr)
        return 2
    print(f"pafp replay: {path} ({header.get('mode')} run)"
          + (" with a changed configuration" if changed else "") + f" -> {out}")
    from host_tools.reports.report import _write_telemetry_csv

    try:
        with run_dir.filling() as staged:
            with (staged / "telemetry.bin").open("wb") as tel:
                r = replay_record(path, fw_cfg if changed else None, controller, tel)
            data = (staged / "telemetry.bin").read_bytes()
            decoder = _write_telemetry_csv(data, staged / "telemetry.csv", r.firmware.f_cpu_hz,
                                           extra_names=r.firmware.published_names)
            s = {"record": str(path), "mode": r.header.get("mode"), "identical": r.identical, "jobs": r.jobs,
                 "diverging_jobs": r.diverging_jobs, "first_divergence": r.first.as_dict() if r.first else None,
                 "ports": r.streams, "starved_calls": r.starved, "unused_inputs": r.unused,
                 "changed": r.changed, "sim_time_s": round(r.sim_time_s, 6),
                 "wall_time_s": round(r.wall_time_s, 3),
                 "realtime_factor": round(r.sim_time_s / r.wall_time_s, 2) if r.wall_time_s > 0 else None,
                 "recorded_run": r.footer, "telemetry_decoder": decoder}
            write_atomic(staged / "summary.json", json.dumps(s, indent=2) + "\n")
            first = r.first.as_dict() if r.first else None
            write_atomic(staged / "divergence.json", json.dumps(first, indent=2) + "\n")
            write_atomic(staged / "replay.md", _report(s))
    except RecordError as e:  # a record that ends or breaks mid-way: nothing published
        print(f"pafp replay: {e}", file=sys.stderr)
        return 2
    except (OSError, OutDirError) as e:  # a write failed (nothing published) or --out was taken meanwhile
        print(output_error("replay", e, run_dir), file=sys.stderr)
        return EXIT_WRITE_FAILED
    print(f"  replayed {r.jobs} jobs, {r.sim_time_s:.3f} s of firmware time in {r.wall_time_s:.2f} s "
          f"(realtime factor {s['realtime_factor']})")
    for name, p in r.streams.items():
        print(f"  {name:<10} {p['recorded_items']:>8} recorded {p['replayed_items']:>8} replayed  "
              f"{'identical' if p['identical'] else 'DIFFERENT'}")
    if r.first is None:
        print("  byte-identical: every output of every job matches the record")
        return 0
    d = r.first
    print(f"  first divergence at {d.t_s:.6f} s, task {d.task} (job {d.job_index}), port {d.port}"
          + (f" (the command of the control job at {d.control_t_s:.6f} s)" if d.control_t_s is not None else "")
          + ":")
    print(f"    recorded: {_message_line(d.expected)}")
    print(f"    replayed: {_message_line(d.produced)}")
    print(f"  {r.diverging_jobs} jobs diverged; the replay went on open-loop on the recorded inputs")
    return 1


def _report(s: dict) -> str:
    lines = ["# Replay", "", f"Record `{s['record']}` ({s['mode']} run), {s['jobs']} jobs, "
             f"{s['sim_time_s']} s of firmware time, realtime factor {s['realtime_factor']}.", ""]
    if s["changed"]:
        lines += ["Changed configuration:", ""] + [f"- `{k}`: {a} → {b}" for k, (a, b) in s["changed"].items()] + [""]
    lines += ["| port | recorded | replayed | identical |", "|---|---|---|---|"]
    lines += [f"| {k} | {p['recorded_items']} | {p['replayed_items']} | {p['identical']} |"
              for k, p in s["ports"].items()]
    d = s["first_divergence"]
    lines += [""]
    if d is None:
        lines += ["Byte-identical: every output of every job matches the record."]
    else:
        lines += [f"First divergence at {d['t_s']} s in task `{d['task']}` (job {d['job_index']}), port "
                  f"`{d['port']}`.", "", f"- recorded: `{json.dumps(d['expected'])}`",
                  f"- replayed: `{json.dumps(d['produced'])}`", "",
                  f"{s['diverging_jobs']} jobs diverged in all; after the first, the replay continued open-loop on "
                  "the recorded inputs (the sensors saw what the recorded run's plant did, not what the changed "
                  "firmware's commands would have made it do)."]
    return "\n".join(lines) + "\n"
