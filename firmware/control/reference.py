"""Position references: the periodic normative gait curve and the minimum-jerk point-to-point move.

The gait curve is a periodic C2 cubic spline fitted with numpy at construction (firmware/control/spline.py);
the per-sample path
evaluates the spline's piecewise-polynomial coefficients (bisect + Horner, exact at any t) in a compiled
:class:`~firmware.control.curve.PeriodicCubic`. See docs/control.md for the closure of the
(non-periodic) published curve.
"""

from __future__ import annotations

import csv
import io
import logging
import math
from collections.abc import Mapping, Sequence
from importlib import resources
from pathlib import Path
from typing import Protocol

from firmware.control.curve import PeriodicCubic
from firmware.control.validation import check_range, is_number

logger = logging.getLogger(__name__)

#: Default range-of-motion clamp in degrees (plantarflexion limit, dorsiflexion limit).
DEFAULT_ROM_DEG: tuple[float, float] = (-25.0, 20.0)
#: Allowed stride times, seconds.
STRIDE_RANGE_S: tuple[float, float] = (0.2, 10.0)
#: Column names of a gait CSV (the first two are required).
PERCENT_COLUMN = "percent_gait"
MEAN_COLUMN = "ankle_angle_deg_mean"
SD_COLUMN = "ankle_angle_deg_sd"
MIN_ROWS = 4


class Trajectory(Protocol):
    """Anything that gives the reference (angle_rad, velocity_rad_s, accel_rad_s2) at time t_s."""

    def sample(self, t_s: float) -> tuple[float, float, float]:
        """Return (angle_rad, velocity_rad_s, accel_rad_s2) at t_s."""
        ...


class _Sampled:
    """Single-quantity accessors shared by the trajectories (use sample() when more than one is needed)."""

    __slots__ = ()

    def sample(self, t_s: float) -> tuple[float, float, float]:  # pragma: no cover - overridden
        """Return (angle_rad, velocity_rad_s, accel_rad_s2) at t_s."""
        raise NotImplementedError

    def angle_rad(self, t_s: float) -> float:
        """Reference angle at t_s."""
        return self.sample(t_s)[0]

    def velocity_rad_s(self, t_s: float) -> float:
        """Reference angular velocity at t_s."""
        return self.sample(t_s)[1]

    def accel_rad_s2(self, t_s: float) -> float:
        """Reference angular acceleration at t_s."""
        return self.sample(t_s)[2]


def _read_gait_csv(text: str, source: str, select: Mapping[str, str] | None
                   ) -> tuple[list[float], list[float], list[float] | None]:
    """Parse gait CSV text ('#' lines skipped) into percent, mean and optional SD columns."""
    lines = [ln for ln in text.splitlines() if ln.strip() and not ln.lstrip().startswith("#")]
    reader = csv.DictReader(io.StringIO("\n".join(lines)))
    fields = [f.strip() for f in (reader.fieldnames or [])]
    reader.fieldnames = fields
    for col in (PERCENT_COLUMN, MEAN_COLUMN, *(select or {})):
        if col not in fields:
            raise ValueError(f"{source}: missing column {col!r} (found columns: {fields})")
    has_sd = SD_COLUMN in fields
    percent: list[float] = []
    mean: list[float] = []
    sd: list[float] = []
    for row_no, row in enumerate(reader, start=2):
        if select and any((row.get(k) or "").strip() != v for k, v in select.items()):
            continue
        cols = (PERCENT_COLUMN, MEAN_COLUMN, SD_COLUMN) if has_sd else (PERCENT_COLUMN, MEAN_COLUMN)
        try:
            values = [float((row.get(c) or "").strip()) for c in cols]
        except ValueError:
            bad = [row.get(c) for c in cols]
            raise ValueError(f"{source}: data row {row_no}: not a number in {bad}") from None
        percent.append(values[0])
        mean.append(values[1])
        if has_sd:
            sd.append(values[2])
    return percent, mean, (sd if has_sd else None)


class GaitReference(_Sampled):
    """Periodic ankle-angle reference from a gait curve (percent of cycle, degrees, dorsiflexion positive).

    The published curve's end mismatch d = y(100 %) - y(0 %) is removed by a linear ramp,
    y_c(p) = y(p) - d p / 100, then a periodic cubic spline (C2) is fitted in time t = p/100 * stride_s.

    >>> ref = GaitReference.normative(stride_s=1.1)
    >>> round(ref.closure_offset_deg, 4)
    -0.2207
    >>> round(math.degrees(ref.sample(0.0)[0]), 4)
    -2.0993
    """

    def __init__(self, percent_gait: Sequence[float], angle_deg: Sequence[float],
                 sd_deg: Sequence[float] | None = None, stride_s: float = 1.1,
                 rom_deg: tuple[float, float] = DEFAULT_ROM_DEG, source: str = "<arrays>") -> None:
        """Validate the curve, close it, fit the periodic spline and tabulate its coefficients."""
        import numpy as np

        from firmware.control.spline import evaluate, periodic_cubic_coefficients

        check_range("stride_s", stride_s, *STRIDE_RANGE_S, unit="s")
        if not (len(rom_deg) == 2 and all(is_number(v) for v in rom_deg)
                and -90.0 <= rom_deg[0] < rom_deg[1] <= 90.0):
            raise ValueError(f"rom_deg = {rom_deg!r} is not allowed: must be (low, high) with "
                             "-90 <= low < high <= 90 degrees")
        p = [float(v) for v in percent_gait]
        y = [float(v) for v in angle_deg]
        if len(p) != len(y):
            raise ValueError(f"{source}: percent_gait has {len(p)} values but angle_deg has {len(y)}")
        if len(p) < MIN_ROWS:
            raise ValueError(f"{source}: only {len(p)} rows; at least {MIN_ROWS} are needed")
        if not all(math.isfinite(v) for v in p + y):
            raise ValueError(f"{source}: percent_gait and angle values must be finite numbers")
        for k in range(1, len(p)):
            if not p[k] > p[k - 1]:
                raise ValueError(f"{source}: percent_gait is not strictly increasing at row {k + 1} "
                                 f"({p[k - 1]!r} then {p[k]!r})")
        if p[0] != 0.0 or p[-1] > 100.0:
            raise ValueError(f"{source}: percent_gait must start at 0 and end at or below 100 "
                             f"(got {p[0]!r} ... {p[-1]!r})")
        if sd_deg is not None:
            sd = [float(v) for v in sd_deg]
            if len(sd) != len(p) or not all(math.isfinite(v) and v >= 0.0 for v in sd):
                raise ValueError(f"{source}: ankle_angle_deg_sd must hold {len(p)} finite values >= 0")
        self.source = source
        self.stride_s = float(stride_s)
        self.rom_deg = (float(rom_deg[0]), float(rom_deg[1]))
        self.data_percent = tuple(p)
        self.data_angle_deg = tuple(y)
        if p[-1] == 100.0:
            self.closure_offset_deg = y[-1] - y[0]
            yc = [y[k] - self.closure_offset_deg * p[k] / 100.0 for k in range(len(p))]
            yc[-1] = yc[0]
            pc = p
        else:  # the curve stops short of 100 %: the last segment wraps to the first point
            self.closure_offset_deg = 0.0
            yc = y + [y[0]]
            pc = p + [100.0]
        self._sd_percent = pc
        self._sd = None if sd_deg is None else (sd + [sd[0]] if len(pc) > len(p) else sd)
        x = np.asarray(pc) / 100.0 * self.stride_s
        c = periodic_cubic_coefficients(x, np.radians(yc))
        self._knots, self._coefficients = x, c
        lo_rad, hi_rad = math.radians(self.rom_deg[0]), math.radians(self.rom_deg[1])
        #: the spline's pieces, sampled by sample() and directly by the firmware's control task
        self.curve = PeriodicCubic(
            [float(v) for v in x[:-1]],
            [(float(c[0, i]), float(c[1, i]), float(c[2, i]), float(c[3, i])) for i in range(c.shape[1])],
            self.stride_s, lo_rad, hi_rad)
        dense = evaluate(x, c, np.linspace(0.0, self.stride_s, 2001))
        self.clamped_fraction = float(np.mean((dense < lo_rad) | (dense > hi_rad)))
        if self.clamped_fraction > 0.0:
            logger.warning("%s: %.1f %% of the gait curve lies outside the range of motion %s deg "
                           "and is clamped", source, 100.0 * self.clamped_fraction, self.rom_deg)

    @classmethod
    def from_csv(cls, path: str | Path, stride_s: float = 1.1, rom_deg: tuple[float, float] = DEFAULT_ROM_DEG,
                 select: Mapping[str, str] | None = None) -> GaitReference:
        """Load a CSV with percent_gait, ankle_angle_deg_mean [, ankle_angle_deg_sd]; select filters rows.

        select, e.g. {"speed_category": "Slow"}, keeps only rows whose named columns equal the values
        (for long-format files holding several groups).
        """
        try:
            text = Path(path).read_text(encoding="utf-8")
        except UnicodeDecodeError as e:
            raise ValueError(f"gait reference {path} is not a text CSV file (byte {e.start} is not UTF-8)") from None
        percent, mean, sd = _read_gait_csv(text, str(path), select)
        return cls(percent, mean, sd, stride_s=stride_s, rom_deg=rom_deg, source=str(path))

    @classmethod
    def normative(cls, stride_s: float = 1.1,
                  rom_deg: tuple[float, float] = DEFAULT_ROM_DEG) -> GaitReference:
        """The packaged normative curve (Schwartz et al. 2008, free speed; see firmware/data/README.md)."""
        text = resources.files("firmware.data").joinpath("ankle_normative.csv").read_text(encoding="utf-8")
        name = "firmware/data/ankle_normative.csv"
        percent, mean, sd = _read_gait_csv(text, name, None)
        return cls(percent, mean, sd, stride_s=stride_s, rom_deg=rom_deg, source=name)

    def sample(self, t_s: float) -> tuple[float, float, float]:
        """Return (angle_rad, velocity_rad_s, accel_rad_s2) at t_s >= 0, clamped to the range of motion."""
        return self.curve.sample(t_s)

    @property
    def clamp_count(self) -> int:
        """Samples clamped to the range of motion so far."""
        return self.curve.clamp_count

    def percent_at(self, t_s: float) -> float:
        """Gait-cycle phase in percent [0, 100) at time t_s."""
        return 100.0 * (t_s % self.stride_s) / self.stride_s

    def band_deg(self, percent: float) -> tuple[float, float]:
        """(mean, sd) in degrees at percent of the cycle (wrapped into [0, 100)); sd nan without SD column."""
        import numpy as np

        if not math.isfinite(percent):
            raise ValueError(f"percent = {percent!r} is not allowed: must be a finite number")
        ph = percent % 100.0
        from firmware.control.spline import evaluate

        mean = math.degrees(float(evaluate(self._knots, self._coefficients, ph / 100.0 * self.stride_s)))
        if self._sd is None:
            return mean, math.nan
        return mean, float(np.interp(ph, self._sd_percent, self._sd))


class MinimumJerk(_Sampled):
    """Minimum-jerk move (Flash & Hogan 1985): theta = theta0 + D (10 s^3 - 15 s^4 + 6 s^5), s = (t - t0)/T.

    Holds theta0 before start_time_s and theta_f after start_time_s + duration_s.

    >>> mj = MinimumJerk(0.0, 1.0, duration_s=2.0)
    >>> mj.sample(1.0)
    (0.5, 0.9375, 0.0)
    """

    __slots__ = ("start_angle_rad", "end_angle_rad", "duration_s", "start_time_s", "_d", "_v", "_a")

    def __init__(self, start_angle_rad: float, end_angle_rad: float, duration_s: float,
                 start_time_s: float = 0.0) -> None:
        """Move from start_angle_rad to end_angle_rad in duration_s, starting at start_time_s."""
        for name, v in (("start_angle_rad", start_angle_rad), ("end_angle_rad", end_angle_rad),
                        ("start_time_s", start_time_s)):
            check_range(name, v, -math.inf, math.inf)
        check_range("duration_s", duration_s, 0.0, 3600.0, lo_open=True, unit="s")
        self.start_angle_rad = float(start_angle_rad)
        self.end_angle_rad = float(end_angle_rad)
        self.duration_s = float(duration_s)
        self.start_time_s = float(start_time_s)
        self._d = self.end_angle_rad - self.start_angle_rad
        self._v = self._d / self.duration_s
        self._a = self._v / self.duration_s

    def sample(self, t_s: float) -> tuple[float, float, float]:
        """Return (angle_rad, velocity_rad_s, accel_rad_s2) at t_s."""
        s = (t_s - self.start_time_s) / self.duration_s
        if s <= 0.0:
            return self.start_angle_rad, 0.0, 0.0
        if s >= 1.0:
            return self.end_angle_rad, 0.0, 0.0
        s2 = s * s
        angle = self.start_angle_rad + self._d * s2 * s * (10.0 + s * (-15.0 + 6.0 * s))
        vel = self._v * s2 * (30.0 + s * (-60.0 + 30.0 * s))
        acc = self._a * s * (60.0 + s * (-180.0 + 120.0 * s))
        return angle, vel, acc

