"""Baud study: the report's "communication delay" limitation quantified on the full firmware run.

Protocol (docs/bench.md): for each motor-link baud rate and feedback mode, the firmware runs on the
virtual bench at each candidate control rate, fastest first; the achievable rate is the first one whose
run has no deadline miss, no latched fault, no TX refusal, and a reply to every feedback request before
the next one is due (no missing or stale reply). Modes:

- selective: GET_VALUES_SELECTIVE every period (23-byte reply), a full GET_VALUES at the profile's
  full_values_hz (the period after a full request sends no request: its 78-byte reply may take two);
- full: every request a full GET_VALUES (full_values_hz = control_hz), hence one every other period.

The analytic bound is wire time only (10 bit-times per byte, PROTOCOLS.md F): a selective period must
carry command + request + reply, and a full request's round trip must fit two periods.
"""

from __future__ import annotations

import logging
import math
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from firmware.config import FirmwareConfig, load_firmware_config
from firmware.drivers.motor import FEEDBACK_MASK, selective_reply_bytes
from hal.virtual.plant import PlantParams
from host_tools.benchtests.output import BenchResult, Figure
from host_tools.reports.report import summarise
from host_tools.runner import RunConfig, RunResult, run_virtual
from protocol.vesc import GetValues, GetValuesSelective, SetCurrent

#: The readings of the report this test runs under (hal.virtual.plant.readings); the geometry is the bench's.
READINGS = {"driver": "current-lag", "imu": "first-order-lag"}
logger = logging.getLogger(__name__)

__all__ = ["BAUDS", "CANDIDATE_HZ", "MODES", "StudyRun", "analytic_max_hz", "link_config", "run", "study_run"]

BAUDS: tuple[int, ...] = (115200, 230400, 460800, 921600)
CANDIDATE_HZ: tuple[int, ...] = (1000, 500, 400, 250, 200, 100)
MODES: tuple[str, ...] = ("selective", "full")
FULL_REPLY_BYTES = 78  # CubeMars GET_VALUES reply on the wire (PROTOCOLS.md F)
VELOCITY_CUTOFF_FRACTION = 0.4  # of the control rate: the encoder's velocity filter must stay below Nyquist
REPORT_TEXT = "limitation named, no figure"
#: Nothing here is fitted to the report (it names the UART delay as a limitation, 4.3, without a figure).
BASIS = "predicted"


def _wire_bytes() -> dict[str, int]:
    """Bytes on the wire per exchange: command, the two requests and the two replies."""
    return {"command": len(SetCurrent(0.0).encode()),
            "selective_request": len(GetValuesSelective(FEEDBACK_MASK).encode()),
            "full_request": len(GetValues().encode()), "selective_reply": selective_reply_bytes(FEEDBACK_MASK),
            "full_reply": FULL_REPLY_BYTES}


def analytic_max_hz(baud: int, mode: str, full_values_hz: int = 10) -> tuple[float, float]:
    """Wire-time bound (control rate, feedback rate) in Hz for a mode at a baud (10 bits per byte).

    Selective: each period carries command + request + 23-byte reply, and each full request's round
    trip must fit two periods; one period per full request carries no request. Full: a full round trip
    every two periods.

    >>> [round(x) for x in analytic_max_hz(921600, "full")]
    [1961, 980]
    """
    if mode not in MODES:
        raise ValueError(f"mode {mode!r} not allowed: one of {MODES}")
    b = _wire_bytes()
    byte_s = 10.0 / baud
    full_hz = 2.0 / ((b["command"] + b["full_request"] + b["full_reply"]) * byte_s)
    if mode == "full":
        return full_hz, full_hz / 2.0
    sel_hz = 1.0 / ((b["command"] + b["selective_request"] + b["selective_reply"]) * byte_s)
    control = min(sel_hz, full_hz)
    return control, control - full_values_hz


def link_config(base: FirmwareConfig, control_hz: int, mode: str) -> FirmwareConfig:
    """The profile at another control rate and feedback mode (velocity filter kept below Nyquist)."""
    if mode not in MODES:
        raise ValueError(f"mode {mode!r} not allowed: one of {MODES}")
    full_hz = control_hz if mode == "full" else min(base.full_values_hz, control_hz)
    return base.with_changes(control_hz=control_hz, full_values_hz=full_hz,
                             velocity_cutoff_hz=min(base.velocity_cutoff_hz, VELOCITY_CUTOFF_FRACTION * control_hz))


@dataclass(frozen=True)
class LinkAccount:
    """A study run's link accounting and tracking (the baud and the link study each add what they vary)."""

    control_hz: int
    deadline_misses: int
    faults: tuple[str, ...]
    requests: int
    replies: int
    missing_replies: int
    stale_replies: int
    tx_refused: int
    feedback_rate_hz: float
    max_feedback_age_ms: float
    rms_error_deg: float
    max_error_deg: float

    @property
    def passed(self) -> bool:
        """No miss, no fault, no refused write, and every request answered before the next one."""
        return (self.deadline_misses == 0 and not self.faults and self.tx_refused == 0
                and self.missing_replies == 0 and self.stale_replies == 0 and self.replies > 0)


def link_account(r: RunResult, control_hz: int) -> dict[str, Any]:
    """The LinkAccount fields of a run, from its summary (a tracking figure it lacks is NaN)."""
    s = summarise(r)
    link = s["motor_link"]
    return {"control_hz": control_hz, "deadline_misses": s["deadline_misses"], "faults": tuple(s["faults"]),
            "requests": link["requests"], "replies": link["replies"], "missing_replies": link["missing_replies"],
            "stale_replies": link["stale_replies"], "tx_refused": r.firmware.motor.stats.tx_refused,
            "feedback_rate_hz": link["feedback_rate_hz"], "max_feedback_age_ms": link["max_feedback_age_ms"],
            **{k: math.nan if s["tracking"]["truth"][src] is None else s["tracking"]["truth"][src]
               for k, src in (("rms_error_deg", "rms_deg"), ("max_error_deg", "max_deg"))}}


@dataclass(frozen=True, kw_only=True)
class StudyRun(LinkAccount):
    """One run of the study: its link configuration, the link accounting and the tracking figures."""

    baud: int
    mode: str


def study_run(base: FirmwareConfig, baud: int, mode: str, control_hz: int, *, strides: int, seed: int,
              params: PlantParams | None = None) -> StudyRun:
    """Run the firmware at one (baud, mode, control rate) and account for its link (params: the plant)."""
    r = run_virtual(RunConfig(strides=strides, baud=baud, seed=seed, firmware=link_config(base, control_hz, mode),
                              trace_capacity=0, bench_options={} if params is None else {"plant_params": params}))
    out = StudyRun(baud=baud, mode=mode, **link_account(r, control_hz))
    logger.info("baud study %s", out)
    return out


def _search(base: FirmwareConfig, baud: int, mode: str, candidates: tuple[int, ...], strides: int,
            seed: int, params: PlantParams | None = None) -> tuple[StudyRun | None, list[StudyRun]]:
    """Try the candidates fastest first; return the first that passes (or None) and every run made."""
    runs: list[StudyRun] = []
    for hz in sorted(candidates, reverse=True):
        runs.append(study_run(base, baud, mode, hz, strides=strides, seed=seed, params=params))
        if runs[-1].passed:
            return runs[-1], runs
    return None, runs


def _fmt_hz(x: float) -> str:
    return f"{x:.0f}"


def run(seed: int = 0, quick: bool = False, profile: Path | None = None, bauds: tuple[int, ...] = BAUDS,
        modes: tuple[str, ...] = MODES, candidates: tuple[int, ...] = CANDIDATE_HZ,
        strides: int | None = None, params: PlantParams | None = None) -> BenchResult:
    """Find the achievable control rate per baud and mode; compare with the wire-time bound."""
    n = strides if strides is not None else 1
    del quick  # already one stride per run
    base = load_firmware_config(profile)
    best: dict[tuple[int, str], StudyRun | None] = {}
    every: list[StudyRun] = []
    figures: list[Figure] = []
    for baud in bauds:
        for mode in modes:
            found, runs = _search(base, baud, mode, candidates, n, seed, params)
            best[(baud, mode)], every = found, every + runs
            bound_hz, bound_fb = analytic_max_hz(baud, mode, base.full_values_hz)
            tag = f"{baud} {mode}"
            if found is None:
                figures.append(Figure(f"{tag}: achievable control rate", "Hz", REPORT_TEXT, None, math.nan,
                                      f"none of {sorted(candidates)} Hz passes; wire bound {_fmt_hz(bound_hz)} Hz",
                                      basis=BASIS))
                continue
            figures += [
                Figure(f"{tag}: achievable control rate", "Hz", REPORT_TEXT, None, float(found.control_hz),
                       f"wire bound {_fmt_hz(bound_hz)} Hz; {found.deadline_misses} deadline misses", basis=BASIS),
                Figure(f"{tag}: feedback rate", "Hz", REPORT_TEXT, None, found.feedback_rate_hz,
                       f"wire bound {_fmt_hz(bound_fb)} Hz", basis=BASIS),
                Figure(f"{tag}: worst feedback age", "ms", REPORT_TEXT, None, found.max_feedback_age_ms, "",
                       basis=BASIS),
                Figure(f"{tag}: RMS tracking error", "deg", REPORT_TEXT, None, found.rms_error_deg,
                       f"max {found.max_error_deg:.3f}°; plant's true angle (emulation only)", basis=BASIS),
            ]
    ok = [r for r in best.values() if r is not None]
    rec = min(ok, key=lambda r: (-r.control_hz, -r.feedback_rate_hz, r.rms_error_deg, r.baud)) if ok else None
    if rec is not None:
        figures.append(Figure("recommended configuration: RMS tracking error", "deg", REPORT_TEXT, None,
                              rec.rms_error_deg, f"{rec.baud} baud, {rec.mode} feedback, {rec.control_hz} Hz control, "
                              f"{rec.feedback_rate_hz:.0f} Hz feedback; plant's true angle (emulation only)",
                              basis=BASIS))
    columns = {name: np.array([getattr(r, name) if name != "faults" else "|".join(r.faults) for r in every])
               for name in ("baud", "mode", "control_hz", "deadline_misses", "faults", "requests", "replies",
                            "missing_replies", "stale_replies", "tx_refused", "feedback_rate_hz",
                            "max_feedback_age_ms", "rms_error_deg", "max_error_deg")}
    columns["passed"] = np.array([int(r.passed) for r in every])

    def plot(fig: object) -> None:
        ax_r, ax_e = fig.subplots(2, 1)  # type: ignore[attr-defined]
        x = np.arange(len(bauds))
        width = 0.8 / max(1, len(modes))
        for k, mode in enumerate(modes):
            ctl = [best[(b, mode)].control_hz if best[(b, mode)] else 0 for b in bauds]  # type: ignore[union-attr]
            fb = [best[(b, mode)].feedback_rate_hz if best[(b, mode)] else 0 for b in bauds]  # type: ignore[union-attr]
            bound = [analytic_max_hz(b, mode, base.full_values_hz)[0] for b in bauds]
            xs = x + (k - (len(modes) - 1) / 2) * width
            ax_r.bar(xs, ctl, width, label=f"{mode}: achievable control rate")
            ax_r.plot(xs, fb, "k^", ms=6, label="feedback rate" if k == 0 else None)
            ax_r.plot(xs, bound, "rx", ms=8, label="wire-time bound (control)" if k == 0 else None)
            rms = [best[(b, mode)].rms_error_deg if best[(b, mode)] else math.nan for b in bauds]  # type: ignore[union-attr]
            ax_e.bar(xs, rms, width, label=mode)
        for ax in (ax_r, ax_e):
            ax.set_xticks(x, [str(b) for b in bauds])
            ax.set_xlabel("motor link baud")
        ax_r.set_yscale("log")
        ax_r.set_ylabel("rate [Hz]")
        ax_r.set_title("Achievable control-loop rate (no miss, a reply to every request)")
        ax_r.legend(fontsize=7)
        ax_e.set_ylabel("RMS tracking error [deg]")
        ax_e.legend(fontsize=7)

    params = {"strides": n, "seed": seed, "bauds": list(bauds), "modes": list(modes), "candidates_hz": list(candidates),
              "wire_bytes": _wire_bytes(), "profile": str(profile) if profile else "profiles/firmware.toml",
              "recommended": None if rec is None else {"baud": rec.baud, "mode": rec.mode, "control_hz": rec.control_hz,
                                                       "feedback_rate_hz": rec.feedback_rate_hz,
                                                       "rms_error_deg": rec.rms_error_deg},
              "achievable": {f"{b} {m}": (None if r is None else r.control_hz) for (b, m), r in best.items()}}
    return BenchResult("baud-study", figures, columns, plot, params)
