"""The report's figures under each reading of the report (`pafp bench readings-table`, docs/bench.md "Readings").

Per report figure: its value and section, the emulated value under each reading, the row's basis, and which
reading reproduces it by a stated test. Geometry rows run the plant-level bench tests under both geometries
(default lengths, seed 0); IMU rows put one stride of the normative reference through each IMU reading (no
plant: what the model alone costs a perfect tracker). docs/bench.md carries this table verbatim and
tests/test_benchtests.py checks that it does.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from firmware.control.reference import GaitReference
from hal.virtual.plant import load_plant_params
from hal.virtual.plant.readings import GEOMETRIES, IMUS, with_geometry
from host_tools.benchtests.output import BenchResult

__all__ = ["GEOMETRY_ROWS", "Row", "imu_rows", "readings_table"]


@dataclass(frozen=True)
class Row:
    """One report figure: where it is in the bench tests and the test that says a value reproduces it."""

    test: str
    figure: str
    report: str
    rule: str
    reproduces: Callable[[float], bool]
    unit: str = ""


GEOMETRY_ROWS: tuple[Row, ...] = (
    Row("uncontrolled", "time from pi/5 to the plantarflexion stop", "falls to late stance within 0.5 s (3.6.1)",
        "reaches -30 deg in < 0.5 s", lambda v: v < 0.5, "s"),
    Row("fast-response", "unpowered: rise time 10-90 %", "rise time under 1 s, motor off (4.2.2, 3.8.2)",
        "< 1 s", lambda v: v < 1.0, "s"),
    Row("fast-response", "unpowered: rebounds above 2% of peak", "\"lack of oscillation\" (4.2.2)", "0 rebounds",
        lambda v: v == 0, ""),
    Row("fast-response", "unpowered: angle at the end", "\"stabilizes near the reference angle of 0 degrees\" (4.2.2)",
        "within 5 deg of 0", lambda v: abs(v) < 5.0, "deg"),
    Row("backdrive", "mean peak tau_b, dorsiflexion, report read as N*m", "2.06 \"Nmm\" (4.2.1) read as N*m",
        "within x3 of 2.06 N*m", lambda v: 2.06 / 3 < v < 2.06 * 3, "N*m"),
    Row("backdrive", "mean peak tau_b, dorsiflexion, report's J_total (no planetary)",
        "2.06 Nmm (4.2.1) with its J_total (3.8.1)", "within x10 of 0.00206 N*m",
        lambda v: 0.00206 / 10 < v < 0.00206 * 10, "N*m"),
    Row("loading", "q-axis (phase) current range, 1.48 kg", "measured -0.2..0.7 A (4.2.3)", "max within x2 of 0.7 A",
        lambda v: 0.35 < v < 1.4, "A"),
    Row("loading", "q-axis current range with the tables' spring, 1.48 kg", "measured -0.2..0.7 A (4.2.3)",
        "max within x2 of 0.7 A", lambda v: 0.35 < v < 1.4, "A"),
    Row("loading", "q-axis current minimum with the tables' spring, 1.48 kg", "measured -0.2..0.7 A (4.2.3)",
        "below 0: changes sign", lambda v: v < 0, "A"),
    Row("loading", "peak motor torque at the ankle, 1.48 kg", "peak torque 10 N*m (4.2.3)", "within 20 %",
        lambda v: 8.0 < v < 12.0, "N*m"),
    Row("loading", "mean per-period peak electrical power, 1.48 kg", "0.39 W (4.2.3)", "within x2",
        lambda v: 0.195 < v < 0.78, "W"),
    Row("open-loop", "eq 3.67 as written: largest real part of its poles", "unstable (3.6.1, Fig 3.13)",
        "a pole with Re > 0", lambda v: v > 0, "1/s"),
    Row("open-loop", "bench loop ({g}): gate impulse (PID +1 for 1 ms), 2 % settling time",
        "\"optimal sampling time is 0.9 sec\" (3.6.2)", "within 0.5..1.8 s", lambda v: 0.5 < v < 1.8, "s"),
)


def _fmt(v: float | None, unit: str) -> str:
    """A value with its unit, 3 significant digits, or a dash."""
    if v is None or not math.isfinite(v):
        return "—"
    return f"{v:.3g} {unit}".strip()


def imu_rows(stride_s: float = 1.1, dt_s: float = 0.002) -> list[str]:
    """Table lines for the IMU reading: the normative reference through each IMU model, one stride."""
    from host_tools.benchtests.tracking import imu_model_error

    ref = GaitReference.normative(stride_s=stride_s)
    t = np.arange(int(round(3 * stride_s / dt_s))) * dt_s
    angle = np.degrees([ref.sample(float(x))[0] for x in t])
    keep = t >= stride_s  # the second and third strides: the lag's start-up transient gone
    err = {r: imu_model_error(angle[keep], t[keep], r) for r in IMUS}
    return [f"| imu | tracking on the IMU, error of the model alone (RMS) | plot only (Figs 4.8–4.10); 0.0195 s "
            f"(3.5.4) | {_fmt(err['first-order-lag']['rms_deg'], '°')} | {_fmt(err['sample-hold']['rms_deg'], '°')} "
            "| predicted | — (plot only): the reading sets most of the IMU-measured error |"]


def readings_table(run: Callable[[str, str], BenchResult]) -> str:
    """The Markdown table; run(test, geometry) gives a bench result (pafp bench's runner)."""
    cache: dict[tuple[str, str], BenchResult] = {}
    lines = ["| reading | figure | report (section) | level-com | hanging | basis | reproduced by (test) |",
             "|---|---|---|---|---|---|---|"]
    for row in GEOMETRY_ROWS:
        values: dict[str, float | None] = {}
        basis = ""
        for g in GEOMETRIES:
            key = (row.test, g)
            if key not in cache:
                cache[key] = run(row.test, g)
            name = row.figure.format(g=g)
            fig = next((f for f in cache[key].figures if f.name == name), None)
            values[g] = None if fig is None else fig.emulated_value
            basis = basis or (fig.basis.split(":", 1)[0] if fig is not None else "")
        ok = [g for g, v in values.items() if v is not None and math.isfinite(v) and row.reproduces(v)]
        verdict = " and ".join(ok) if ok else "neither"
        lines.append(f"| geometry | {row.test}: {row.figure.format(g='…')} | {row.report} | "
                     f"{_fmt(values['level-com'], row.unit)} | {_fmt(values['hanging'], row.unit)} | {basis} | "
                     f"{verdict} ({row.rule}) |")
    lines.append("")
    lines.append("| reading | figure | report (section) | first-order-lag | sample-hold | basis "
                 "| reproduced by (test) |")
    lines.append("|---|---|---|---|---|---|---|")
    lines += imu_rows()
    return "\n".join(lines) + "\n"


def default_runner(test: str, geometry: str) -> BenchResult:
    """Run one bench test under a geometry with the profile's other values (seed 0, default lengths)."""

    from host_tools.benchtests import TESTS

    module = TESTS.load(test)
    return module.run(seed=0, quick=False, params=with_geometry(load_plant_params(), geometry))
