"""One point of a sweep, run where Dask puts it: `run_point(task)` returns the point's row (never raises).

`run_point` is a plain top-level function of a picklable `PointTask`, so Dask ships both to any worker;
the task carries the firmware profile's text, so workers need no shared disk. The only contact with the
plant-parameter draw is `plant_seed_run_options`. A row's figures are those of the run's summary: the true
RMS (emulation only) and the measured one (reference minus the IMU pitch the firmware received, as the
report measured it), over the time in RUN; NaN where the run had too little of it.
"""

from __future__ import annotations

import copy
import functools
import logging
import math
import tempfile
import time
import tomllib
import traceback
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

__all__ = ["FIGURES", "SATURATION_LEVEL", "PointTask", "error_row", "failure_text", "firmware_config_of",
           "plant_seed_run_options", "run_config_of", "run_point", "warm_up"]

SATURATION_LEVEL = 0.98  # of the control current limit: a tick at or above it counts as saturated
#: Summary figures of a row, in column order.
FIGURES = ("rms_error_deg", "rms_measured_deg", "max_error_deg", "lag_ms", "deadline_misses", "faults",
           "saturation_fraction", "sim_time_s", "wall_time_s", "realtime_factor")


def plant_seed_run_options(seed: int) -> dict[str, Any]:
    """Extra RunConfig keyword arguments for the Monte Carlo point whose plant seed is `seed`.

    The sweep's one contact with the seeded plant draw (`hal.virtual.plant.draw.draw_plant`, a plain
    function of (profile, seed)): the same option as `pafp run --plant-seed seed`.
    """
    return {"plant_seed": seed}


@dataclass(frozen=True)
class PointTask:
    """Everything a worker needs to run one point."""

    index: int
    params: tuple[tuple[str, Any], ...]  # grid values: run.* keys and firmware-profile keys
    sample: int | None
    plant_seed: int | None
    seed: int
    run: tuple[tuple[str, Any], ...]  # the base run's RunConfig values (strides, baud, seed, board, settle_s)
    profile_name: str
    profile_text: str
    timeout_s: float


def firmware_config_of(profile_text: str, overrides: dict[str, Any], profile_name: str = "profile") -> Any:
    """The FirmwareConfig of the profile text with dotted keys overridden (ValueError names the profile)."""
    return _firmware_config(profile_text, tuple(overrides.items()), profile_name)


@functools.lru_cache(maxsize=64)  # the Monte Carlo samples of a grid cell share one (frozen) configuration
def _firmware_config(profile_text: str, items: tuple[tuple[str, Any], ...], profile_name: str) -> Any:
    overrides = dict(items)
    from firmware.config import load_firmware_config
    from host_tools.studies.sweep_spec import set_profile_key

    doc = tomllib.loads(profile_text)
    if not overrides:
        doc_text = profile_text
    else:
        doc = copy.deepcopy(doc)
        for k, v in overrides.items():
            set_profile_key(doc, k, v)
        import tomlkit

        doc_text = tomlkit.dumps(doc)
    with tempfile.TemporaryDirectory(prefix="pafp-point-") as d:
        p = Path(d) / "firmware.toml"
        p.write_text(doc_text, encoding="utf-8")
        try:
            return load_firmware_config(p)
        except ValueError as e:
            raise ValueError(str(e).replace(str(p), profile_name)) from None


def run_config_of(task: PointTask, plant_options: Callable[[int], dict[str, Any]] = plant_seed_run_options,
                  trace: bool = False) -> Any:
    """The RunConfig of a point (the plant draw's options merged in for a Monte Carlo point); ``trace``: keep the
    RTOS trace (`--point` writes trace.pftrace; the sweep's rows do not need it)."""
    from host_tools.runner import RunConfig

    params = dict(task.params)
    run = dict(task.run)
    run.update({k.removeprefix("run."): v for k, v in params.items() if k.startswith("run.")})
    run["seed"] = task.seed
    fw = firmware_config_of(task.profile_text, {k: v for k, v in params.items() if not k.startswith("run.")},
                            task.profile_name)
    extra = plant_options(task.plant_seed) if task.plant_seed is not None else {}
    traced = {} if trace else {"trace_capacity": 0}  # with it: RunConfig's default, as `pafp run`
    plant_file = Path(run["plant_file"]) if run.get("plant_file") else None
    return RunConfig(strides=run["strides"], baud=run["baud"], seed=run["seed"], board=run["board"],
                     settle_s=run["settle_s"], firmware=fw, plant_file=plant_file, **traced, **extra)


class _PointTimeout(Exception):
    pass


def _deadline(timeout_s: float) -> Callable[[float], None]:
    """A run_virtual progress callback that stops the run once timeout_s of wall time has passed."""
    end = time.perf_counter() + timeout_s

    def check(_fraction: float) -> None:
        if time.perf_counter() > end:
            raise _PointTimeout
    return check


def _base_row(task: PointTask) -> dict[str, Any]:
    row: dict[str, Any] = {"point": task.index}
    row.update(dict(task.params))
    row.update({"sample": task.sample, "plant_seed": task.plant_seed, "seed": task.seed})
    return row


def error_row(task: PointTask, status: str, error: str, wall_time_s: float = math.nan) -> dict[str, Any]:
    """The row of a point that gave no figures (status 'error' or 'timeout')."""
    row = _base_row(task)
    row.update({"status": status, "error": error})
    row.update({f: math.nan for f in FIGURES})
    row.update({"deadline_misses": -1, "faults": "", "wall_time_s": wall_time_s})
    return row


def _float(value: float | None) -> float:
    """A summary figure for the table: NaN where the summary has null (too little time in RUN)."""
    return math.nan if value is None else float(value)


def failure_text(e: BaseException) -> str:
    """A point's failure as one line for its row: the exception, its message and where it was raised."""
    last = traceback.extract_tb(e.__traceback__)[-1] if e.__traceback__ else None
    where = f" ({Path(last.filename).name}:{last.lineno})" if last else ""
    return f"{type(e).__name__}: {e}{where}".replace("\n", " ")


def warm_up() -> str:
    """Import what a point needs (run once on every worker before the first point); returns the build."""
    from host_tools.build_info import describe
    from host_tools.reports.report import summarise  # noqa: F401
    from host_tools.runner import run_virtual  # noqa: F401

    return describe()


def run_point(task: PointTask, plant_options: Callable[[int], dict[str, Any]] = plant_seed_run_options
              ) -> dict[str, Any]:
    """Run one point on the virtual bench and return its row; an exception or a timeout becomes the row's error."""
    from host_tools.reports.report import summarise
    from host_tools.runner import run_virtual

    logging.getLogger("firmware.safety").setLevel(logging.ERROR)  # a fault is in the row, not on the console
    t0 = time.perf_counter()
    try:
        cfg = run_config_of(task, plant_options)
        r = run_virtual(cfg, progress=_deadline(task.timeout_s))
        s = summarise(r)
    except _PointTimeout:
        return error_row(task, "timeout", f"timeout: no result within {task.timeout_s:g} s",
                         time.perf_counter() - t0)
    except Exception as e:  # noqa: BLE001 - any failure of a point is its row, not the sweep's end
        return error_row(task, "error", failure_text(e), time.perf_counter() - t0)
    p = r.probe.arrays()
    start = r.gait_start_s if r.gait_start_s is not None else math.inf
    gait = p["t_s"] >= start
    i = p["current_cmd_a"][gait]
    sat = float(np.mean(np.abs(i) >= SATURATION_LEVEL * cfg.firmware.current_limit_a)) if len(i) else math.nan
    faults = ",".join(s["faults"])
    row = _base_row(task)
    truth = s["tracking"]["truth"]  # the sweep's error columns: the plant's true angle (emulation only)
    row.update({
        "status": "fault" if faults else "ok", "error": f"fault {faults}" if faults else "",
        "rms_error_deg": _float(truth["rms_deg"]), "rms_measured_deg": _float(s["tracking"]["imu"]["rms_deg"]),
        "max_error_deg": _float(truth["max_deg"]), "lag_ms": _float(truth["lag_ms"]),
        "deadline_misses": int(s["deadline_misses"]), "faults": faults, "saturation_fraction": round(sat, 5),
        "sim_time_s": float(s["sim_time_s"]), "wall_time_s": round(r.wall_time_s, 4),
        "realtime_factor": float(s["realtime_factor"] or math.nan),
    })
    return row
