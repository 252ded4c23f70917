"""telemetry.csv of a run: one row per record, a time column in seconds, floats at the precision they carry.

The columns are those of :data:`~protocol.telemetry.RECORD_COLUMNS` with ``time_s`` after
``time_cycles`` (the cycle count over the board's clock, to the nanosecond). The record's floats travel as
float32, so each is written as the shortest decimal that reads back as the same float32 (``-0.09``, not
``-0.09000000197086964``); the ``*_deg`` columns, computed from them, get the same treatment. Rows are
written a batch at a time from the decoder's value tuples
(:meth:`~protocol.telemetry.TelemetryDecoder.feed_values`), no record objects.

>>> import io
>>> buf = io.StringIO()
>>> w = TelemetryCsv(buf, f_cpu_hz=168_000_000)
>>> w.write([(1, 343650, -0.0015707963611930609, 0.0, 0.0, 0.0, 0.1, 2.5, 0.0, 0.0, 1, 0, 0)])
>>> print(buf.getvalue().splitlines()[1])
1,343650,0.002045536,-0.0015707964,-0.09,0,0,0,0,0,0,0.1,5.729578,2.5,0,0,1,RUN,0,NONE,0
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import TextIO

import numpy as np

from protocol.telemetry import RECORD_COLUMNS, RECORD_SPECS, FaultReason, FieldSpec, SupervisorState

__all__ = ["TelemetryCsv", "float32_digits"]

_ENUMS = {"supervisor_state": SupervisorState, "fault_reason": FaultReason}
_ANGLES = {s.name for s in RECORD_SPECS if "_rad" in s.name and s.name.replace("_rad", "_deg", 1) in RECORD_COLUMNS}


def float32_digits(values: np.ndarray) -> np.ndarray:
    """Significant digits (6 to 9) of the shortest decimal reading back as the same float32, per value.

    ``%.6g`` drops trailing zeros, so 6 covers every value with 6 digits or fewer.

    >>> float32_digits(np.array([0.1, 0.12573022, 1 / 3, 0.0, np.nan], dtype=np.float32)).tolist()
    [6, 8, 8, 6, 6]
    """
    v32 = np.asarray(values, dtype=np.float32)
    digits = np.full(v32.shape, 9, dtype=np.int64)
    plain = ~np.isfinite(v32) | (v32 == 0)
    digits[plain] = 6
    x = v32[~plain].astype(np.float64)
    if len(x):
        exponent = np.floor(np.log10(np.abs(x)))
        best = np.full(x.shape, 9, dtype=np.int64)
        for d in (8, 7, 6):  # fewer digits read back whenever more do not suffice: keep the smallest that does
            scale = 10.0 ** (d - 1 - exponent)
            ok = (np.round(x * scale) / scale).astype(np.float32) == x.astype(np.float32)
            best[ok] = d
        digits[~plain] = best
    return digits


class TelemetryCsv:
    """Writes the header at once, then rows a batch at a time (each batch one write, flushed)."""

    def __init__(self, out: TextIO, f_cpu_hz: int | None, extra_names: Sequence[str] = ()) -> None:
        """Write to out; with f_cpu_hz, a ``time_s`` column follows ``time_cycles``; ``extra_names`` (a
        controller's published values, float32 fields after the base ones) are the last columns."""
        self._out = out
        self._specs = RECORD_SPECS + tuple(FieldSpec(name, "f", 0.0) for name in extra_names)
        self.f_cpu_hz = f_cpu_hz
        self.rows = 0
        self._float_specs = [spec for spec in self._specs if spec.fmt == "f"]
        columns = [*RECORD_COLUMNS, *extra_names]
        if f_cpu_hz is not None:
            columns.insert(columns.index("time_cycles") + 1, "time_s")
        self.columns = tuple(columns)
        cells = []
        for spec in self._specs:
            if spec.name == "time_cycles":
                cells += ["%d"] + (["%.9f"] if f_cpu_hz is not None else [])
            elif spec.fmt == "f":
                cells += ["%.*g", "%.*g"] if spec.name in _ANGLES else ["%.*g"]
            elif spec.name in _ENUMS:
                cells += ["%d", "%s"]
            else:
                cells.append("%d")
        self._row_format = ",".join(cells) + "\n"
        out.write(",".join(self.columns) + "\n")
        out.flush()

    def write(self, rows: Sequence[tuple[int | float, ...]]) -> None:
        """Write records given as value tuples in RECORD_FIELDS order (then the extra values)."""
        if not rows:
            return
        columns = list(zip(*rows, strict=True))
        floats = [np.array(c, dtype=np.float64) for spec, c in zip(self._specs, columns, strict=True)
                  if spec.fmt == "f"]
        series = np.array([v for spec, v in zip(self._float_specs, floats, strict=True)
                           for v in ((v, np.degrees(v)) if spec.name in _ANGLES else (v,))], dtype=np.float32)
        digits = float32_digits(series).tolist()  # every float column in one go
        values = series.astype(np.float64).tolist()
        pairs = iter(zip(digits, values, strict=True))
        cells: list[Sequence[object]] = []
        for spec, column in zip(self._specs, columns, strict=True):
            if spec.name == "time_cycles":
                cells.append(column)
                if self.f_cpu_hz is not None:
                    cells.append([c / self.f_cpu_hz for c in column])
            elif spec.fmt == "f":
                for _ in range(2 if spec.name in _ANGLES else 1):
                    d, v = next(pairs)
                    cells += [d, v]
            elif spec.name in _ENUMS:
                enum = _ENUMS[spec.name]
                names = {m.value: m.name for m in enum}
                cells.append(column)
                cells.append([names.get(c, f"UNKNOWN_{c}") for c in column])
            else:
                cells.append(column)
        fmt = self._row_format
        self._out.write("".join([fmt % row for row in zip(*cells, strict=True)]))
        self._out.flush()
        self.rows += len(rows)
