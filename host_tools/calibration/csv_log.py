"""A bench log in CSV for `pafp fit LOG.csv`: its column mapping (presets for the SDKs' logs), units and checks.

Roles (docs/csv_fit.md): ``time``, ``current`` (measured q current) and ``position`` or ``speed`` are required;
``command`` (the commanded current: for the current lag) and ``torque`` (an external torque sensor on the shaft, the
torque the motor delivers to the load: for Kt) are optional. ``--columns role=HEADER[:unit],...`` maps them; a preset
names the columns an SDK's logger writes. Every check runs before the fit and fails in one line naming the value, the
column and the allowed range.
"""

from __future__ import annotations

import csv
import math
from dataclasses import dataclass
from pathlib import Path

import numpy as np

__all__ = ["PRESETS", "ROLES", "UNITS", "BenchLog", "parse_columns", "read_log"]

ROLES = ("time", "command", "current", "position", "speed", "torque")
UNITS: dict[str, dict[str, float]] = {  # role -> unit -> factor to SI
    "time": {"s": 1.0, "ms": 1e-3, "us": 1e-6},
    "command": {"A": 1.0, "mA": 1e-3},
    "current": {"A": 1.0, "mA": 1e-3},
    "position": {"rad": 1.0, "deg": math.pi / 180.0, "rev": 2.0 * math.pi},
    "speed": {"rad/s": 1.0, "deg/s": math.pi / 180.0, "rpm": 2.0 * math.pi / 60.0},
    "torque": {"Nm": 1.0, "Nmm": 1e-3},
}
PRESETS: dict[str, dict[str, str]] = {
    # TMotorCANControl 1.2 servo_can.TMotorManager_servo_can(CSV_file=...): "pi_time" then LOG_VARIABLES
    # (get_motor_angle_radians, get_motor_velocity_radians_per_second, get_current_qaxis_amps)
    "tmotor-servo": {"time": "pi_time", "position": "motor_position", "speed": "motor_speed",
                     "current": "motor_current"},
    # TMotorCANControl 1.2 mit_can.TMotorManager_mit_can: output side (after the gearbox: give --gear-ratio); its
    # "output_torque" is Kt x current, not a sensor, and is not used
    "tmotor-mit": {"time": "pi_time", "position": "output_angle", "speed": "output_velocity", "current": "current"},
    # opensourceleg 3.x Logger.track_attributes(actuator, [...]) writes "<actuator>.motor_position" etc. (matched by
    # the name after the last "."); the Logger writes no time of its own: track one named "time"
    "opensourceleg": {"time": "time", "position": "motor_position", "speed": "motor_velocity",
                      "current": "motor_current"},
}
# plausibility bounds of the SI values, to catch a unit slip (mA read as A, ms read as s, degrees read as radians)
MAX_ABS = {"command": 200.0, "current": 200.0, "speed": 5000.0, "torque": 1000.0}
SI = {"command": "A", "current": "A", "speed": "rad/s", "torque": "N m"}
PERIOD_RANGE_S = (1e-5, 0.5)
MIN_ROWS = 200


@dataclass(frozen=True)
class Column:
    """One mapped column: its role, header, unit and where the mapping came from (for messages)."""

    role: str
    header: str
    unit: str
    source: str


@dataclass
class BenchLog:
    """The mapped columns in SI units (None: not in the log), and where they came from."""

    path: Path
    columns: dict[str, Column]
    t: np.ndarray
    current: np.ndarray
    command: np.ndarray | None
    position: np.ndarray | None
    speed: np.ndarray | None
    torque: np.ndarray | None

    def where(self, role: str) -> str:
        """'column HEADER [unit] (source)' for messages."""
        c = self.columns[role]
        return f"column {c.header!r} [{c.unit}] ({c.source})"


def parse_columns(text: str | None) -> dict[str, tuple[str, str | None]]:
    """``role=HEADER[:unit],...`` -> {role: (header, unit or None)}; ValueError names a bad item."""
    out: dict[str, tuple[str, str | None]] = {}
    for item in (text or "").split(","):
        if not item.strip():
            continue
        role, eq, rest = item.partition("=")
        role = role.strip()
        if not eq or role not in ROLES or not rest.strip():
            raise ValueError(f"--columns item {item.strip()!r}: expected ROLE=HEADER[:unit] with ROLE one of "
                             f"{', '.join(ROLES)}")
        header, colon, unit = rest.rpartition(":") if ":" in rest else (rest, "", "")
        unit_s = unit.strip() if colon else None
        if unit_s is not None and unit_s not in UNITS[role]:
            raise ValueError(f"--columns {role}: unit {unit_s!r} unknown: allowed {', '.join(UNITS[role])}")
        out[role] = (header.strip(), unit_s)
    return out


def _match(header: list[str], name: str) -> str | None:
    """The header equal to name, or whose part after the last '.' is name (opensourceleg's prefixes)."""
    if name in header:
        return name
    hits = [h for h in header if h.rsplit(".", 1)[-1] == name]
    return hits[0] if len(hits) == 1 else None


def _mapping(header: list[str], preset: str | None, given: dict[str, tuple[str, str | None]],
             path: Path) -> dict[str, Column]:
    """The columns: the preset's (or the first preset whose required columns the header has), then --columns."""
    if preset is not None and preset not in PRESETS:
        raise ValueError(f"--preset {preset!r} unknown: choose from {', '.join(PRESETS)}")
    # no preset named: the one whose columns the header has most of (the first of equals)
    names = [preset] if preset is not None else [max(PRESETS, key=lambda p: sum(
        _match(header, name) is not None for name in PRESETS[p].values()))]
    cols: dict[str, Column] = {}
    for p in names:
        for role, name in PRESETS[p].items():
            found = _match(header, name)
            if found is not None and role not in given:
                cols[role] = Column(role, found, next(iter(UNITS[role])), f"preset {p}")
    for role, (name, unit) in given.items():
        found = _match(header, name)
        if found is None:
            raise ValueError(f"{path}: column {name!r} (--columns {role}) not in the header: it has "
                             f"{', '.join(header)}")
        cols[role] = Column(role, found, unit or next(iter(UNITS[role])), "--columns")
    missing = [r for r in ("time", "current") if r not in cols]
    if "position" not in cols and "speed" not in cols:
        missing.append("position")
    if missing:
        expected = ", ".join(f"{r} ({PRESETS[names[0]][r]!r} in preset {names[0]})" for r in missing)
        raise ValueError(f"{path}: no column for {expected}; the header has {', '.join(header)}: map it with "
                         "--columns ROLE=HEADER[:unit]")
    return cols


def read_log(path: Path, columns: str | None = None, preset: str | None = None) -> BenchLog:
    """Read and check a CSV bench log; ValueError (one line: the value, its column and row, the allowed range)."""
    given = parse_columns(columns)
    with open(path, newline="", encoding="utf-8") as f:
        reader = csv.reader(f)
        header = [h.strip() for h in next(reader, [])]
        if not header:
            raise ValueError(f"{path}: empty file: a CSV bench log starts with a header row")
        cols = _mapping(header, preset, given, path)
        index = {role: header.index(c.header) for role, c in cols.items()}
        data: dict[str, list[float]] = {role: [] for role in cols}
        for row_no, row in enumerate(reader, start=2):
            if not row or all(not cell.strip() for cell in row):
                continue
            for role, k in index.items():
                cell = row[k].strip() if k < len(row) else ""
                try:
                    v = float(cell)
                except ValueError:
                    v = math.nan
                if not math.isfinite(v):
                    raise ValueError(f"{path} row {row_no}, column {cols[role].header!r} ({role}): {cell!r} is not a "
                                     "finite number")
                data[role].append(v * UNITS[role][cols[role].unit])
    arrays = {role: np.asarray(v, dtype=float) for role, v in data.items()}
    log = BenchLog(path, cols, arrays["time"], arrays["current"], arrays.get("command"), arrays.get("position"),
                   arrays.get("speed"), arrays.get("torque"))
    _check(log)
    return log


def _check(log: BenchLog) -> None:
    """The checks of a read log (rows, time, units) in one line each."""
    n = len(log.t)
    if n < MIN_ROWS:
        raise ValueError(f"{log.path}: {n} data rows: at least {MIN_ROWS} needed")
    dt = np.diff(log.t)
    bad = np.flatnonzero(dt <= 0.0)
    if bad.size:
        k = int(bad[0])
        raise ValueError(f"{log.path} row {k + 3}: time {log.t[k + 1]:.9g} s is not after row {k + 2}'s "
                         f"{log.t[k]:.9g} s "
                         f"({log.where('time')}): time must increase strictly")
    period = float(np.median(dt))
    lo, hi = PERIOD_RANGE_S
    if not lo <= period <= hi:
        raise ValueError(f"{log.path}: median sample period {period:.6g} s from {log.where('time')} outside the "
                         f"allowed range [{lo}, {hi}] s: is the time in another unit (time=HEADER:ms or :us)?")
    for role in ("command", "current", "speed", "torque"):
        v = getattr(log, role)
        if v is not None and float(np.max(np.abs(v))) > MAX_ABS[role]:
            k = int(np.argmax(np.abs(v)))
            raise ValueError(f"{log.path} row {k + 2}: {role} {v[k]:.6g} {SI[role]} from {log.where(role)} outside the "
                             f"allowed range [-{MAX_ABS[role]:g}, {MAX_ABS[role]:g}] {SI[role]}: is the unit right?")
    if log.position is not None and log.speed is not None:
        _check_speed_against_position(log)


def _check_speed_against_position(log: BenchLog) -> None:
    """The speed column against the position's derivative: the slope of one on the other must be about 1."""
    assert log.position is not None and log.speed is not None
    w_pos = np.gradient(log.position, log.t)
    moving = np.abs(w_pos) > 0.1 * float(np.percentile(np.abs(w_pos), 95))
    if moving.sum() < MIN_ROWS // 2:
        return
    ratio = float(np.dot(log.speed[moving], w_pos[moving]) / np.dot(w_pos[moving], w_pos[moving]))
    if not 0.8 <= ratio <= 1.25:
        raise ValueError(f"{log.path}: speed from {log.where('speed')} is {ratio:.4g} x the derivative of the position "
                         f"from {log.where('position')}; allowed range [0.8, 1.25]: one of the two units is wrong "
                         "(57.3: degrees against radians; 9.55: rpm against rad/s)")
