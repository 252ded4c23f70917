"""The hazard table's OVER_TEMPERATURE row (host_tools/studies/fault_heat.py): the hot walk as a campaign point."""

from __future__ import annotations

import pytest

from host_tools.studies.fault_heat import HOT_WALK, SETTLE_S, hot_walk_row, hot_walk_table


def test_the_hot_walk_trips_after_the_winding_crosses_fault_c_and_the_safe_command_follows():
    row = hot_walk_row()
    assert row["detected"] and row["reason"] == "OVER_TEMPERATURE"
    # the trip follows the model's crossing by at most the 0.1 C reporting step plus a reading period's (10 Hz) heat:
    # bounded in temperature, not time (how long 0.1 C takes depends on the walk's heating rate near fault_c)
    assert row["onset_s"] < row["trip_s"]
    assert HOT_WALK["fault_c"] < row["winding_at_trip_c"] < HOT_WALK["fault_c"] + 0.2
    assert row["detect_ms"] == pytest.approx((row["trip_s"] - row["onset_s"]) * 1e3)
    assert row["trip_s"] < row["safe_s"] < row["trip_s"] + 0.005  # zero current on the wire within 5 ms
    # until the trip the hot run is its pair: no unintended motion before the safe command
    assert row["excursion_deg"] < 0.01
    # the released foot walks off: the safe state's own motion is the shared residual (docs/safety.md)
    assert row["settle_excursion_deg"] > 5.0


def test_the_table_row_says_the_figures_and_the_criteria_they_miss():
    table = hot_walk_table().splitlines()
    assert len(table) == 3 and table[0].startswith("| fault | hazard |")
    row = hot_walk_row()
    cells = [c.strip() for c in table[2].strip("|").split("|")]
    assert cells[0] == "`OVER_TEMPERATURE` (heat, no injector)"
    assert cells[4] == f"{row['detect_ms']:.1f}" and cells[5] == f"{row['safe_ms']:.1f}"
    missed = cells[9].split(", ")
    assert ("time_to_safe_ms" in missed) == (row["safe_ms"] > 50.0)
    assert ("impact_dps" in missed) == (row["impact_dps"] > 0.0)


def test_the_row_measures_the_safe_state_over_the_shipped_campaigns_settle_time():
    from host_tools.studies.fault_spec import load_fault_spec
    from profiles import profile_path

    assert SETTLE_S == load_fault_spec(profile_path("faults/default.toml")).settle_s
