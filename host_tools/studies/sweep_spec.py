"""The spec of a sweep (`pafp sweep SPEC.toml`): the base run, grid axes, Monte Carlo; checked whole before any run.

A spec is TOML (docs/sweeps.md)::

    [base]
    profile = "../firmware.toml"   # firmware profile, relative to the spec file (default profiles/firmware.toml)
    scenario = "gait"              # the suspended foot tracking the normative gait, as `pafp run`
    controller = "cascade"
    strides = 2
    seed = 0
    timeout_s = 600                # per point

    [[grid]]
    key = "control.position.kp"    # a key of the firmware profile, or run.strides / run.baud / run.seed / ...
    values = [4.0, 8.0, 16.0]      # or linspace = [lo, hi, n] / logspace = [lo, hi, n]

    [monte_carlo]
    samples = 200                  # plant draws (pafp run --plant-seed) per grid point
    seed = 1

Points are the grid's cartesian product (first axis outermost) times the Monte Carlo samples (innermost),
numbered from 0. Every point's seeds come from the spec: the run seed is `[base] seed` (or the `run.seed`
axis), the plant seed of sample k is drawn from `numpy.random.SeedSequence([monte_carlo.seed, k])`, the same
for every grid point (common random numbers: grid points are compared on the same plants).
"""

from __future__ import annotations

import difflib
import hashlib
import itertools
import math
import tomllib
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from firmware.config import DEFAULT_PROFILE

__all__ = ["CONTROLLERS", "MAX_POINTS", "RUN_KEYS", "SCENARIOS", "Axis", "Point", "SpecError", "SweepSpec",
           "load_spec", "plant_seed_of", "profile_keys", "set_profile_key"]

SCENARIOS = ("gait",)  # the only virtual-bench scenario of `pafp run`: suspended foot, normative gait
CONTROLLERS = ("cascade",)  # the firmware's controller (cascaded position PID -> velocity PI)
#: Run parameters an axis or [base] may set: name -> (type, low, high) (None: any value the type allows).
RUN_KEYS: dict[str, tuple[type, float | None, float | None]] = {
    "strides": (int, 1, 100), "baud": (int, 9600, 3_000_000), "seed": (int, 0, 2**32 - 1),
    "board": (str, None, None), "settle_s": (float, 0.0, 10.0),
}
BASE_KEYS = ("profile", "plant", "scenario", "controller", "timeout_s", *RUN_KEYS)
BASE_DEFAULTS: dict[str, Any] = {"strides": 2, "baud": 921600, "seed": 0, "board": "stm32f4", "settle_s": 1.0}
MAX_POINTS = 100_000
MAX_AXIS_VALUES = 10_000
TIMEOUT_RANGE = (0.0, 86_400.0)  # exclusive low


class SpecError(ValueError):
    """A spec that cannot be run: the message is one line naming the value, the key and the allowed range."""


@dataclass(frozen=True)
class Axis:
    """One grid axis: a run key (`run.baud`) or a firmware-profile key (`control.position.kp`) and its values."""

    key: str
    values: tuple[Any, ...]

    @property
    def is_run_key(self) -> bool:
        """True for `run.*` axes (RunConfig fields), False for firmware-profile keys."""
        return self.key.startswith("run.")


@dataclass(frozen=True)
class Point:
    """One run of the sweep: its index, grid values (axis order), Monte Carlo sample and seeds."""

    index: int
    params: tuple[tuple[str, Any], ...]
    sample: int | None
    plant_seed: int | None
    seed: int


@dataclass(frozen=True)
class SweepSpec:
    """A checked sweep spec; `points()` enumerates its runs in their fixed order."""

    path: Path
    profile: Path
    profile_text: str  # shipped with each point: workers on a cluster need no shared disk
    scenario: str
    controller: str
    run: dict[str, Any]  # strides, baud, seed, board, settle_s
    timeout_s: float
    grid: tuple[Axis, ...]
    samples: int  # Monte Carlo samples per grid point (0: none)
    mc_seed: int
    digest: str  # sha256 of the spec text and the profile text: --resume refuses another spec

    @property
    def n_points(self) -> int:
        """Number of points: the grid's product times the samples."""
        return math.prod(len(a.values) for a in self.grid) * max(1, self.samples)

    def points(self) -> list[Point]:
        """Every point in index order."""
        out = []
        combos = itertools.product(*(a.values for a in self.grid)) if self.grid else [()]
        samples: list[int | None] = list(range(self.samples)) if self.samples else [None]
        for combo in combos:
            params = tuple(zip((a.key for a in self.grid), combo, strict=True))
            seed = int(dict(params).get("run.seed", self.run["seed"]))
            for k in samples:
                ps = None if k is None else plant_seed_of(self.mc_seed, k)
                out.append(Point(len(out), params, k, ps, seed))
        return out


def plant_seed_of(mc_seed: int, sample: int) -> int:
    """The plant seed of Monte Carlo sample `sample` (a 32-bit int from SeedSequence([mc_seed, sample]))."""
    return int(np.random.SeedSequence([mc_seed, sample]).generate_state(1)[0])


def profile_keys(doc: dict[str, Any], prefix: str = "") -> list[str]:
    """Every scalar key of a parsed profile as a dotted path (`control.position.kp`)."""
    keys = []
    for k, v in doc.items():
        path = f"{prefix}{k}"
        if isinstance(v, dict):
            keys += profile_keys(v, path + ".")
        else:
            keys.append(path)
    return keys


def set_profile_key(doc: dict[str, Any], key: str, value: Any) -> None:
    """Set the dotted `key` of a parsed profile in place (the key must exist and hold a scalar)."""
    *tables, last = key.split(".")
    node = doc
    for t in tables:
        node = node[t]
    old = node[last]
    node[last] = float(value) if isinstance(old, float) and type(value) is int else value


class _Where:
    """Formats one-line errors that name the spec file."""

    def __init__(self, path: Path) -> None:
        self.path = path

    def __call__(self, msg: str) -> SpecError:
        return SpecError(f"spec {self.path}: {msg}")


def _number(v: Any) -> bool:
    return isinstance(v, (int, float)) and not isinstance(v, bool) and math.isfinite(v)


def _check_run_value(err: _Where, where: str, name: str, value: Any) -> Any:
    typ, lo, hi = RUN_KEYS[name]
    if typ is str:
        if not isinstance(value, str):
            raise err(f"{where} = {value!r} is not a string")
        if name == "board":
            from host_tools.runner import board_profile

            try:
                board_profile(value)
            except ValueError as e:
                raise err(f"{where}: {e}") from None
        return value
    if typ is int and isinstance(value, float) and value.is_integer():  # from linspace / logspace
        value = int(value)
    ok = _number(value) and (typ is float or (isinstance(value, int)))
    if not ok or not (lo is None or lo <= value) or not (hi is None or value <= hi):
        kind = "an int" if typ is int else "a number"
        raise err(f"{where} = {value!r} out of range: {kind} in {lo}..{hi}")
    return float(value) if typ is float else int(value)


def _axis_values(err: _Where, where: str, table: dict[str, Any]) -> tuple[Any, ...]:
    given = [k for k in ("values", "linspace", "logspace") if k in table]
    if len(given) != 1:
        raise err(f"{where} needs exactly one of values = [...], linspace = [lo, hi, n], logspace = [lo, hi, n] "
                  f"(got {given or 'none'})")
    kind = given[0]
    v = table[kind]
    if kind == "values":
        if not isinstance(v, list) or not 1 <= len(v) <= MAX_AXIS_VALUES:
            raise err(f"{where}.values = {v!r} out of range: a list of 1..{MAX_AXIS_VALUES} values")
        if len({repr(x) for x in v}) != len(v):
            raise err(f"{where}.values = {v!r} repeats a value: each value once")
        return tuple(v)
    if (not isinstance(v, list) or len(v) != 3 or not all(_number(x) for x in v[:2]) or not isinstance(v[2], int)
            or isinstance(v[2], bool) or not 2 <= v[2] <= MAX_AXIS_VALUES):
        raise err(f"{where}.{kind} = {v!r} out of range: [lo, hi, n] with numbers lo, hi and an int n in "
                  f"2..{MAX_AXIS_VALUES}")
    lo, hi, n = v
    if kind == "logspace":
        if lo <= 0 or hi <= 0:
            raise err(f"{where}.logspace = {v!r} out of range: lo and hi > 0")
        return tuple(float(f"{x:.12g}") for x in np.geomspace(lo, hi, n))  # 8.0, not 7.999999999999999
    return tuple(float(f"{x:.12g}") for x in np.linspace(lo, hi, n))


def _unknown(err: _Where, where: str, table: dict[str, Any], allowed: tuple[str, ...]) -> None:
    for k in table:
        if k not in allowed:
            raise err(f"{where} has no key {k!r}: allowed {', '.join(allowed)}")


def load_spec(path: str | Path) -> SweepSpec:
    """Read and check a sweep spec; SpecError (one line: the value, the key, the allowed range) if it is wrong."""
    path = Path(path)
    err = _Where(path)
    try:
        text = path.read_text(encoding="utf-8")
    except OSError as e:
        raise SpecError(f"cannot read spec {path}: {e.strerror or e}") from None
    try:
        doc = tomllib.loads(text)
    except tomllib.TOMLDecodeError as e:
        raise err(f"not valid TOML: {e}") from None
    _unknown(err, "the spec", doc, ("base", "grid", "monte_carlo"))
    base = doc.get("base", {})
    if not isinstance(base, dict):
        raise err("base must be a table [base]")
    _unknown(err, "[base]", base, BASE_KEYS)
    scenario = base.get("scenario", SCENARIOS[0])
    if scenario not in SCENARIOS:
        raise err(f"[base] scenario = {scenario!r} unknown: choose one of {list(SCENARIOS)}")
    controller = base.get("controller", CONTROLLERS[0])
    if controller not in CONTROLLERS:
        raise err(f"[base] controller = {controller!r} unknown: choose one of {list(CONTROLLERS)}")
    prof = base.get("profile")
    if prof is not None and not isinstance(prof, str):
        raise err(f"[base] profile = {prof!r} is not a path string")
    profile = (path.parent / prof).resolve() if prof else DEFAULT_PROFILE
    try:
        profile_text = profile.read_text(encoding="utf-8")
        profile_doc = tomllib.loads(profile_text)
    except OSError as e:
        raise err(f"[base] profile = {prof!r}: cannot read {profile}: {e.strerror or e}") from None
    except tomllib.TOMLDecodeError as e:
        raise err(f"[base] profile = {prof!r}: {profile} is not valid TOML: {e}") from None
    run = {k: _check_run_value(err, f"[base] {k}", k, base.get(k, d)) for k, d in BASE_DEFAULTS.items()}
    plant = base.get("plant")
    if plant is not None:  # a plant profile (e.g. `pafp fit`'s) every point runs; Monte Carlo draws around it
        if not isinstance(plant, str):
            raise err(f"[base] plant = {plant!r} is not a path string")
        plant_path = (path.parent / plant).resolve()
        try:
            from hal.virtual.plant import load_plant_params

            load_plant_params(plant_path)
        except OSError as e:
            raise err(f"[base] plant = {plant!r}: cannot read {plant_path}: {e.strerror or e}") from None
        except ValueError as e:
            raise err(f"[base] plant = {plant!r}: {e}") from None
        run["plant_file"] = str(plant_path)
    timeout = base.get("timeout_s", 600.0)
    if not _number(timeout) or not TIMEOUT_RANGE[0] < timeout <= TIMEOUT_RANGE[1]:
        raise err(f"[base] timeout_s = {timeout!r} out of range: a number of seconds in (0, {TIMEOUT_RANGE[1]:g}]")

    grid_tables = doc.get("grid", [])
    if not isinstance(grid_tables, list):
        raise err("grid must be an array of tables [[grid]]")
    known = profile_keys(profile_doc)
    axes: list[Axis] = []
    for i, table in enumerate(grid_tables):
        where = f"[[grid]] #{i + 1}"
        _unknown(err, where, table, ("key", "values", "linspace", "logspace"))
        key = table.get("key")
        if not isinstance(key, str):
            raise err(f"{where} key = {key!r}: a run key (run.{', run.'.join(RUN_KEYS)}) or a profile key")
        where = f"[[grid]] key {key!r}"
        if key in (a.key for a in axes):
            raise err(f"{where} appears twice: one axis per key")
        values = _axis_values(err, where, table)
        if key.startswith("run."):
            name = key.removeprefix("run.")
            if name not in RUN_KEYS:
                raise err(f"{where} is no run key: choose one of run.{', run.'.join(RUN_KEYS)}")
            values = tuple(_check_run_value(err, f"{where} value", name, v) for v in values)
        elif key not in known:
            close = difflib.get_close_matches(key, known, n=3)
            hint = f" (did you mean {', '.join(close)}?)" if close else ""
            raise err(f"{where} is not a key of the profile {profile}{hint}: a dotted path such as "
                      f"control.position.kp, or run.<{'|'.join(RUN_KEYS)}>")
        axes.append(Axis(key, values))

    mc = doc.get("monte_carlo", {})
    if not isinstance(mc, dict):
        raise err("monte_carlo must be a table [monte_carlo]")
    _unknown(err, "[monte_carlo]", mc, ("samples", "seed"))
    samples = mc.get("samples", 0)
    if not isinstance(samples, int) or isinstance(samples, bool) or not (0 <= samples <= MAX_POINTS):
        raise err(f"[monte_carlo] samples = {samples!r} out of range: an int in 0..{MAX_POINTS}")
    mc_seed = mc.get("seed", 0)
    if not isinstance(mc_seed, int) or isinstance(mc_seed, bool) or not 0 <= mc_seed <= 2**63 - 1:
        raise err(f"[monte_carlo] seed = {mc_seed!r} out of range: an int in 0..{2**63 - 1}")
    if "monte_carlo" in doc and samples == 0:
        raise err("[monte_carlo] samples = 0 out of range: an int in 1..100000 (or leave out [monte_carlo])")

    digest = hashlib.sha256(text.encode() + b"\0" + profile_text.encode()).hexdigest()
    spec = SweepSpec(path, profile, profile_text, scenario, controller, run, float(timeout), tuple(axes), samples,
                     mc_seed, digest)
    if spec.n_points > MAX_POINTS:
        raise err(f"{spec.n_points} points out of range: at most {MAX_POINTS} (grid product x samples)")
    return spec
