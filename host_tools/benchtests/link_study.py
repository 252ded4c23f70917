"""Link study: UART or CAN? The report's future-work item measured on the full firmware run.

For each motor link (the UART at a baud with selective feedback, as in the baud study; CAN at 1 Mbit/s
in servo mode and in MIT mode) the firmware runs on the virtual bench at each candidate control rate,
fastest first; the achievable rate is the first whose run has no deadline miss, no latched fault, no
refused command, and no missing or stale reply (the baud study's test). Each row gives the rate, the
feedback rate, the worst feedback age, the load of the busiest direction of the link (UART: bytes x
10 bit-times over the run, per direction; CAN: bit-times of every frame, exact stuffing, over the run)
and the tracking error against the plant's true angle. Every link is also run at the profile's
1 kHz (``SAME_RATE_HZ``): what each link gives at an equal control rate.

Feedback age, per link, as the driver accounts it: UART and MIT mode, request (command) to the reply
taken by the motor task; servo mode, the longest gap between two status frames taken (no request).

The wire-time bound of CAN: MIT mode sends an 8-byte standard frame and gets one back each period;
servo mode sends a 4-byte extended SET_CURRENT each period and the motor adds its 8-byte extended
status frames at their own rate; both with worst-case stuffing (:mod:`hal.virtual.can_bits`).
"""

from __future__ import annotations

import logging
import math
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from firmware.config import FirmwareConfig, load_firmware_config
from hal.virtual.can_bits import worst_case_bits
from hal.virtual.plant import PlantParams
from host_tools.benchtests.baud_study import LinkAccount, analytic_max_hz, link_account, link_config
from host_tools.benchtests.output import BenchResult, Figure
from host_tools.runner import RunConfig, run_virtual

#: The readings of the report this test runs under (hal.virtual.plant.readings); the geometry is the bench's.
READINGS = {"driver": "current-lag", "imu": "first-order-lag"}
logger = logging.getLogger(__name__)

__all__ = ["CANDIDATE_HZ", "LINKS", "LinkRun", "can_bound_hz", "link_run", "run"]

LINKS: tuple[str, ...] = ("uart", "can-servo", "can-mit")
CANDIDATE_HZ: tuple[int, ...] = (4000, 2000, 1000, 500)
SAME_RATE_HZ = 1000  # every link is also run at the profile's rate: what a link buys at equal control rate
CAN_BITRATE = 1_000_000
UART_BAUD = 921_600
STATUS_HZ = 500.0  # the virtual AK60-6's servo-mode status rate (Ak60CanConfig.status_period_s)
REPORT_TEXT = "future work: switch from UART to CAN (ch. 5); UART delay a limitation (§4.3)"


def _basis(link: str, what: str) -> str:
    """Nothing is fitted to these rows; servo mode's feedback follows the status rate we assume for the motor."""
    if link == "can-servo" and what == "feedback":
        return "assumed: the AK60-6's servo-mode status rate, 500 Hz (no source gives it; docs/devices.md)"
    return "predicted"


def can_bound_hz(link: str, bitrate: int = CAN_BITRATE, status_hz: float = STATUS_HZ) -> float:
    """Control rate at which the worst-case frames of one period fill the bus.

    >>> round(can_bound_hz("can-mit")), round(can_bound_hz("can-servo"))
    (3704, 7667)
    """
    if link == "can-mit":
        return bitrate / (2 * worst_case_bits(8, False))
    if link == "can-servo":
        free = 1.0 - status_hz * worst_case_bits(8, True) / bitrate
        return free * bitrate / worst_case_bits(4, True)
    raise ValueError(f"link {link!r} not a CAN link: can-servo or can-mit")


def bound_hz(link: str, full_values_hz: int) -> float:
    """The wire-time bound of a link's control rate (UART: the baud study's, selective feedback)."""
    return analytic_max_hz(UART_BAUD, "selective", full_values_hz)[0] if link == "uart" else can_bound_hz(link)


@dataclass(frozen=True, kw_only=True)
class LinkRun(LinkAccount):
    """One run: link, control rate, link accounting, load and tracking."""

    link: str
    link_load: float


def _load(r: object) -> float:
    bench, span = r.bench, r.sim_time_s  # type: ignore[attr-defined]
    if bench.can_bus is not None:
        return bench.can_bus.busy_ticks / bench.f_cpu_hz / span
    up = bench.motor_uart.tx_bytes * 10 / bench.motor_uart.baud
    down = bench.motor.stats.bytes_out * 10 / bench.motor_uart.baud
    return max(up, down) / span


def link_run(base: FirmwareConfig, link: str, control_hz: int, *, strides: int, seed: int,
             params: PlantParams | None = None) -> LinkRun:
    """Run the firmware on one link at one control rate (params: the plant, default the profile's)."""
    fw = link_config(base, control_hz, "selective").with_changes(motor_link=link)
    r = run_virtual(RunConfig(strides=strides, baud=UART_BAUD, seed=seed, firmware=fw, trace_capacity=0,
                              bench_options={} if params is None else {"plant_params": params}))
    out = LinkRun(link=link, link_load=round(_load(r), 4), **link_account(r, control_hz))
    logger.info("link study %s", out)
    return out


def run(seed: int = 0, quick: bool = False, profile: Path | None = None, links: tuple[str, ...] = LINKS,
        candidates: tuple[int, ...] = CANDIDATE_HZ, strides: int | None = None,
        params: PlantParams | None = None) -> BenchResult:
    """Find the achievable control rate per link; rows side by side, with the wire-time bounds."""
    n = strides if strides is not None else 1
    del quick  # already one stride per run
    base = load_firmware_config(profile)
    best: dict[str, LinkRun | None] = {}
    every: list[LinkRun] = []
    figures: list[Figure] = []
    for link in links:
        found = None
        for hz in sorted(candidates, reverse=True):
            every.append(link_run(base, link, hz, strides=n, seed=seed, params=params))
            if every[-1].passed:
                found = every[-1]
                break
        best[link] = found
        bound = bound_hz(link, base.full_values_hz)
        if found is None:
            figures.append(Figure(f"{link}: achievable control rate", "Hz", REPORT_TEXT, None, math.nan,
                                  f"none of {sorted(candidates)} Hz passes; wire bound {bound:.0f} Hz",
                                  basis=_basis(link, "other")))
            continue
        figures += [
            Figure(f"{link}: achievable control rate", "Hz", REPORT_TEXT, None, float(found.control_hz),
                   f"wire bound {bound:.0f} Hz; {found.deadline_misses} deadline misses", basis=_basis(link, "other")),
            Figure(f"{link}: feedback rate", "Hz", REPORT_TEXT, None, found.feedback_rate_hz, "",
                   basis=_basis(link, "feedback")),
            Figure(f"{link}: worst feedback age", "ms", REPORT_TEXT, None, found.max_feedback_age_ms, "",
                   basis=_basis(link, "feedback")),
            Figure(f"{link}: link load", "%", REPORT_TEXT, None, round(100 * found.link_load, 2), "busiest direction",
                   basis=_basis(link, "other")),
            Figure(f"{link}: RMS tracking error", "deg", REPORT_TEXT, None, found.rms_error_deg,
                   f"max {found.max_error_deg:.3f}°", basis=_basis(link, "other")),
        ]
    for link in links:  # the same control rate on every link
        same = next((r for r in every if r.link == link and r.control_hz == SAME_RATE_HZ), None)
        if same is None:
            same = link_run(base, link, SAME_RATE_HZ, strides=n, seed=seed, params=params)
            every.append(same)
        figures += [
            Figure(f"{link} at {SAME_RATE_HZ} Hz: worst feedback age", "ms", REPORT_TEXT, None,
                   same.max_feedback_age_ms, f"feedback {same.feedback_rate_hz:.0f} Hz; passed {same.passed}",
                   basis=_basis(link, "feedback")),
            Figure(f"{link} at {SAME_RATE_HZ} Hz: link load", "%", REPORT_TEXT, None, round(100 * same.link_load, 2),
                   "busiest direction", basis=_basis(link, "other")),
            Figure(f"{link} at {SAME_RATE_HZ} Hz: RMS tracking error", "deg", REPORT_TEXT, None, same.rms_error_deg,
                   f"max {same.max_error_deg:.3f}°", basis=_basis(link, "other")),
        ]
    columns = {name: np.array([getattr(r, name) if name != "faults" else "|".join(r.faults) for r in every])
               for name in ("link", "control_hz", "deadline_misses", "faults", "requests", "replies",
                            "missing_replies", "stale_replies", "tx_refused", "feedback_rate_hz",
                            "max_feedback_age_ms", "link_load", "rms_error_deg", "max_error_deg")}
    columns["passed"] = np.array([int(r.passed) for r in every])

    def plot(fig: object) -> None:
        ax_r, ax_a, ax_e = fig.subplots(3, 1)  # type: ignore[attr-defined]
        x = np.arange(len(links))
        rows = [best[k] for k in links]
        ax_r.bar(x, [r.control_hz if r else 0 for r in rows], 0.5, label="achievable control rate")
        ax_r.plot(x, [r.feedback_rate_hz if r else 0 for r in rows], "k^", ms=7, label="feedback rate")
        ax_r.plot(x, [bound_hz(k, base.full_values_hz) for k in links], "rx", ms=8, label="wire-time bound")
        ax_r.set_ylabel("rate [Hz]")
        ax_r.set_title(f"Motor link: UART {UART_BAUD} baud vs CAN {CAN_BITRATE // 1000} kbit/s")
        ax_r.legend(fontsize=7)
        ages = [r.max_feedback_age_ms if r else math.nan for r in rows]
        ax_a.bar(x - 0.15, ages, 0.3, label="worst feedback age [ms]")
        ax_a.bar(x + 0.15, [100 * r.link_load if r else math.nan for r in rows], 0.3, label="link load [%]")
        ax_a.legend(fontsize=7)
        ax_e.bar(x, [r.rms_error_deg if r else math.nan for r in rows], 0.5)
        ax_e.set_ylabel("RMS tracking error [deg]")
        for ax in (ax_r, ax_a, ax_e):
            ax.set_xticks(x, [("uart " + str(UART_BAUD)) if k == "uart" else k for k in links])

    params = {"strides": n, "seed": seed, "links": list(links), "candidates_hz": list(candidates),
              "uart_baud": UART_BAUD, "can_bitrate": CAN_BITRATE, "status_hz": STATUS_HZ,
              "bounds_hz": {k: round(bound_hz(k, base.full_values_hz)) for k in links},
              "achievable": {k: (None if r is None else r.control_hz) for k, r in best.items()}}
    return BenchResult("link-study", figures, columns, plot, params)
