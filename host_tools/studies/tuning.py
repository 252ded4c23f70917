"""Automatic gain search on the emulator (`pafp tune`): seeded, constrained differential evolution on Dask.

Each candidate (position kp, ki, kd; velocity kp, ki) runs the full firmware on the virtual bench.
Score = RMS tracking error [deg] + EFFORT_WEIGHT x (RMS current command + RMS change of the current command
per control tick) [A]: the second term penalises effort and chatter (encoder noise amplified by kd).
A candidate is infeasible (score +inf) if its run misses a deadline, latches a fault, sits at the current
limit for more than SATURATION_MAX_FRACTION of the gait (a saturation storm), or leaves the reference by
more than STABLE_MAX_ERROR_DEG (not stable). Search: scipy.optimize.differential_evolution in log space
over BOUNDS, population POPULATION, seeded with numpy.random.default_rng(seed); its initial population is
the starting gains plus POPULATION - 1 log-normal perturbations (SIGMA0 in log space); each generation's
candidates are evaluated through its map-like `workers` on Dask (`_DaskMap`) and ranked by (score, index),
so the result is the same for a seed whatever the number of workers or their completion order.
A stop signal (host_tools/studies/interrupt.py: Interrupted) ends the search where it is: the result holds every
candidate finished so far, its best one, and ``interrupted`` names the signal.
The plant every candidate runs is `TunePlant`: the packaged one, a plant profile (`pafp tune --plant FILE`, e.g.
one `pafp fit` wrote) and/or a draw around it (``--plant-seed``), handed to RunConfig as `pafp run` and the
sweeps' ``[base] plant`` do (RunConfig.bench_setup builds the bench from them).
"""

from __future__ import annotations

import logging
import math
from collections.abc import Callable, Iterable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
from scipy.optimize import differential_evolution

from firmware.config import FirmwareConfig
from firmware.control.pid import PidGains
from host_tools.outdir import naming, write_atomic
from host_tools.reports.report import summarise
from host_tools.runner import RunConfig, run_virtual
from host_tools.studies.interrupt import Interrupted

logger = logging.getLogger(__name__)

__all__ = ["BOUNDS", "Candidate", "Evaluation", "TunePlant", "TuneResult", "check_budget", "evaluate", "gains_of",
           "search", "with_gains", "write_profile"]

#: Searched gains and their bounds (log-uniform space): name -> (low, high).
BOUNDS: dict[str, tuple[float, float]] = {
    "position_kp": (0.3, 60.0), "position_ki": (0.01, 60.0), "position_kd": (1e-4, 0.3),
    "velocity_kp": (0.02, 10.0), "velocity_ki": (0.1, 300.0),
}
EFFORT_WEIGHT = 0.02  # deg per A
SATURATION_MAX_FRACTION = 0.02
SATURATION_LEVEL = 0.98  # of the current limit
STABLE_MAX_ERROR_DEG = 5.0
POPULATION = 8  # differential evolution's population: the budget is spent in generations of this many runs
SIGMA0 = 0.6  # log-normal spread of the initial population around the starting gains
MUTATION = (0.5, 1.0)  # differential_evolution's dithered differential weight
RECOMBINATION = 0.7
MIN_POPULATION = 5  # scipy's differential_evolution refuses fewer
INFEASIBLE_ENERGY = 1e3  # what the optimiser sees for an infeasible candidate (its score is +inf)

Candidate = dict[str, float]


@dataclass(frozen=True)
class Evaluation:
    """The outcome of one candidate's run: tracking, effort, constraint flags and the score."""

    index: int
    gains: Candidate
    rms_error_deg: float
    max_error_deg: float
    rms_current_a: float
    rms_current_step_a: float
    saturation_fraction: float
    deadline_misses: int
    faults: tuple[str, ...]
    score: float
    feasible: bool
    reason: str

    def as_dict(self) -> dict[str, object]:
        """JSON-ready mapping (inf score as None)."""
        d = dict(self.__dict__)
        d["faults"] = list(self.faults)
        d["score"] = self.score if math.isfinite(self.score) else None
        return d


@dataclass(frozen=True)
class TunePlant:
    """The plant the candidates run: a plant profile (None: the packaged one) and a draw around it (None: none)."""

    file: Path | None = None
    seed: int | None = None

    def run_options(self) -> dict[str, Any]:
        """The RunConfig options that select this plant (those of `pafp run --plant FILE --plant-seed N`)."""
        return {"plant_file": self.file, "plant_seed": self.seed}

    def check(self) -> None:
        """ValueError naming the file or the seed when the bench cannot be built from them (before any run)."""
        try:
            RunConfig(**self.run_options()).bench_setup()
        except OSError as e:
            raise ValueError(f"--plant {self.file}: cannot read it ({e.strerror or e})") from None

    def as_dict(self) -> dict[str, object]:
        """For tune.json."""
        return {"file": None if self.file is None else str(self.file), "seed": self.seed}


@dataclass(frozen=True)
class TuneResult:
    """Every evaluation in index order, the starting one (index 0) and the best feasible one (the start if none
    is); ``interrupted``: the signal that ended the search early (its evaluations are those finished by then)."""

    evaluations: list[Evaluation]
    start: Evaluation
    best: Evaluation
    interrupted: str | None = None


def gains_of(cfg: FirmwareConfig) -> Candidate:
    """The searched gains of a firmware configuration."""
    p, v = cfg.position_gains, cfg.velocity_gains
    return {"position_kp": p.kp, "position_ki": p.ki, "position_kd": p.kd, "velocity_kp": v.kp, "velocity_ki": v.ki}


def with_gains(cfg: FirmwareConfig, gains: Candidate) -> FirmwareConfig:
    """The configuration with the searched gains replaced (derivative filters and velocity kd kept)."""
    p, v = cfg.position_gains, cfg.velocity_gains
    return cfg.with_changes(
        position_gains=PidGains(gains["position_kp"], gains["position_ki"], gains["position_kd"], p.derivative_tau_s),
        velocity_gains=PidGains(gains["velocity_kp"], gains["velocity_ki"], v.kd, v.derivative_tau_s))


def evaluate(index: int, base: FirmwareConfig, gains: Candidate, strides: int, seed: int,
             plant: TunePlant = TunePlant()) -> Evaluation:
    """Run one candidate on the virtual bench and score it (module-level, so a process pool can call it)."""
    cfg = with_gains(base, gains)
    r = run_virtual(RunConfig(strides=strides, seed=seed, firmware=cfg, trace_capacity=0, **plant.run_options()))
    s = summarise(r)
    p = r.probe.arrays()
    start = r.gait_start_s if r.gait_start_s is not None else math.inf
    i = p["current_cmd_a"][p["t_s"] >= start]
    if len(i) < 2:
        i = np.zeros(2)
    rms_i = float(np.sqrt(np.mean(i**2)))
    rms_di = float(np.sqrt(np.mean(np.diff(i) ** 2)))
    sat = float(np.mean(np.abs(i) >= SATURATION_LEVEL * cfg.current_limit_a))
    # None: less than one stride in RUN (host_tools.reports.metrics), scored as not stable below
    truth = s["tracking"]["truth"]  # the tuner scores the plant (emulation only)
    rms, mx = (math.nan if truth[k] is None else float(truth[k]) for k in ("rms_deg", "max_deg"))
    reasons = []
    if s["deadline_misses"]:
        reasons.append(f"{s['deadline_misses']} deadline misses")
    if s["faults"]:
        reasons.append("fault " + ",".join(s["faults"]))
    if sat > SATURATION_MAX_FRACTION:
        reasons.append(f"saturation storm ({sat:.1%} of the gait at the current limit)")
    if not math.isfinite(mx) or mx > STABLE_MAX_ERROR_DEG:
        reasons.append(f"not stable (max error {mx:.2f} deg)")
    score = rms + EFFORT_WEIGHT * (rms_i + rms_di) if not reasons else math.inf
    return Evaluation(index, dict(gains), rms, mx, rms_i, rms_di, sat, int(s["deadline_misses"]),
                      tuple(s["faults"]), score, not reasons, "; ".join(reasons))


def _clip(gains: Candidate) -> Candidate:
    return {k: float(min(max(gains[k], lo), hi)) for k, (lo, hi) in BOUNDS.items()}


def _perturb(rng: np.random.Generator, centre: Candidate, sigma: float) -> Candidate:
    """A log-normal step from centre in every searched gain, clipped to BOUNDS."""
    steps = rng.normal(0.0, sigma, len(BOUNDS))
    return _clip({k: max(centre[k], BOUNDS[k][0]) * math.exp(float(s)) for k, s in zip(BOUNDS, steps, strict=True)})


def _rank(e: Evaluation) -> tuple[float, int]:
    return (e.score, e.index)


def _to_x(gains: Candidate) -> np.ndarray:
    return np.log([max(gains[k], BOUNDS[k][0]) for k in BOUNDS])


def _to_gains(x: np.ndarray) -> Candidate:
    """Gains from log space, to 12 significant digits (exp(log(8.0)) is 8.0 again, not 7.999999999999998)."""
    return _clip({k: float(f"{math.exp(float(v)):.12g}") for k, v in zip(BOUNDS, x, strict=True)})


def _energy(x: np.ndarray) -> float:
    """Placeholder objective handed to differential_evolution: _DaskMap evaluates the candidates itself."""
    raise RuntimeError("evaluated by _DaskMap")  # pragma: no cover


class _DaskMap:
    """The map-like `workers` of differential_evolution: each candidate is an `evaluate` run on Dask (or here).

    differential_evolution calls it with its objective wrapper and one generation of points; the points go to
    `evaluate` (the record of every run is kept, not only its score) in submission order, so the result does
    not depend on which worker finished first.
    """

    def __init__(self, client: Any, base: FirmwareConfig, strides: int, seed: int, budget: int,
                 progress: Callable[[int, int], None] | None, plant: TunePlant) -> None:
        self.client, self.base, self.strides, self.seed, self.budget = client, base, strides, seed, budget
        self.plant = plant
        self.progress = progress
        self.evaluations: list[Evaluation] = []
        self.done = 0

    def __call__(self, _func: Callable[[np.ndarray], float], xs: Iterable[np.ndarray]) -> list[float]:
        cands = [_to_gains(np.asarray(x)) for x in xs]
        idx0 = len(self.evaluations)
        results: list[Evaluation] = []
        if self.client is None:
            for k, c in enumerate(cands):
                results.append(evaluate(idx0 + k, self.base, c, self.strides, self.seed, self.plant))
                self.evaluations.append(results[-1])  # kept as it comes: an interrupted search keeps it
                self._step()
        else:
            futures = [self.client.submit(evaluate, idx0 + k, self.base, c, self.strides, self.seed, self.plant,
                                          pure=False) for k, c in enumerate(cands)]
            for fut in futures:  # in index order; progress counts them as they come
                results.append(fut.result())
                self.evaluations.append(results[-1])
                self._step()
        best = min(self.evaluations, key=_rank)
        logger.info("%d evaluations: best score %.4f (candidate %d)", len(self.evaluations), best.score, best.index)
        return [e.score if math.isfinite(e.score) else INFEASIBLE_ENERGY for e in results]

    def _step(self) -> None:
        self.done += 1
        if self.progress:
            self.progress(self.done, self.budget)


def check_budget(budget: int) -> None:
    """ValueError unless `budget` is a number of runs the search can spend."""
    if not isinstance(budget, int) or isinstance(budget, bool) or not MIN_POPULATION <= budget <= 100_000:
        raise ValueError(f"budget {budget!r} out of range: an int in {MIN_POPULATION}..100000 runs "
                         f"(differential evolution's smallest population is {MIN_POPULATION})")


def search(base: FirmwareConfig, *, budget: int, strides: int = 2, seed: int = 0, client: Any = None,
           start: Candidate | None = None, progress: Callable[[int, int], None] | None = None,
           plant: TunePlant = TunePlant()) -> TuneResult:
    """Search the gains with differential evolution within `budget` runs (>= 5); deterministic for a seed.

    `client`: a dask.distributed Client whose workers run each generation's candidates (None: in-process).
    `plant`: the plant every candidate runs (checked before the first run: ValueError naming it).
    """
    check_budget(budget)
    plant.check()
    rng = np.random.default_rng(seed)
    first = dict(start) if start is not None else gains_of(base)
    size = min(POPULATION, budget)
    generations = budget // size  # the initial population and generations - 1 evolved ones
    init = np.array([_to_x(first)] + [_to_x(_perturb(rng, first, SIGMA0)) for _ in range(size - 1)])
    mapper = _DaskMap(client, base, strides, seed, size * generations, progress, plant)
    lo, hi = _to_x({k: b[0] for k, b in BOUNDS.items()}), _to_x({k: b[1] for k, b in BOUNDS.items()})
    interrupted = None
    try:
        differential_evolution(_energy, list(zip(lo, hi, strict=True)), maxiter=generations - 1, popsize=size,
                               init=init, mutation=MUTATION, recombination=RECOMBINATION, rng=rng, polish=False,
                               tol=0.0, atol=0.0, updating="deferred", workers=mapper)
    except Interrupted as stop:
        if not mapper.evaluations:  # not one candidate finished: nothing to keep
            raise
        interrupted = stop.signal
    evaluations = mapper.evaluations
    best = min(evaluations, key=_rank)
    return TuneResult(evaluations, evaluations[0], best if best.feasible else evaluations[0], interrupted)


_TABLES = {"position": ("control", "position"), "velocity": ("control", "velocity")}


def write_profile(source: Path, gains: Candidate, out: Path) -> Path:
    """Copy the TOML profile `source` to `out` with the searched gains replaced (comments and layout kept, tomlkit)."""
    import tomlkit

    doc = tomlkit.parse(source.read_text(encoding="utf-8"))
    missing = []
    for key, value in gains.items():
        loop, gain = key.split("_", 1)
        table: Any = doc
        for name in _TABLES[loop]:
            table = table.get(name) if hasattr(table, "get") else None
        if table is None or gain not in table:
            missing.append(key)
            continue
        table[gain] = float(value)
    if missing:
        raise ValueError(f"profile {source} has no line for {sorted(missing)}: cannot write the tuned gains")
    with naming(out.parent):
        out.parent.mkdir(parents=True, exist_ok=True)
    write_atomic(out, tomlkit.dumps(doc))
    return out
