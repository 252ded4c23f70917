"""The walking scenario's inputs: the ankle-moment curve (packaged normative, or a user's CSV) and the load."""

from __future__ import annotations

import csv
import io
from importlib import resources
from pathlib import Path

from hal.virtual.plant.walking import WalkingLoad

__all__ = ["MOMENT_COLUMN", "SCENARIOS", "moment_curve", "walking_load"]

SCENARIOS = ("suspended", "walk")
MOMENT_COLUMN = "ankle_moment_nm_per_kg_mean"
NORMATIVE = "firmware/data/ankle_normative.csv"


def moment_curve(path: Path | None = None) -> tuple[list[float], list[float], str]:
    """(percent_gait, ankle moment N m/kg, source) from a CSV shaped like the normative one ('#' lines skipped)."""
    if path is None:
        text, source = resources.files("firmware.data").joinpath("ankle_normative.csv").read_text("utf-8"), NORMATIVE
    else:
        try:
            text, source = Path(path).read_text(encoding="utf-8"), str(path)
        except OSError as e:
            raise ValueError(f"cannot read moment CSV {path}: {e.strerror or e}") from None
    lines = [ln for ln in text.splitlines() if ln.strip() and not ln.lstrip().startswith("#")]
    reader = csv.DictReader(io.StringIO("\n".join(lines)))
    fields = [f.strip() for f in reader.fieldnames or []]
    reader.fieldnames = fields
    for col in ("percent_gait", MOMENT_COLUMN):
        if col not in fields:
            raise ValueError(f"{source}: missing column {col!r} (found columns: {fields})")
    percent, moment = [], []
    for row_no, row in enumerate(reader, start=2):
        try:
            percent.append(float(row["percent_gait"]))
            moment.append(float(row[MOMENT_COLUMN]))
        except (TypeError, ValueError):
            raise ValueError(f"{source}: data row {row_no}: not a number in "
                             f"{[row.get('percent_gait'), row.get(MOMENT_COLUMN)]}") from None
    return percent, moment, source


def walking_load(body_mass_kg: float, stride_s: float, path: Path | None = None) -> WalkingLoad:
    """The ground's moment for body_mass_kg on the stride; ValueError naming a bad value or file."""
    percent, moment, source = moment_curve(path)
    try:
        return WalkingLoad(percent, moment, body_mass_kg, stride_s)
    except ValueError as e:
        raise ValueError(f"{source}: {e}" if "moment curve" in str(e) else str(e)) from None
