"""Fast response: the suspended foot hit by a push, as the report sets it up and as its outcome reads.

The report's setup (3.8.2): "an impulse response using a pneumatic system while the motor remains off".
Its outcome (4.2.2): "the angle decays rapidly and stabilizes near the reference angle of 0 degrees [...]
the small overshoot demonstrates effective controller tuning". An unpowered suspended foot cannot come to
rest at 0 deg (gravity plantarflexes it onto its stop, docs/plant.md): the outcome is that of a foot held
at 0 deg by the controller. Both cases are run:

- unpowered: the foot rests on the -30 deg stop (its rest angle with the motor off);
- controlled: the firmware's cascade (profile gains, feed-forward) holds the report's rest angle 0 deg,
  fed the plant's angle and velocity at 1 kHz, from HOLD_S before the push.

The push (the same in both) is the impulse fixture's rectangular dorsiflexing torque pulse at the ankle,
10 N*m for 50 ms = 0.5 N*m*s at t = 0.2 s after the hold. Assumed (the report gives no force or duration):
a short pneumatic push, sized so the unpowered foot's excursion stays inside the range of motion. From the
angle sampled at 1 kHz: excursion = angle - rest angle; rise time = 10 %..90 % of the peak excursion
on the rising edge; overshoot = largest excursion below the rest angle after the return (into the
stop), in % of the peak; rebounds = separate returns above SETTLE_BAND of the peak after the first
landing; settling time = from the pulse start until the excursion stays within SETTLE_BAND of peak.
"""

from __future__ import annotations

import logging
import math

import numpy as np

from firmware.config import FirmwareConfig, load_firmware_config
from firmware.control.pid import CascadeController, Feedforward
from hal.virtual.plant import Plant, PlantParams, impulse, load_plant_params
from host_tools.benchtests.output import BenchResult, Figure

#: The readings of the report this test runs under (hal.virtual.plant.readings); the geometry is the bench's.
READINGS = {"driver": "current-lag", "imu": "n/a"}
logger = logging.getLogger(__name__)

PULSE_TORQUE_NM = 10.0
PULSE_S = 0.05
PULSE_START_S = 0.2
SAMPLE_S = 1e-3
SETTLE_BAND = 0.02
#: Report: rise time under 1 s, little overshoot, no oscillation.
REPORT_RISE_S = 1.0
#: Controlled case: the cascade holds 0 deg this long before the push; excursions are measured from 0 deg
#: (the reference) and settle within 0.1 deg, about one encoder count (0.09 deg): what a bench resolves.
HOLD_S = 1.0
CONTROLLED_BAND_RAD = math.radians(0.1)
PUSH = (f"assumed: a pneumatic push, {PULSE_TORQUE_NM:g} N*m for {PULSE_S * 1000:g} ms at the ankle "
        f"({PULSE_TORQUE_NM * PULSE_S:g} N*m*s; the report gives no force or duration)")


def step_metrics(t_s: np.ndarray, angle_rad: np.ndarray, start_s: float, rest_rad: float | None = None,
                 band_rad: float | None = None) -> dict[str, float]:
    """Rise time 10-90 %, peak, overshoot (%), rebounds and settling time of a pulse response.

    The excursion is measured from rest_rad (default: the angle just before the push); the settling and
    rebound band is band_rad (default SETTLE_BAND of the peak excursion).
    """
    rest = float(angle_rad[t_s < start_s][-1]) if rest_rad is None else rest_rad
    ex = angle_rad - rest
    k_peak = int(np.argmax(ex))
    peak = float(ex[k_peak])
    if not peak > 0:
        raise ValueError(f"the push produced no excursion (peak {peak!r} rad): no response to measure")
    band = SETTLE_BAND * peak if band_rad is None else band_rad
    rising = ex[: k_peak + 1]
    t10 = float(t_s[np.argmax(rising >= 0.1 * peak)])
    t90 = float(t_s[np.argmax(rising >= 0.9 * peak)])
    after = ex[k_peak:]
    landed = np.nonzero(after <= band)[0]
    overshoot = 0.0
    rebounds = 0
    if landed.size:
        tail = after[landed[0]:]
        overshoot = float(max(0.0, -tail.min()) / peak * 100.0)
        above = (tail > band).astype(int)
        rebounds = int(np.sum(np.diff(above) == 1))
    outside = np.nonzero(np.abs(ex) > band)[0]
    settle = float(t_s[outside[-1] + 1] - start_s) if outside.size and outside[-1] + 1 < len(t_s) else math.nan
    return {"rest_rad": rest, "peak_rad": peak, "peak_time_s": float(t_s[k_peak] - start_s),
            "rise_s": t90 - t10, "overshoot_pct": overshoot, "rebounds": float(rebounds), "settling_s": settle}


def rest_angle_rad(p: PlantParams) -> float:
    """Where gravity puts the unpowered foot: the COM straight below the ankle, within the stops."""
    return min(p.stop_max_rad, max(p.stop_min_rad, -p.com_angle_at_zero_rad))


def controlled_response(p: PlantParams, fw: FirmwareConfig, duration_s: float) -> tuple[np.ndarray, np.ndarray]:
    """The foot held at 0 deg by the firmware's cascade (plant angle fed back at 1 kHz), pushed at HOLD_S + 0.2 s."""
    start = HOLD_S + PULSE_START_S
    plant = Plant(p, impulse(PULSE_TORQUE_NM, PULSE_S, start_s=start), initial_angle_rad=0.0)
    ctl = CascadeController(fw.position_gains, fw.velocity_gains, SAMPLE_S, fw.current_limit_a,
                            fw.velocity_limit_rad_s)
    ff = Feedforward(fw.feedforward_params) if fw.feedforward else None
    t = np.arange(int(round((HOLD_S + duration_s) / SAMPLE_S)) + 1) * SAMPLE_S
    angle = np.empty_like(t)
    for k, tk in enumerate(t):
        st = plant.state_at(float(tk))
        angle[k] = st.output_angle_rad
        i_ff = ff.current_a(fw.com_angle_rad, 0.0) if ff is not None else 0.0
        plant.set_current_command(ctl.update(0.0, 0.0, st.output_angle_rad, st.output_velocity_rad_s, i_ff), float(tk))
    return t - HOLD_S, angle


def run(seed: int = 0, quick: bool = False, params: PlantParams | None = None,
        duration_s: float = 2.5) -> BenchResult:
    """Push the unpowered foot off its stop, and the controlled foot off 0 deg; rise, overshoot, settling."""
    del seed, quick  # deterministic and fast
    p = params if params is not None else load_plant_params()
    rest = rest_angle_rad(p)
    plant = Plant(p, impulse(PULSE_TORQUE_NM, PULSE_S, start_s=PULSE_START_S), initial_angle_rad=rest)
    plant.set_powered(False, 0.0)
    t = np.arange(int(round(duration_s / SAMPLE_S)) + 1) * SAMPLE_S
    angle = np.array([plant.output_angle_rad(float(x)) for x in t])
    m = step_metrics(t, angle, PULSE_START_S)
    t_c, angle_c = controlled_response(p, load_firmware_config(), duration_s)
    keep = t_c >= 0.0
    t_c, angle_c = t_c[keep], angle_c[keep]
    mc = step_metrics(t_c, angle_c, PULSE_START_S, rest_rad=0.0, band_rad=CONTROLLED_BAND_RAD)
    logger.info("fast response: unpowered %s, controlled %s", m, mc)
    where = "on the -30 deg stop" if rest == p.stop_min_rad else f"at {math.degrees(rest):.0f} deg"
    unpowered = f"{PUSH}; motor off, resting {where} where gravity puts it (3.8.2's setup)"
    controlled = f"{PUSH}; cascade holding 0 deg (4.2.2's outcome), firmware profile gains"
    figures = [
        Figure("unpowered: rise time 10-90 %", "s", "< 1 (4.2.2)", REPORT_RISE_S, m["rise_s"],
               "pass" if m["rise_s"] < REPORT_RISE_S else "FAIL", basis=unpowered),
        Figure("unpowered: overshoot (below rest, into the stop)", "%", "small (4.2.2)", None, m["overshoot_pct"],
               f"peak excursion {math.degrees(m['peak_rad']):.1f} deg at {m['peak_time_s']:.3f} s", basis=unpowered),
        Figure(f"unpowered: rebounds above {SETTLE_BAND:.0%} of peak", "count", "none (\"lack of oscillation\", 4.2.2)",
               0.0, m["rebounds"], "stop contact damping 0.3 of critical (plant profile)", basis=unpowered),
        Figure(f"unpowered: settling time ({SETTLE_BAND:.0%} band)", "s", "not given", None, m["settling_s"],
               f"rests at {math.degrees(m['rest_rad']):.1f} deg"
               + (", not near 0 deg as the report's outcome" if abs(m["rest_rad"]) > 0.02 else
                  ", near 0 deg as the report's outcome"),
               basis=unpowered),
        Figure("unpowered: angle at the end", "deg", "\"stabilizes near the reference angle of 0 degrees\" (4.2.2)",
               0.0, math.degrees(float(angle[-1])),
               f"after {duration_s:g} s; the static friction ({p.static_friction_nm:.2f} N*m at the ankle) holds the "
               "foot wherever gravity's moment is below it", basis=unpowered),
        Figure("controlled: rise time 10-90 %", "s", "< 1 (4.2.2)", REPORT_RISE_S, mc["rise_s"],
               "pass" if mc["rise_s"] < REPORT_RISE_S else "FAIL", basis=controlled),
        Figure("controlled: overshoot below 0 deg", "%", "\"small overshoot\" (4.2.2)", None, mc["overshoot_pct"],
               f"peak excursion {math.degrees(mc['peak_rad']):.2f} deg at {mc['peak_time_s']:.3f} s", basis=controlled),
        Figure("controlled: rebounds above 0.1 deg", "count", "none (\"lack of oscillation\", 4.2.2)",
               0.0, mc["rebounds"], "", basis=controlled),
        Figure("controlled: settling time (0.1 deg band)", "s", "\"stabilizes near [...] 0 degrees\"",
               None, mc["settling_s"], f"settles at {math.degrees(float(angle_c[-1])):.2f} deg", basis=controlled),
    ]

    def plot(fig: object) -> None:
        ax, ax_c = fig.subplots(2, 1, sharex=True)  # type: ignore[attr-defined]
        ax_c.plot(t_c, np.degrees(angle_c), color="tab:green", label="controlled, holding 0°")
        ax_c.axvspan(PULSE_START_S, PULSE_START_S + PULSE_S, color="tab:red", alpha=0.2)
        ax_c.set_ylabel("angle [deg]")
        ax_c.legend(fontsize=8)
        ax.plot(t, np.degrees(angle), label=f"unpowered, from rest ({math.degrees(m['rest_rad']):.0f}°)")
        ax.axvspan(PULSE_START_S, PULSE_START_S + PULSE_S, color="tab:red", alpha=0.2,
                   label=f"push {PULSE_TORQUE_NM:g} N·m × {PULSE_S * 1000:g} ms")
        rest, peak = m["rest_rad"], m["peak_rad"]
        for frac in (0.1, 0.9):
            ax.axhline(math.degrees(rest + frac * peak), color="0.6", ls=":", lw=0.8)
        ax_c.set_xlabel("time [s]")
        ax.set_ylabel("angle [deg]")
        ax.set_title(f"Impulse response, driver unpowered: rise {m['rise_s'] * 1000:.0f} ms, "
                     f"overshoot {m['overshoot_pct']:.1f} %, {int(m['rebounds'])} rebound(s)")
        ax.legend(fontsize=8)

    return BenchResult("fast-response", figures, {"t_s": t, "angle_deg": np.degrees(angle),
                                                  "controlled_angle_deg": np.degrees(angle_c)}, plot,
                       {"pulse_torque_nm": PULSE_TORQUE_NM, "pulse_s": PULSE_S, "pulse_start_s": PULSE_START_S,
                        "settle_band": SETTLE_BAND, "hold_s": HOLD_S, **m,
                        "controlled": {**mc, "final_deg": math.degrees(float(angle_c[-1]))}})
