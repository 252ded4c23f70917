"""The report's design point -- 14 N*m at 55 rpm at the output (3.2, 3.2.1) -- against the actuator's limits.

From the plant profile (nominal): ankle torque per motor amp Kt N eta; the current and the motor speed the
design point needs; the bus voltage it needs (i R + Ke w_m, steady state); the firmware's current limit
(12 A), the supervisor's (20 A) and the motor's peak (22.7 A) as ankle torques; the maker's rated
(continuous) and peak torque and rated speed of the actuator, carried through the belt. Also the report's
1.5 safety-factor case, "21 Nm at 250 rpm" (3.2.1). Steady state, no inertia: a bound, not a run.
"""

from __future__ import annotations

import math

from firmware.config import load_firmware_config
from hal.virtual.plant import PlantParams, load_plant_params
from host_tools.benchtests.output import BenchResult, Figure

#: The readings of the report this test runs under (hal.virtual.plant.readings); the geometry is the bench's.
READINGS = {"geometry": "n/a", "driver": "n/a", "imu": "n/a"}
__all__ = ["run"]

DESIGN_TORQUE_NM = 14.0
DESIGN_RPM = 55.0
SAFETY_TORQUE_NM = 21.0
SAFETY_RPM = 250.0
#: Maker (cubemars_rich.csv via PROTOCOLS.md C): at the actuator's 6:1 output.
MAKER_RATED_NM = 3.0
MAKER_RATED_A = 6.5
MAKER_PEAK_NM = 9.0
MAKER_RATED_RPM = 420.0
MAKER_NO_LOAD_RPM = 560.0


def needs(p: PlantParams, torque_nm: float, rpm: float) -> dict[str, float]:
    """Current, motor speed and bus voltage a steady ankle torque at an ankle speed needs."""
    i = torque_nm / p.output_torque_per_amp_nm
    w_m = rpm * 2 * math.pi / 60 * p.total_ratio
    return {"current_a": i, "motor_rad_s": w_m, "voltage_v": i * p.phase_resistance_ohm + p.ke_v_s_per_rad * w_m,
            "actuator_rpm": rpm * p.belt_ratio}


def run(seed: int = 0, quick: bool = False, params: PlantParams | None = None) -> BenchResult:
    """The design point and the safety case against the current, voltage, torque and speed limits."""
    del seed, quick
    p = params if params is not None else load_plant_params()
    fw = load_firmware_config()
    d = needs(p, DESIGN_TORQUE_NM, DESIGN_RPM)
    sf = needs(p, SAFETY_TORQUE_NM, SAFETY_RPM)
    sf_in = needs(p, SAFETY_TORQUE_NM, SAFETY_RPM / p.belt_ratio)
    actuator_constant = p.kt_nm_per_a * p.gearbox_ratio * p.gearbox_efficiency
    belt = p.belt_ratio * p.belt_efficiency
    pred = "predicted"
    figures = [
        Figure("current for 14 N*m at the ankle", "A", "14 N*m at 55 rpm (3.2.1)", None, d["current_a"],
               f"Kt N eta = {p.output_torque_per_amp_nm:.3f} N*m/A", basis=pred),
        Figure("bus voltage for 14 N*m at 55 rpm", "V", "24 V supply", p.supply_voltage_v, d["voltage_v"],
               f"i R + Ke w_m, motor at {d['motor_rad_s']:.0f} rad/s", basis=pred),
        Figure("ankle torque at the firmware's current limit", "N*m", "design 14 N*m", DESIGN_TORQUE_NM,
               fw.current_limit_a * p.output_torque_per_amp_nm, f"{fw.current_limit_a:g} A (profiles/firmware.toml)",
               basis=pred),
        Figure("ankle torque at the supervisor's current limit", "N*m", "design 14 N*m", DESIGN_TORQUE_NM,
               fw.safety.current_limit_a * p.output_torque_per_amp_nm, f"{fw.safety.current_limit_a:g} A", basis=pred),
        Figure("ankle torque at the motor's peak current", "N*m", "design 14 N*m", DESIGN_TORQUE_NM,
               p.peak_current_a * p.output_torque_per_amp_nm, f"{p.peak_current_a:g} A (Table B2)", basis=pred),
        Figure("maker's rated (continuous) torque at the ankle", "N*m", "design 14 N*m", DESIGN_TORQUE_NM,
               MAKER_RATED_NM * belt, f"3 N*m x 14/3 = {MAKER_RATED_NM * p.belt_ratio:.1f} N*m exactly: the design "
               "point is the rated torque (the input pulley \"expected to transmit 3 Nm\", 3.2.2); below it only "
               "through the assumed belt loss", basis=f"assumed: belt efficiency {p.belt_efficiency:g} (catalogue)"),
        Figure("actuator output torque per amp", "N*m/A", f"maker {MAKER_RATED_NM:g} N*m / {MAKER_RATED_A:g} A",
               MAKER_RATED_NM / MAKER_RATED_A, actuator_constant,
               f"K_t x 6 x eta_gearbox = {p.kt_nm_per_a:g} x 6 x {p.gearbox_efficiency:g}: "
               f"{100 * (actuator_constant * MAKER_RATED_A / MAKER_RATED_NM - 1):.0f} % against the maker's pair "
               "(the profile argues the gap)",
               basis=f"assumed: gearbox efficiency {p.gearbox_efficiency:g} on top of Table B2's K_t"),
        Figure("current for 14 N*m with the maker's output constant", "A", "14 N*m at 55 rpm (3.2.1)", None,
               DESIGN_TORQUE_NM / (MAKER_RATED_NM / MAKER_RATED_A * belt), "3/6.5 N*m/A x belt ratio x belt "
               "efficiency", basis=f"assumed: belt efficiency {p.belt_efficiency:g}"),
        Figure("maker's peak torque at the ankle", "N*m", "21 N*m with safety factor 1.5 (3.2.1)", SAFETY_TORQUE_NM,
               MAKER_PEAK_NM * belt, "9 N*m x belt ratio x belt efficiency", basis=pred),
        Figure("actuator speed at 55 rpm at the ankle", "rpm", f"maker rated {MAKER_RATED_RPM:g} rpm", MAKER_RATED_RPM,
               d["actuator_rpm"], "within the rated speed", basis=pred),
        Figure("actuator speed for the safety case, 250 rpm read at the ankle", "rpm",
               f"maker no-load {MAKER_NO_LOAD_RPM:g} rpm", MAKER_NO_LOAD_RPM, sf["actuator_rpm"],
               f"needs {sf['voltage_v']:.0f} V: unreachable on 24 V",
               basis="assumed: \"21 Nm at 250 rpm\" (3.2.1) read as the ankle's speed"),
        Figure("bus voltage for the safety case, 250 rpm read at the input pulley", "V", "24 V supply",
               p.supply_voltage_v, sf_in["voltage_v"],
               f"{sf_in['current_a']:.1f} A at {SAFETY_RPM / p.belt_ratio:.1f} rpm at the ankle: reachable "
               f"(55 rpm x 14/3 = {DESIGN_RPM * p.belt_ratio:.0f} rpm at the input pulley)",
               basis="assumed: \"21 Nm at 250 rpm\" (3.2.1) read as the input pulley's speed"),
        Figure("firmware velocity limit as ankle speed", "rpm", "55 rpm (3.2.1)", DESIGN_RPM,
               fw.velocity_limit_rad_s * 60 / (2 * math.pi), f"{fw.velocity_limit_rad_s:g} rad/s", basis=pred),
    ]
    return BenchResult("design-point", figures, {}, None,
                       {"design": d, "safety_case": sf,
                        "safety_case_input_pulley_rpm": sf_in, "output_torque_per_amp_nm": p.output_torque_per_amp_nm})
