"""Recording a run's inputs for `pafp replay`: the header that says what ran, the board and tasks wrapped.

The composition roots (runner.py for the virtual bench, serial_run.py for real ports) call
`start_recording` before they build the firmware (its constructor's calls are the ``init`` section), hand
the firmware the recording board, run `RunRecording.tasks` instead of the firmware's own task list, and
call `stop_section` before the stop path and `close` at the end. The record is ``record.bin`` in the run
directory (hal/record/format.py); docs/calibration.md says what a replay can and cannot reproduce.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Callable
from dataclasses import replace
from pathlib import Path

from firmware.config import TASK_NAMES, CostModel, FirmwareConfig
from firmware.control.pid import FeedforwardParams, PidGains
from firmware.drivers.ground_sensor_config import GroundSensorConfig
from firmware.safety import SafetyLimits, ThermalLimits
from hal.interfaces import Board
from hal.record.recorder import Recorder, SectionedBody
from host_tools.build_info import describe, version
from rtos import Job, Task

__all__ = ["INIT_TASK", "RECORD_NAME", "STOP_TASK", "RunRecording", "check_header", "config_dict", "config_from_dict",
           "read_record_header"]

RECORD_NAME = "record.bin"
INIT_TASK = 254  # the section of the firmware's constructor
STOP_TASK = 255  # the section of the stop path (zero current, then the brake)


def config_dict(cfg: FirmwareConfig) -> dict:
    """The firmware configuration as JSON-ready values (`config_from_dict` builds it back, equal)."""
    d = dataclasses.asdict(cfg)
    d["task_cycles"] = {k: dataclasses.asdict(v) if isinstance(v, CostModel) else {"base": 500, "per_byte": 0}
                        for k, v in cfg.task_cycles.items()}
    return d


def config_from_dict(d: dict) -> FirmwareConfig:
    """The firmware configuration a record's header holds (ValueError naming a bad value, as the profile's)."""
    d = dict(d)
    return FirmwareConfig(**{**d, "position_gains": PidGains(**d["position_gains"]),
                             "velocity_gains": PidGains(**d["velocity_gains"]),
                             "feedforward_params": FeedforwardParams(**d["feedforward_params"]),
                             "safety": SafetyLimits(**d["safety"]),
                             # [thermal] (issue 23); a record written before it has none: the defaults
                             "thermal": ThermalLimits(**d.get("thermal", {})),
                             "task_cycles": {k: CostModel(**v) for k, v in d["task_cycles"].items()},
                             "ground_sensors": GroundSensorConfig.from_table(
                                 {**d["ground_sensors"],
                                  "calibration": [list(r) for r in d["ground_sensors"]["calibration"]]})})


def check_header(header: dict, path: Path) -> FirmwareConfig:
    """The firmware configuration of a record's header, every key a replay or a fit uses checked: RecordError in one
    line naming the record, the key and what was expected (a version-1 record has no header checksum, and a
    hand-edited one may name what this pafp does not know)."""
    from firmware.control.registry import build_controller
    from hal.record.format import RecordError
    from host_tools.walk import SPEEDS

    def bad(key: str, what: str) -> RecordError:
        return RecordError(f"record {path}: header key {key!r} {what}")

    def table(doc: dict, key: str, where: str) -> dict:
        value = doc.get(key)
        if not isinstance(value, dict):
            raise bad(where, "missing: expected a table" if value is None else f"= {value!r}: expected a table")
        return value

    table(header, "firmware", "firmware")
    f_cpu = header.get("f_cpu_hz")
    if isinstance(f_cpu, bool) or not isinstance(f_cpu, int) or f_cpu <= 0:
        raise bad("f_cpu_hz", f"= {f_cpu!r}: expected an integer > 0")
    tasks = header.get("tasks")
    if not isinstance(tasks, list) or not set(TASK_NAMES) <= set(t for t in tasks if isinstance(t, str)):
        raise bad("tasks", f"= {tasks!r}: expected a list naming the firmware's tasks {list(TASK_NAMES)}")
    for key in ("ports", "encoder"):
        table(header, key, key)
    reference = header.get("reference", {})
    if not isinstance(reference, dict):
        raise bad("reference", f"= {reference!r}: expected a table")
    speed, csv = reference.get("speed"), reference.get("csv")
    if speed is not None and speed not in SPEEDS:
        raise bad("reference.speed", f"= {speed!r}: expected one of {list(SPEEDS)}")
    if csv is not None and not (isinstance(csv, str) and csv):
        raise bad("reference.csv", f"= {csv!r}: expected the path of the gait reference CSV")
    if csv is not None and not Path(csv).is_file():
        raise bad("reference.csv", f"= {csv!r}: the gait reference CSV it names cannot be read (not found)")
    try:
        cfg = config_from_dict(header["firmware"])
        build_controller(cfg.controller, cfg, dict(cfg.controller_params))
    except (KeyError, TypeError, ValueError, AttributeError) as e:
        what = f"missing key {e}" if isinstance(e, KeyError) else " ".join(str(e).split())
        raise bad("firmware", f"does not describe a firmware configuration: {what}") from None
    return cfg


def read_record_header(path: Path) -> tuple[dict, FirmwareConfig]:
    """(the header, its firmware configuration) of the record at ``path``, checked (:func:`check_header`;
    RecordError naming the byte offset or the key)."""
    from hal.record.reader import RecordReader

    reader = RecordReader(path)
    reader.close()
    return reader.header, check_header(reader.header, path)


def _board_header(board: Board) -> dict:
    ports = {role: {"baud": u.baud, "name": u.name} for role, u in board.uarts().items()}
    return {"ports": ports, "encoder": {"bits": board.encoder.bits, "arr": board.encoder.arr},
            "can_bitrate": board.can.bitrate if board.can is not None else None, "led": board.led.level,
            "f_cpu_hz": board.f_cpu_hz}


class RunRecording:
    """A run being recorded into `directory`/record.bin: the board to hand the firmware, the tasks to run."""

    def __init__(self, directory: Path, board: Board, fw_cfg: FirmwareConfig, mode: str, reference: dict,
                 start_cycles: int, extra: dict | None = None) -> None:
        """Write the header and open the ``init`` section (at `start_cycles`), before the firmware is built."""
        header = {"mode": mode, "firmware": config_dict(fw_cfg), "reference": reference, "tasks": list(TASK_NAMES),
                  **_board_header(board), **(extra or {})}
        self.path = directory / RECORD_NAME
        self.recorder = Recorder(self.path, header)
        self.board = self.recorder.board(board)
        self._ids = {name: i for i, name in enumerate(TASK_NAMES)}
        self.recorder.job(INIT_TASK, start_cycles, 0)

    def tasks(self, tasks: list[Task]) -> list[Task]:
        """The firmware's tasks, each body opening its job's section first."""
        return [replace(t, body=self._wrap(self._ids[t.name], t.body)) for t in tasks]

    def _wrap(self, task_id: int, body: Callable[[Job], object] | None) -> Callable[[Job], object]:
        assert body is not None
        return SectionedBody(self.recorder, task_id, body)

    def health(self, kernel_health: Callable[[], tuple[int, int]]) -> Callable[[], tuple[int, int]]:
        """The kernel's deadline health as the firmware reads it, recorded."""
        return self.recorder.health(kernel_health)

    def stop_section(self, t_cycles: int) -> None:
        """The stop path begins at t_cycles: its calls form the last section."""
        self.recorder.job(STOP_TASK, t_cycles, 0)

    def close(self, footer: dict | None = None) -> dict:
        """End the record (the footer names the pafp that wrote it: asked here, after the run, not before it,
        so the start-up costs nothing more); returns what summary.json says of it."""
        self.recorder.close({**(footer or {}), "pafp": {"version": version(), "build": describe()}})
        r = self.recorder
        return {"file": RECORD_NAME, "jobs": r.jobs, "events": r.events, "raw_bytes": r.raw_bytes,
                "bytes": self.path.stat().st_size}
