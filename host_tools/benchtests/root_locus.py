"""The report's gain tuning (4.4: "the root locus method"; Appendix B, "Code: Gain analysis") redone.

Appendix B's script tunes a discrete PI on an RL winding 1/(L s + R) with R = 0.5 Ohm, L = 1 uH, Ts = 0.1 ms
and wc = pi/5: k = R wc / (1 - exp(-R Ts / L)), ki = 1 - exp(-R Ts / L). The PI's zero then cancels the
winding's discrete pole, the loop is wc / (z - 1) and the closed-loop pole sits at z = 1 - wc. Redone as
written and with Table B2's winding (0.202 Ohm, 138 uH).
Then the method on the linearised position loop (hal.virtual.plant.linear, the voltage-amplifier reading:
the PID's +-1 is +-24 V behind 24/(1 + 0.00114 s), the bench's geometry): the root locus of a P position
gain, and the gain at which the dominant pair reaches zeta = 0.7 (assumed: the report gives neither its
design point nor its gains). Those poles are checked on the emulator: the nonlinear plant follows the
normative gait for 2 strides with that gain, its driver the voltage amplifier (Plant(driver=
"voltage-amplifier"): the PID's output as a voltage, the current set by the winding and the back-EMF).
"""

from __future__ import annotations

import math

import numpy as np

from firmware.control.reference import GaitReference
from hal.virtual.plant import Plant, PlantParams, load_plant_params
from hal.virtual.plant.linear import loop_state_space
from hal.virtual.plant.readings import geometry_of
from host_tools.benchtests.output import BenchResult, Figure

__all__ = ["READINGS", "appendix_b_gains", "locus", "run"]

#: The readings this test runs under; the geometry is the bench's.
READINGS = {"driver": "voltage-amplifier", "imu": "n/a"}
#: Appendix B's script: R [Ohm], L [H], Ts [s], wc [rad/sample].
APPENDIX_B = {"r_ohm": 0.5, "l_h": 1e-6, "ts_s": 1e-4, "wc": math.pi / 5}
TARGET_ZETA = 0.7
CONTROL_S = 1e-3
STRIDE_S = 1.1


def appendix_b_gains(r_ohm: float, l_h: float, ts_s: float, wc: float) -> dict[str, float]:
    """k, ki, the winding's discrete pole and the closed-loop pole of Appendix B's PI design."""
    pole = math.exp(-r_ohm * ts_s / l_h)
    ki = 1.0 - pole
    k = r_ohm * wc / ki
    # loop: k (z - 1 + ki)/(z - 1) x (1 - pole)/R / (z - pole); the PI zero 1 - ki equals the pole: cancelled
    loop_gain = k * (1.0 - pole) / r_ohm
    return {"k": k, "ki": ki, "plant_pole_z": pole, "pi_zero_z": 1.0 - ki, "closed_loop_pole_z": 1.0 - loop_gain,
            "crossover_rad_s": wc / ts_s}


def locus(a: np.ndarray, b: np.ndarray, c: np.ndarray, gains: np.ndarray) -> np.ndarray:
    """Closed-loop poles of u = K (r - y) for each gain: eig(A - K b c), one row per gain."""
    return np.array([np.sort_complex(np.linalg.eigvals(a - k * (b @ c))) for k in gains])


def _dominant_zeta(poles: np.ndarray) -> float:
    """Damping ratio of the slowest complex pair (1 when the slowest poles are real)."""
    slow = min(poles, key=lambda s: -s.real)
    if abs(slow.imag) < 1e-9:
        return 1.0
    return float(-slow.real / abs(slow))


def track(p: PlantParams, kp: float, strides: int = 2) -> dict[str, np.ndarray]:
    """The nonlinear plant, its driver a voltage amplifier, following the normative gait with u = kp (r - theta)."""
    ref = GaitReference.normative(stride_s=STRIDE_S)
    th0 = ref.sample(0.0)[0]
    plant = Plant(p, initial_angle_rad=th0, driver="voltage-amplifier")
    n = int(round(strides * STRIDE_S / CONTROL_S))
    t = np.arange(n) * CONTROL_S
    angle = np.empty(n)
    reference = np.empty(n)
    for k, tk in enumerate(t):
        st = plant.state_at(float(tk))
        r = ref.sample(float(tk))[0]
        angle[k], reference[k] = st.output_angle_rad, r
        plant.set_voltage_command(kp * (r - st.output_angle_rad), float(tk))
    return {"t_s": t, "angle_rad": angle, "reference_rad": reference}


def run(seed: int = 0, quick: bool = False, params: PlantParams | None = None) -> BenchResult:
    """Appendix B's design redone, the root locus of the linearised loop, its pick tracked on the emulator."""
    del seed
    p = params if params is not None else load_plant_params()
    geometry = geometry_of(p)
    as_written = appendix_b_gains(**APPENDIX_B)
    table_b2 = appendix_b_gains(p.phase_resistance_ohm, p.phase_inductance_h, APPENDIX_B["ts_s"], APPENDIX_B["wc"])
    a, b, c = loop_state_space(p, geometry if geometry != "custom" else "level-com", "voltage-amplifier")
    gains = np.logspace(-2, 3, 501)
    poles = locus(a, b, c, gains)
    zetas = np.array([_dominant_zeta(row) for row in poles])
    stable = np.array([row.real.max() < 0 for row in poles])
    ok = np.nonzero((zetas >= TARGET_ZETA) & stable)[0]
    pick = float(gains[ok[-1]]) if ok.size else math.nan
    pick_poles = poles[ok[-1]] if ok.size else np.array([])
    unstable = np.nonzero(~stable)[0]
    k_max = float(gains[unstable[0]]) if unstable.size else math.inf
    tr = track(p, pick, strides=1 if quick else 2) if math.isfinite(pick) else None
    rms = max_err = math.nan
    if tr is not None:
        err = np.degrees(tr["reference_rad"] - tr["angle_rad"])
        steady = tr["t_s"] >= STRIDE_S * 0.25
        rms, max_err = float(np.sqrt(np.mean(err[steady] ** 2))), float(np.max(np.abs(err[steady])))
    slow = min(pick_poles, key=lambda s: -s.real) if pick_poles.size else complex(math.nan)
    pred = "predicted"
    design = f"assumed: P position gain at dominant zeta = {TARGET_ZETA} (the report gives no design point)"
    figures = [
        Figure("Appendix B as written: proportional gain k", "-", "R wc / (1 - exp(-R Ts/L)) (App. B)",
               None, as_written["k"], f"ki = {as_written['ki']:.4f}; R Ts/L = 50: the winding's pole at z = "
               f"{as_written['plant_pole_z']:.1e}, cancelled by the PI's zero", basis=pred),
        Figure("Appendix B as written: closed-loop pole", "z", "1 - wc = 0.372 (App. B)", 1 - APPENDIX_B["wc"],
               as_written["closed_loop_pole_z"], f"crossover {as_written['crossover_rad_s']:.0f} rad/s "
               f"({as_written['crossover_rad_s'] / (2 * math.pi):.0f} Hz): a current loop, not the position loop",
               basis=pred),
        Figure("Appendix B with Table B2's winding: k", "-", "R = 0.5 Ohm, L = 1 uH in the script (App. B)", None,
               table_b2["k"], f"R = {p.phase_resistance_ohm:g} Ohm, L = {p.phase_inductance_h * 1e6:g} uH: ki = "
               f"{table_b2['ki']:.3f}; same closed-loop pole {table_b2['closed_loop_pole_z']:.3f}", basis=pred),
        Figure(f"position loop ({geometry}): P gain at zeta {TARGET_ZETA}", "1/rad", "root locus (4.4)", None, pick,
               f"dominant poles {slow.real:.1f} ± {abs(slow.imag):.1f}j /s; unstable above {k_max:.3g} /rad",
               basis=design),
        Figure(f"position loop ({geometry}): that gain on the emulator, RMS error", "deg",
               "\"smoother data\" after tuning (4.4)", None, rms,
               f"max {max_err:.2f} deg; nonlinear plant with the voltage-amplifier driver, normative gait, 1 kHz; "
               "the plant's true angle (emulation only)", basis=design),
    ]

    def plot(fig: object) -> None:
        ax1, ax2 = fig.subplots(1, 2)  # type: ignore[attr-defined]
        for j in range(poles.shape[1]):
            ax1.plot(poles[:, j].real, poles[:, j].imag, ".", ms=1.5)
        if pick_poles.size:
            ax1.plot(pick_poles.real, pick_poles.imag, "k*", ms=8, label=f"K = {pick:.3g} /rad (ζ {TARGET_ZETA})")
        ax1.set(xlabel="Re [1/s]", ylabel="Im [1/s]", title=f"Root locus, P position gain ({geometry})",
                xlim=(-2000, 200))
        ax1.legend(fontsize=7)
        if tr is not None:
            ax2.plot(tr["t_s"], np.degrees(tr["reference_rad"]), "k", label="reference")
            ax2.plot(tr["t_s"], np.degrees(tr["angle_rad"]), label="plant (emulation only)")
        ax2.set(xlabel="time [s]", ylabel="ankle angle [deg]", title=f"On the emulator: RMS {rms:.2f}°")
        ax2.legend(fontsize=7)

    columns: dict[str, np.ndarray] = {"gain_per_rad": gains, "dominant_zeta": zetas}
    for j in range(poles.shape[1]):
        columns[f"pole{j}_re"] = poles[:, j].real
        columns[f"pole{j}_im"] = poles[:, j].imag
    if tr is not None:
        columns.update({"track_t_s": tr["t_s"], "track_reference_deg": np.degrees(tr["reference_rad"]),
                        "track_angle_deg": np.degrees(tr["angle_rad"])})
    return BenchResult("root-locus", figures, columns, plot,
                       {"appendix_b": {"inputs": APPENDIX_B, "as_written": as_written, "table_b2": table_b2},
                        "geometry": geometry, "target_zeta": TARGET_ZETA, "pick_gain_per_rad": pick,
                        "pick_poles": [str(s) for s in pick_poles], "unstable_above_per_rad": k_max,
                        "track_rms_deg": rms, "track_max_deg": max_err})
