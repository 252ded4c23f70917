"""The shipped design search, profiles/designs/adult.toml, on 2 worker processes (--benchmark-only): its wall time
and its answer.

Issue 23's goal: the whole search in under 20 minutes on this 2-core machine with 2 workers (now 12 walking runs
of 6 strides on adult-shaped gait data). Reports the spec's check (every design's profile built), the cluster's
start-up, the total, the time per point and the median point's own time, and checks that every point gave figures
(ok or a fault, none an error). Issue 38: no point walks 80 kg by every criterion of the spec (docs/design.md
says so), and the shipped adult design (profiles/designs/adult_80kg.toml), the closest, is a point that walks 80 kg
at free and at fast speed by every criterion but its belt's rating (the steady winding with the pessimistic housing
resistance 20 C below the derating start), its belt over the rating; design.md and results.csv are kept in
runs/bench/design-adult/, and docs/design.md's table of the search must be the one these rows give.
"""

from __future__ import annotations

import dataclasses
import shutil
import statistics
import time
from pathlib import Path

import pyarrow.parquet as pq

from hal.virtual.plant.design import load_design
from host_tools.commands.design import _write_profiles, columns
from host_tools.studies.design_docs import block
from host_tools.studies.design_point import design_error_row, run_design_point
from host_tools.studies.design_report import docs_search_table, walks, write_design_report
from host_tools.studies.design_spec import load_design_spec
from host_tools.studies.sweep_engine import dask_client, run_tasks

ADULT = Path(__file__).resolve().parents[2] / "profiles" / "designs" / "adult.toml"
GOAL_S = 20 * 60


def test_bench_adult_design_search(benchmark, tmp_path: Path):
    result: dict = {}

    def run() -> None:
        t0 = time.perf_counter()
        spec = load_design_spec(ADULT)
        points = spec.points(tmp_path / "out")
        _write_profiles(points, tmp_path / "out")
        result["spec_check_s"] = time.perf_counter() - t0
        with dask_client(workers=2) as client:
            result["cluster_start_s"] = time.perf_counter() - t0 - result["spec_check_s"]
            outcome = run_tasks(points, run_design_point, tmp_path / "out", client, columns=columns(),
                                digest=spec.digest, error_row=design_error_row, progress=False,
                                ok=lambda row: row["status"] in ("ok", "fault"))
        result["search_s"] = outcome.wall_time_s
        result["total_s"] = time.perf_counter() - t0
        write_design_report(spec, points, outcome.rows, tmp_path / "out", outcome.wall_time_s, "2 workers (bench)")

    benchmark.pedantic(run, rounds=1, iterations=1)
    rows = pq.read_table(tmp_path / "out" / "results.parquet").to_pylist()
    info = benchmark.extra_info
    info.update({k: round(v, 2) for k, v in result.items()})
    info["points"] = len(rows)
    info["per_point_s"] = round(result["search_s"] / len(rows), 3)
    info["point_median_s"] = round(statistics.median(r["wall_time_s"] for r in rows), 3)
    info["status"] = {s: sum(r["status"] == s for r in rows) for s in sorted({r["status"] for r in rows})}
    assert len(rows) == 12
    assert all(r["status"] in ("ok", "fault") for r in rows), [r["error"] for r in rows if r["error"]][:3]
    kept = Path("runs/bench/design-adult")
    kept.mkdir(parents=True, exist_ok=True)
    for name in ("design.md", "docs_table.md"):
        if (tmp_path / "out" / name).is_file():
            shutil.copyfile(tmp_path / "out" / name, kept / name)
    design = load_design(ADULT.parent / "adult_80kg.toml")
    assert design is not None and design.spring is not None
    spec = load_design_spec(ADULT)
    mine = [r for r in rows if (r["motor"], r["driver_teeth"], r["driven_teeth"], r["pitch_mm"]) == (
        design.motor, design.belt_driver_teeth, design.belt_driven_teeth, design.belt_pitch_mm)
        and r["spring"].startswith(f"{design.spring.stiffness_nm_per_rad:g} N")]
    assert sorted(r["speed"] for r in mine) == ["fast", "free"]
    assert not any(walks(r, spec.criteria) for r in rows), [r["point"] for r in rows if walks(r, spec.criteria)]
    but_the_belt = dataclasses.replace(spec.criteria, belt_within_rating=False)
    assert all(walks(r, but_the_belt) and r["belt_tension_n"] > r["belt_rated_n"] for r in mine), mine
    info["adult_80kg"] = {r["speed"]: {k: r[k] for k in ("moment_share", "tracking_rms_deg", "belt_tension_n",
                                                          "belt_rated_n", "steady_state_pessimistic_c")} for r in mine}
    assert block("design_search") == docs_search_table(spec, rows), (
        "docs/design.md's design_search table is stale: python -m host_tools.studies.design_docs search "
        "runs/bench/design-adult")
    assert result["total_s"] < GOAL_S
