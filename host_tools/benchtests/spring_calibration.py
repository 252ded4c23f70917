"""Spring calibration: the stiffness the report's own oscillation data (Tables B4, B5) imply.

The report hangs 680 g and 1080 g on the spring, times 5 oscillations five times each (Tables B4, B5),
uses w = sqrt(k/m) and states "approximately 250 N/m" (Appendix B), while its loading test uses 215 N/m
(3.8.3, 4.2.3). From the tables: T = (mean time of 5 oscillations) / 5, k = m (2 pi / T)^2 per mass, and
the two-mass estimate k = 4 pi^2 (m2 - m1) / (T2^2 - T1^2), which cancels the spring's own mass.
Nothing is simulated: this is the report's arithmetic redone.
"""

from __future__ import annotations

import math

import numpy as np

from host_tools.benchtests.output import BenchResult, Figure

#: The readings of the report this test runs under (hal.virtual.plant.readings); the geometry is the bench's.
READINGS = {"geometry": "n/a", "driver": "n/a", "imu": "n/a"}
__all__ = ["TABLE_B4", "TABLE_B5", "run", "stiffness", "two_mass_stiffness"]

#: Time of 5 oscillations [s], five trials (Table B4: 680 g; Table B5: 1080 g).
TABLE_B4 = (5.75, 6.15, 6.20, 5.65, 5.85)
TABLE_B5 = (7.61, 7.63, 8.0, 8.86, 9.68)
MASSES_KG = (0.680, 1.080)
OSCILLATIONS = 5
REPORT_APPENDIX_N_PER_M = 250.0
REPORT_LOADING_N_PER_M = 215.0


def stiffness(mass_kg: float, times_s: tuple[float, ...], oscillations: int = OSCILLATIONS) -> tuple[float, float]:
    """(k [N/m], period [s]) of a mass on a spring from the times of `oscillations` oscillations.

    >>> round(stiffness(1.0, (2 * math.pi,), 1)[0], 9)
    1.0
    """
    period = float(np.mean(times_s)) / oscillations
    return mass_kg * (2 * math.pi / period) ** 2, period


def two_mass_stiffness() -> float:
    """The spring rate both tables give together, k = 4 pi^2 (m2 - m1) / (T2^2 - T1^2) [N/m]."""
    _, t1 = stiffness(MASSES_KG[0], TABLE_B4)
    _, t2 = stiffness(MASSES_KG[1], TABLE_B5)
    return 4 * math.pi**2 * (MASSES_KG[1] - MASSES_KG[0]) / (t2**2 - t1**2)


def run(seed: int = 0, quick: bool = False) -> BenchResult:
    """The stiffness from each table and from both together, against the report's 250 and 215 N/m."""
    del seed, quick  # arithmetic on the report's data
    k1, t1 = stiffness(MASSES_KG[0], TABLE_B4)
    k2, t2 = stiffness(MASSES_KG[1], TABLE_B5)
    k_two = two_mass_stiffness()
    basis = "predicted"
    note = "k = m (2 pi / T)^2, T = mean time / 5"
    figures = [
        Figure("stiffness from Table B4 (680 g)", "N/m", "\"approximately 250 N/m\" (App. B)", REPORT_APPENDIX_N_PER_M,
               k1, f"{note}; T = {t1:.3f} s", basis=basis),
        Figure("stiffness from Table B5 (1080 g)", "N/m", "\"approximately 250 N/m\" (App. B)", REPORT_APPENDIX_N_PER_M,
               k2, f"{note}; T = {t2:.3f} s", basis=basis),
        Figure("stiffness from both (spring mass cancelled)", "N/m", "215 N/m (3.8.3, loading test)",
               REPORT_LOADING_N_PER_M, k_two, "k = 4 pi^2 (m2 - m1) / (T2^2 - T1^2)", basis=basis),
        Figure("period 215 N/m would give with 680 g", "s", "Table B4: 5.92 s per 5 = 1.18 s", t1,
               2 * math.pi * math.sqrt(MASSES_KG[0] / REPORT_LOADING_N_PER_M), "T = 2 pi sqrt(m / k)", basis=basis),
    ]

    def plot(fig: object) -> None:
        ax = fig.subplots(1, 1)  # type: ignore[attr-defined]
        ks = np.linspace(5, 300, 300)
        for m, t, label in ((MASSES_KG[0], t1, "680 g"), (MASSES_KG[1], t2, "1080 g")):
            ax.plot(ks, 2 * math.pi * np.sqrt(m / ks), label=f"T(k) for {label}")
            ax.axhline(t, ls=":", color="0.4")
        for k, label in ((REPORT_LOADING_N_PER_M, "215 N/m"), (REPORT_APPENDIX_N_PER_M, "250 N/m")):
            ax.axvline(k, ls="--", color="tab:red", lw=0.8)
            ax.text(k, ax.get_ylim()[1] * 0.9, label, fontsize=8)
        ax.set_xlabel("spring stiffness k [N/m]")
        ax.set_ylabel("period T [s]")
        ax.set_title("Report Tables B4/B5 (dotted: measured periods) against the stated stiffness")
        ax.legend(fontsize=8)

    return BenchResult("spring-calibration", figures,
                       {"table_b4_s": np.array(TABLE_B4), "table_b5_s": np.array(TABLE_B5)}, plot,
                       {"k_680g_n_per_m": k1, "k_1080g_n_per_m": k2, "k_two_mass_n_per_m": k_two,
                        "period_680g_s": t1, "period_1080g_s": t2})
