"""Automatic gain search on the emulator (`pafp tune`): a seeded, parallel, constrained evolutionary search.

Each candidate (position kp, ki, kd; velocity kp, ki) runs the full firmware on the virtual bench.
Score = RMS tracking error [deg] + EFFORT_WEIGHT x (RMS current command + RMS change of the current command
per control tick) [A]: the second term penalises effort and chatter (encoder noise amplified by kd).
A candidate is infeasible (score +inf) if its run misses a deadline, latches a fault, sits at the current
limit for more than SATURATION_MAX_FRACTION of the gait (a saturation storm), or leaves the reference by
more than STABLE_MAX_ERROR_DEG (not stable). Search: generation 0 is the starting gains plus
POPULATION - 1 log-normal perturbations (step SIGMA0 in log space); each later generation perturbs the best
feasible candidate so far with a step shrunk by SIGMA_DECAY. Candidates come from
numpy.random.default_rng(seed), are evaluated in a process pool, and are ranked by (score, index), so the
result is the same for a seed whatever the number of workers or their completion order.
"""

from __future__ import annotations

import logging
import math
import re
from collections.abc import Callable
from concurrent.futures import Future, ProcessPoolExecutor
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from firmware.config import FirmwareConfig
from firmware.control.pid import PidGains
from host_tools.report import summarise
from host_tools.runner import RunConfig, run_virtual

logger = logging.getLogger(__name__)

__all__ = ["BOUNDS", "Candidate", "Evaluation", "TuneResult", "evaluate", "gains_of", "search", "with_gains",
           "write_profile"]

#: Searched gains and their bounds (log-uniform space): name -> (low, high).
BOUNDS: dict[str, tuple[float, float]] = {
    "position_kp": (0.3, 60.0), "position_ki": (0.01, 60.0), "position_kd": (1e-4, 0.3),
    "velocity_kp": (0.02, 10.0), "velocity_ki": (0.1, 300.0),
}
EFFORT_WEIGHT = 0.02  # deg per A
SATURATION_MAX_FRACTION = 0.02
SATURATION_LEVEL = 0.98  # of the current limit
STABLE_MAX_ERROR_DEG = 5.0
POPULATION = 8
SIGMA0 = 0.6
SIGMA_DECAY = 0.7

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
class TuneResult:
    """Every evaluation in index order, the starting one (index 0) and the best feasible one."""

    evaluations: list[Evaluation]
    start: Evaluation
    best: Evaluation


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


def evaluate(index: int, base: FirmwareConfig, gains: Candidate, strides: int, seed: int) -> Evaluation:
    """Run one candidate on the virtual bench and score it (module-level, so a process pool can call it)."""
    cfg = with_gains(base, gains)
    r = run_virtual(RunConfig(strides=strides, seed=seed, firmware=cfg, trace_capacity=0))
    s = summarise(r)
    p = r.probe.arrays()
    start = r.gait_start_s if r.gait_start_s is not None else math.inf
    i = p["current_cmd_a"][p["t_s"] >= start]
    if len(i) < 2:
        i = np.zeros(2)
    rms_i = float(np.sqrt(np.mean(i**2)))
    rms_di = float(np.sqrt(np.mean(np.diff(i) ** 2)))
    sat = float(np.mean(np.abs(i) >= SATURATION_LEVEL * cfg.current_limit_a))
    # None: less than one stride in RUN (host_tools.metrics), scored as not stable below
    rms, mx = (math.nan if s[k] is None else float(s[k]) for k in ("rms_error_deg", "max_error_deg"))
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


def search(base: FirmwareConfig, *, budget: int, strides: int = 2, seed: int = 0, jobs: int = 1,
           start: Candidate | None = None, progress: Callable[[int, int], None] | None = None) -> TuneResult:
    """Search the gains within `budget` runs (>= 2) using `jobs` worker processes; deterministic for a seed."""
    if not isinstance(budget, int) or not 2 <= budget <= 100_000:
        raise ValueError(f"budget {budget!r} out of range: an int in 2..100000 runs")
    if not isinstance(jobs, int) or not 1 <= jobs <= 1024:
        raise ValueError(f"jobs {jobs!r} out of range: an int in 1..1024 worker processes")
    rng = np.random.default_rng(seed)
    first = dict(start) if start is not None else gains_of(base)
    evaluations: list[Evaluation] = []
    done = 0
    pool = ProcessPoolExecutor(max_workers=jobs) if jobs > 1 else None
    try:
        generation = 0
        while len(evaluations) < budget:
            size = min(POPULATION, budget - len(evaluations))
            feasible = [e for e in evaluations if e.feasible]
            centre = min(feasible, key=_rank).gains if feasible else first
            sigma = SIGMA0 * SIGMA_DECAY ** generation
            cands = [_perturb(rng, centre, sigma) for _ in range(size)]
            if generation == 0:
                cands[0] = first
            idx0 = len(evaluations)
            results: list[Evaluation | None] = [None] * size
            if pool is None:
                for k, c in enumerate(cands):
                    results[k] = evaluate(idx0 + k, base, c, strides, seed)
                    done += 1
                    if progress:
                        progress(done, budget)
            else:
                futures: list[Future[Evaluation]] = [pool.submit(evaluate, idx0 + k, base, c, strides, seed)
                                                     for k, c in enumerate(cands)]
                for k, fut in enumerate(futures):  # collect in index order; progress counts completions
                    results[k] = fut.result()
                    done += 1
                    if progress:
                        progress(done, budget)
            evaluations += [e for e in results if e is not None]
            best = min(evaluations, key=_rank)
            logger.info("generation %d (sigma %.3f): best score %.4f (candidate %d)", generation, sigma,
                        best.score, best.index)
            generation += 1
    finally:
        if pool is not None:
            pool.shutdown()
    best = min(evaluations, key=_rank)
    return TuneResult(evaluations, evaluations[0], best if best.feasible else evaluations[0])


_TABLES = {"control.position": "position", "control.velocity": "velocity"}
_LINE = re.compile(r"^(\s*)(kp|ki|kd)(\s*=\s*)([^#\n]*?)(\s*(#.*)?)$")


def write_profile(source: Path, gains: Candidate, out: Path) -> Path:
    """Copy the TOML profile `source` to `out` with the searched gains replaced (comments kept)."""
    lines = source.read_text(encoding="utf-8").splitlines(keepends=True)
    table = ""
    seen: set[str] = set()
    out_lines = []
    for line in lines:
        head = re.match(r"^\s*\[([^\]]+)\]", line)
        if head:
            table = head.group(1).strip()
        m = _LINE.match(line.rstrip("\n"))
        if m and table in _TABLES:
            key = f"{_TABLES[table]}_{m.group(2)}"
            if key in gains:
                line = f"{m.group(1)}{m.group(2)}{m.group(3)}{gains[key]!r}{m.group(5)}\n"
                seen.add(key)
        out_lines.append(line)
    missing = sorted(set(gains) - seen)
    if missing:
        raise ValueError(f"profile {source} has no line for {missing}: cannot write the tuned gains")
    out.parent.mkdir(parents=True, exist_ok=True)
    out.write_text("".join(out_lines), encoding="utf-8")
    return out
