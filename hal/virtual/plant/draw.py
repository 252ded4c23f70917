"""A plant drawn from its parameters' documented tolerances: ``draw_plant(params, seed) -> params``.

The tolerances are in ``profiles/plant_tolerances.toml`` (each with its source). The draw is a plain
function of (nominal parameters, seed, tolerances): no global state, the same inputs give the same
plant, so a robustness sweep can call it once per seed. Each parameter is uniform within its
tolerance; the parameters are drawn in the table's order from one ``numpy.random.default_rng(seed)``.
The back-EMF constant follows a drawn torque constant (Ke/Kt kept: they are one machine constant).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, fields, replace
from pathlib import Path

import numpy as np

from hal.virtual.plant.params import PlantParams
from profiles import profile_path, read_toml

__all__ = ["DEFAULT_TOLERANCES", "Tolerance", "draw_plant", "drawn_values", "load_tolerances"]

#: The packaged tolerance table.
DEFAULT_TOLERANCES = profile_path("plant_tolerances.toml")
#: Seeds accepted (numpy takes any non-negative int; the CLI keeps to 32 bits).
SEED_RANGE = (0, 2**32 - 1)


@dataclass(frozen=True)
class Tolerance:
    """Uniform spread of one parameter: ``rel`` (nominal * [1 - rel, 1 + rel]) or an absolute ``lo..hi``."""

    name: str
    rel: float | None = None
    lo: float | None = None
    hi: float | None = None

    def bounds(self, nominal: float) -> tuple[float, float]:
        """The interval the parameter is drawn from."""
        if self.rel is not None:
            return nominal * (1.0 - self.rel), nominal * (1.0 + self.rel)
        assert self.lo is not None and self.hi is not None
        return self.lo, self.hi


def load_tolerances(path: str | Path | None = None) -> tuple[Tolerance, ...]:
    """Read a tolerance table; ValueError names the file, the key and what is wrong."""
    p = Path(path) if path is not None else DEFAULT_TOLERANCES
    doc = read_toml(p, "plant tolerance table")
    known = {f.name for f in fields(PlantParams)}
    out = []
    for name, spec in doc.items():
        if name not in known or not isinstance(spec, dict):
            raise ValueError(f"plant tolerances {p}: [{name}] is not a plant parameter")
        if set(spec) == {"rel"} and _number(spec["rel"]) and 0.0 <= spec["rel"] < 1.0:
            out.append(Tolerance(name, rel=float(spec["rel"])))
        elif (set(spec) == {"range"} and isinstance(spec["range"], list) and len(spec["range"]) == 2
              and all(_number(v) for v in spec["range"]) and spec["range"][0] <= spec["range"][1]):
            out.append(Tolerance(name, lo=float(spec["range"][0]), hi=float(spec["range"][1])))
        else:
            raise ValueError(f"plant tolerances {p}: [{name}] = {spec!r} must be rel = r (0 <= r < 1) or "
                             "range = [lo, hi] (lo <= hi)")
    return tuple(out)


def _number(v: object) -> bool:
    return isinstance(v, (int, float)) and not isinstance(v, bool) and math.isfinite(v)


def draw_plant(params: PlantParams, seed: int, tolerances: tuple[Tolerance, ...] | None = None) -> PlantParams:
    """The plant with every toleranced parameter drawn uniformly within its tolerance (seeded).

    >>> from hal.virtual.plant.params import load_plant_params
    >>> nominal = load_plant_params()
    >>> draw_plant(nominal, 1) == draw_plant(nominal, 1), draw_plant(nominal, 1) == draw_plant(nominal, 2)
    (True, False)
    """
    if isinstance(seed, bool) or not isinstance(seed, int) or not SEED_RANGE[0] <= seed <= SEED_RANGE[1]:
        raise ValueError(f"plant seed {seed!r} out of range: an int in {SEED_RANGE[0]}..{SEED_RANGE[1]}")
    tol = load_tolerances() if tolerances is None else tolerances
    rng = np.random.default_rng(seed)
    drawn = {}
    for t in tol:
        nominal = getattr(params, t.name)
        if nominal is None and t.rel is not None:  # an optional key the profile leaves out: nothing to draw around
            continue
        lo, hi = t.bounds(nominal)
        drawn[t.name] = float(rng.uniform(lo, hi))
    if "kt_nm_per_a" in drawn and "ke_v_s_per_rad" not in drawn:  # one machine constant: Ke follows Kt
        drawn["ke_v_s_per_rad"] = params.ke_v_s_per_rad * drawn["kt_nm_per_a"] / params.kt_nm_per_a
    return replace(params, **drawn)  # PlantParams checks every value and the cross-field rules


def drawn_values(nominal: PlantParams, drawn: PlantParams) -> dict[str, dict[str, float]]:
    """{parameter: {"nominal", "drawn"}} for every parameter that differs (for summary.json)."""
    return {f.name: {"nominal": getattr(nominal, f.name), "drawn": getattr(drawn, f.name)}
            for f in fields(PlantParams) if getattr(nominal, f.name) != getattr(drawn, f.name)}
