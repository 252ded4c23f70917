"""`pafp replay`'s engine: the firmware re-executed in virtual time on a record's inputs, its outputs compared.

The firmware is built on a `ReplayBoard` (hal/record/replay.py) from the configuration the record's header
holds, or from another profile or controller; then each recorded job runs in order at its recorded time
with its recorded inputs, and what it writes is compared with what the recorded run wrote. The first job
whose outputs differ is the *first divergence* (time, task, port, both byte strings decoded as messages);
the replay goes on open-loop on the recorded inputs and counts every diverging job. No device and no plant
takes part: a changed controller sees the sensors of the recorded run, not what the plant would have done
with its commands (that is the fitted twin's job, docs/calibration.md).
"""

from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import BinaryIO

from firmware.app import Firmware
from firmware.config import TASK_NAMES, FirmwareConfig
from hal.record.format import Kind, RecordError
from hal.record.reader import RecordReader, Section
from hal.record.replay import ReplayBoard, replay_sections
from hal.record.streams import item_bytes, port_name
from host_tools.recording import INIT_TASK, RECORD_NAME, STOP_TASK, check_header
from host_tools.runner import gait_reference
from rtos import Job

__all__ = ["Divergence", "ReplayResult", "find_record", "replay_record"]

_PROTOCOL = {"motor": "vesc", "telemetry": "telemetry", "imu": "rvc"}


def find_record(run_dir: Path) -> Path:
    """The record of a run directory (or the record file itself); RecordError when there is none."""
    path = run_dir / RECORD_NAME if run_dir.is_dir() else run_dir
    if path.exists() and not path.is_file():
        raise RecordError(f"record {path}: not a regular file (a run directory or its {RECORD_NAME} is needed)")
    if not path.is_file():
        raise RecordError(f"record {path}: not found (a run records its inputs into {RECORD_NAME}: serial runs "
                          "always, virtual runs with --record)")
    return path


@dataclass
class Divergence:
    """The first job whose outputs differ from the record's."""

    t_s: float
    task: str
    job_index: int
    port: str
    expected_hex: str
    produced_hex: str
    expected: list[dict]
    produced: list[dict]
    control_t_s: float | None = None  # the control job of that period (whose command the motor task sends)

    def as_dict(self) -> dict:
        """For divergence.json."""
        return {"t_s": round(self.t_s, 9), "task": self.task, "job_index": self.job_index, "port": self.port,
                "control_job_t_s": None if self.control_t_s is None else round(self.control_t_s, 9),
                "expected_hex": self.expected_hex, "produced_hex": self.produced_hex,
                "expected": self.expected, "produced": self.produced}


@dataclass
class ReplayResult:
    """What a replay found: identical or not, the first divergence, per-port streams, counts."""

    header: dict
    footer: dict
    firmware: Firmware
    jobs: int
    diverging_jobs: int
    first: Divergence | None
    streams: dict[str, dict]
    starved: int
    unused: int
    sim_time_s: float
    wall_time_s: float
    changed: dict
    cpu_time_s: float = 0.0  # this process's CPU time over the replay loop (the wall time less a busy host's share)

    @property
    def identical(self) -> bool:
        """True when every output of every job matched the record."""
        return self.diverging_jobs == 0 and all(s["identical"] for s in self.streams.values())


def _decode(port: str, data: bytes, extra_fields: int) -> list[dict]:
    """The messages in data as JSON-ready dicts (raw hex where the port has no codec)."""
    from host_tools.commands.decode import _jsonable, message_fields

    if port == "motor":
        from protocol import vesc

        return [_jsonable(message_fields(m)) for m in vesc.Decoder(direction="to-motor").feed(data)]
    if port == "telemetry":
        from protocol.telemetry import TelemetryDecoder, record_to_row

        return [_jsonable(record_to_row(r)) for r in TelemetryDecoder(extra_fields).feed(data)]
    return [{"type": "raw", "hex": data.hex()}] if data else []


def _divergence(section: Section, diff: dict[int, tuple[list, list]], f_cpu: int, extra: int) -> Divergence:
    key = min(diff)  # UART writes (motor first) before the pins
    expected, produced = diff[key]
    port = port_name(key)
    exp = b"".join(item_bytes(key, i) for i in expected)
    got = b"".join(item_bytes(key, i) for i in produced)
    task = ("init" if section.task_id == INIT_TASK else "stop" if section.task_id == STOP_TASK
            else TASK_NAMES[section.task_id])
    if key >> 2 == Kind.WRITE:
        exp_msgs, got_msgs = _decode(port, exp, extra), _decode(port, got, extra)
    else:
        exp_msgs = [{"type": port, "value": repr(v)} for v in expected]
        got_msgs = [{"type": port, "value": repr(v)} for v in produced]
    return Divergence(section.start / f_cpu, task, section.index, port, exp.hex(), got.hex(), exp_msgs, got_msgs)


def replay_record(path: Path, fw_cfg: FirmwareConfig | None = None, controller: object = None,
                  telemetry_out: BinaryIO | None = None,
                  progress: Callable[[float], None] | None = None) -> ReplayResult:
    """Re-execute the firmware on the record at `path`; `fw_cfg`/`controller` replace the recorded ones.

    The telemetry the replayed firmware writes goes to `telemetry_out` (about 64 KB at a time). RecordError
    (naming the byte offset) when the record is truncated or damaged.
    """
    reader = RecordReader(path)
    header = reader.header
    try:
        recorded_cfg = check_header(header, path)  # RecordError naming the key
        f_cpu = int(header["f_cpu_hz"])
        replay = ReplayBoard(header, {"telemetry": telemetry_out} if telemetry_out is not None else None)
        names = list(header["tasks"])
    except (KeyError, TypeError, ValueError) as e:
        reader.close()
        raise RecordError(f"record {path}: header does not describe a run ({type(e).__name__}: {e})") from None
    cfg = fw_cfg or recorded_cfg
    changed = {k: [repr(v), repr(getattr(cfg, k))] for k, v in vars(recorded_cfg).items() if getattr(cfg, k) != v}
    sections = reader.sections()
    first_section = next(sections, None)
    if first_section is None or first_section.task_id != INIT_TASK:
        raise RecordError(f"record {path}: no init section at the start of the first chunk")
    replay.begin(first_section)
    fw = Firmware(replay.board, cfg, reference=gait_reference(header.get("reference", {}), cfg.stride_s),
                  controller=controller)
    fw.kernel_health = replay.health
    if header.get("mode") == "serial":
        fw.supervisor.latch_deadline_misses = False  # as serial mode runs it
    bodies: dict[int, tuple[Callable[[Job], object], Job]] = {}
    for t in fw.tasks:
        assert t.body is not None
        bodies[names.index(t.name)] = (t.body, Job(t))
    extra = len(fw.published_names)
    first: list[Divergence] = []
    diverging = 0
    wall0, cpu0 = time.perf_counter(), time.process_time()

    def on_diff(section: Section, diff: dict) -> None:
        nonlocal diverging
        diverging += 1
        if not first:
            d = _divergence(section, diff, f_cpu, extra)
            # the control job of the period whose command this job sends (control runs before the motor task)
            d.control_t_s = None if replay.last_control < 0 else replay.last_control / f_cpu
            first.append(d)

    diff0 = replay.finish()
    replay.account(diff0)
    if diff0:
        on_diff(first_section, diff0)
    jobs, last = replay_sections(replay, sections, bodies, names.index("control"), STOP_TASK,
                                 lambda start: fw.stop(start / f_cpu, 0.5), on_diff,
                                 None if progress is None else lambda start: progress(start / f_cpu))
    wall, cpu = time.perf_counter() - wall0, time.process_time() - cpu0
    return ReplayResult(header, reader.footer, fw, jobs, diverging, first[0] if first else None,
                        {k: v.as_dict() for k, v in sorted(replay.streams.items())}, replay.starved, replay.unused,
                        last / f_cpu, wall, changed, cpu)
