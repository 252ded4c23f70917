"""Fast response: the suspended foot, driver unpowered, resting on the plantarflexion stop, hit by a push.

Protocol (docs/bench.md): the foot rests on the -30 deg stop; at t = 0.2 s the impulse fixture applies
a rectangular dorsiflexing torque pulse (10 N*m for 50 ms: 0.5 N*m*s, a pneumatic push). From the
angle sampled at 1 kHz: excursion = angle - rest angle; rise time = 10 %..90 % of the peak excursion
on the rising edge; overshoot = largest excursion below the rest angle after the return (into the
stop), in % of the peak; rebounds = separate returns above SETTLE_BAND of the peak after the first
landing; settling time = from the pulse start until the excursion stays within SETTLE_BAND of peak.
"""

from __future__ import annotations

import logging
import math

import numpy as np

from hal.virtual.plant import Plant, PlantParams, impulse, load_plant_params
from host_tools.benchtests.output import BenchResult, Figure

logger = logging.getLogger(__name__)

PULSE_TORQUE_NM = 10.0
PULSE_S = 0.05
PULSE_START_S = 0.2
SAMPLE_S = 1e-3
SETTLE_BAND = 0.02
#: Report: rise time under 1 s, little overshoot, no oscillation.
REPORT_RISE_S = 1.0


def step_metrics(t_s: np.ndarray, angle_rad: np.ndarray, start_s: float) -> dict[str, float]:
    """Rise time 10-90 %, peak, overshoot (%), rebounds and settling time of a pulse response."""
    rest = float(angle_rad[t_s < start_s][-1])
    ex = angle_rad - rest
    k_peak = int(np.argmax(ex))
    peak = float(ex[k_peak])
    if not peak > 0:
        raise ValueError(f"the push produced no excursion (peak {peak!r} rad): no response to measure")
    rising = ex[: k_peak + 1]
    t10 = float(t_s[np.argmax(rising >= 0.1 * peak)])
    t90 = float(t_s[np.argmax(rising >= 0.9 * peak)])
    after = ex[k_peak:]
    landed = np.nonzero(after <= SETTLE_BAND * peak)[0]
    overshoot = 0.0
    rebounds = 0
    if landed.size:
        tail = after[landed[0]:]
        overshoot = float(max(0.0, -tail.min()) / peak * 100.0)
        above = (tail > SETTLE_BAND * peak).astype(int)
        rebounds = int(np.sum(np.diff(above) == 1))
    outside = np.nonzero(np.abs(ex) > SETTLE_BAND * peak)[0]
    settle = float(t_s[outside[-1] + 1] - start_s) if outside.size and outside[-1] + 1 < len(t_s) else math.nan
    return {"rest_rad": rest, "peak_rad": peak, "peak_time_s": float(t_s[k_peak] - start_s),
            "rise_s": t90 - t10, "overshoot_pct": overshoot, "rebounds": float(rebounds), "settling_s": settle}


def run(seed: int = 0, quick: bool = False, params: PlantParams | None = None,
        duration_s: float = 2.5) -> BenchResult:
    """Push the unpowered foot off its stop and measure rise, overshoot, rebounds and settling."""
    del seed, quick  # deterministic and fast
    p = params if params is not None else load_plant_params()
    plant = Plant(p, impulse(PULSE_TORQUE_NM, PULSE_S, start_s=PULSE_START_S), initial_angle_rad=p.stop_min_rad)
    plant.set_powered(False, 0.0)
    t = np.arange(int(round(duration_s / SAMPLE_S)) + 1) * SAMPLE_S
    angle = np.array([plant.output_angle_rad(float(x)) for x in t])
    m = step_metrics(t, angle, PULSE_START_S)
    logger.info("fast response: %s", m)
    figures = [
        Figure("rise time 10-90 %", "s", "< 1", REPORT_RISE_S, m["rise_s"],
               "pass" if m["rise_s"] < REPORT_RISE_S else "FAIL"),
        Figure("overshoot (below rest, into the stop)", "%", "little", None, m["overshoot_pct"],
               f"peak excursion {math.degrees(m['peak_rad']):.1f} deg at {m['peak_time_s']:.3f} s"),
        Figure(f"rebounds above {SETTLE_BAND:.0%} of peak", "count", "none (no oscillation)", 0.0, m["rebounds"],
               "stop contact damping 0.3 of critical (plant profile)"),
        Figure(f"settling time ({SETTLE_BAND:.0%} band)", "s", "not given", None, m["settling_s"], ""),
    ]

    def plot(fig: object) -> None:
        ax = fig.subplots(1, 1)  # type: ignore[attr-defined]
        ax.plot(t, np.degrees(angle), label="ankle angle")
        ax.axvspan(PULSE_START_S, PULSE_START_S + PULSE_S, color="tab:red", alpha=0.2,
                   label=f"push {PULSE_TORQUE_NM:g} N·m × {PULSE_S * 1000:g} ms")
        rest, peak = m["rest_rad"], m["peak_rad"]
        for frac in (0.1, 0.9):
            ax.axhline(math.degrees(rest + frac * peak), color="0.6", ls=":", lw=0.8)
        ax.set_xlabel("time [s]")
        ax.set_ylabel("angle [deg]")
        ax.set_title(f"Impulse response, driver unpowered: rise {m['rise_s'] * 1000:.0f} ms, "
                     f"overshoot {m['overshoot_pct']:.1f} %, {int(m['rebounds'])} rebound(s)")
        ax.legend(fontsize=8)

    return BenchResult("fast-response", figures, {"t_s": t, "angle_deg": np.degrees(angle)}, plot,
                       {"pulse_torque_nm": PULSE_TORQUE_NM, "pulse_s": PULSE_S, "pulse_start_s": PULSE_START_S,
                        "settle_band": SETTLE_BAND, **m})
