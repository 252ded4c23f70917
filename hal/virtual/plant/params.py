"""Plant parameters (motor, driver, transmission, foot, friction, stops, spring bench) and their loader."""

from __future__ import annotations

import logging
import math
from dataclasses import dataclass, fields
from pathlib import Path
from typing import Any

logger = logging.getLogger(__name__)

#: Name of the packaged profile in the repository's ``profiles/`` directory.
DEFAULT_PROFILE_NAME = "plant_ak60_6.toml"

# field name -> (TOML table, lowest allowed, highest allowed). Ranges are plausibility bounds, wide
# enough for other motors/feet but tight enough to catch unit slips (g*cm^2 vs kg*m^2, mOhm vs Ohm).
_RANGES: dict[str, tuple[str, float, float]] = {
    "supply_voltage_v": ("motor", 1.0, 100.0),
    "kv_rpm_per_v": ("motor", 1.0, 5000.0),
    "kt_nm_per_a": ("motor", 1e-3, 2.0),
    "ke_v_s_per_rad": ("motor", 1e-3, 2.0),
    "phase_resistance_ohm": ("motor", 1e-3, 100.0),
    "phase_inductance_h": ("motor", 1e-7, 1e-1),
    "pole_pairs": ("motor", 1, 100),
    "rotor_inertia_kg_m2": ("motor", 1e-8, 1e-2),
    "peak_current_a": ("motor", 0.1, 500.0),
    "current_time_constant_s": ("driver", 1e-6, 0.1),
    "brake_speed_scale_rad_s": ("driver", 1e-3, 1e3),
    "gearbox_ratio": ("transmission", 1.0, 1000.0),
    "belt_ratio": ("transmission", 0.1, 100.0),
    "belt_driver_pitch_diameter_m": ("transmission", 1e-3, 1.0),
    "belt_driven_pitch_diameter_m": ("transmission", 1e-3, 1.0),
    "gearbox_efficiency": ("transmission", 0.1, 1.0),
    "belt_efficiency": ("transmission", 0.1, 1.0),
    "efficiency_backdriven": ("transmission", 0.1, 1.0),
    "actuator_output_inertia_kg_m2": ("transmission", 0.0, 1.0),
    "ankle_pulley_inertia_kg_m2": ("transmission", 0.0, 1.0),
    "backlash_deg": ("transmission", 0.0, 10.0),
    "foot_inertia_kg_m2": ("foot", 1e-5, 10.0),
    "foot_mass_kg": ("foot", 0.0, 50.0),
    "foot_com_distance_m": ("foot", 0.0, 1.0),
    "foot_damping_nm_s_per_rad": ("foot", 0.0, 100.0),
    "gravity_m_s2": ("foot", 0.0, 30.0),
    "com_angle_at_zero_rad": ("foot", -math.pi, math.pi),
    "toe_lever_m": ("foot", 0.01, 1.0),
    "actuator_backdrive_torque_nm": ("friction", 0.0, 100.0),
    "coulomb_friction_nm": ("friction", 0.0, 100.0),
    "stop_min_rad": ("stops", -math.pi, 0.0),
    "stop_max_rad": ("stops", 0.0, math.pi),
    "stop_stiffness_nm_per_rad": ("stops", 0.0, 1e6),
    "stop_damping_nm_s_per_rad": ("stops", 0.0, 1e4),
    "spring_rate_n_per_m": ("spring_bench", 0.0, 1e6),
    "spring_lever_m": ("spring_bench", 0.0, 1.0),
    "spring_offset_rad": ("spring_bench", -math.pi, math.pi),
    "load_masses_kg": ("spring_bench", 0.0, 100.0),
    "load_lever_m": ("spring_bench", 0.0, 1.0),
    "parallel_stiffness_nm_per_rad": ("spring", 0.0, 2000.0),
    "parallel_engage_rad": ("spring", -math.pi / 6, math.pi / 6),
    "parallel_two_sided": ("spring", 0, 1),
    # opt-in imperfections the fit's model lacks (hal/virtual/plant/imperfections.py): 0 = off
    "stribeck_peak_nm": ("friction", 0.0, 100.0),
    "stribeck_speed_rad_s": ("friction", 1e-4, 100.0),
    "ripple_amplitude_nm": ("ripple", 0.0, 100.0),
    "ripple_periods_per_rev": ("ripple", 1.0, 10000.0),
    # belt compliance (hal/virtual/plant/belt.py): the belt's tension members as a spring; stiffness 0 = off
    "belt_stiffness_n_per_mm": ("belt", 0.0, 1e5),
    "belt_width_mm": ("belt", 1.0, 200.0),
    "belt_center_distance_m": ("belt", 1e-3, 2.0),
    "belt_damping_ratio": ("belt", 0.0, 2.0),
}
OPTIONAL = {"parallel_stiffness_nm_per_rad": 0.0, "parallel_engage_rad": 0.0, "parallel_two_sided": False,
            "backlash_deg": None, "efficiency_backdriven": None, "stribeck_peak_nm": 0.0,
            "stribeck_speed_rad_s": 0.02, "ripple_amplitude_nm": 0.0, "ripple_periods_per_rev": 140.0,
            "belt_stiffness_n_per_mm": 0.0, "belt_width_mm": 10.0, "belt_center_distance_m": 0.080,
            "belt_damping_ratio": 0.05}
"""Keys a plant profile may leave out, with their values then: [spring] (no parallel spring); backlash_deg None =
the bench imperfection's figure (profiles/bench_imperfections.toml [gearbox_backlash]); efficiency_backdriven None =
one efficiency as a torque gain in both power directions (see PlantParams.backdriven_torque_per_amp_nm); the
Stribeck friction's and the torque ripple's amplitudes 0 = none (hal/virtual/plant/imperfections.py); the belt's
stiffness 0 = a rigid belt (hal/virtual/plant/belt.py)."""
_BOOLS = ("parallel_two_sided",)

#: Relative mismatch allowed between ``belt_ratio`` and the ratio of the pitch diameters.
BELT_RATIO_TOLERANCE = 0.02


@dataclass(frozen=True)
class PlantParams:
    """Physical parameters of motor, driver, gearbox, belt, foot and bench, in SI units."""

    supply_voltage_v: float
    kv_rpm_per_v: float
    kt_nm_per_a: float
    ke_v_s_per_rad: float
    phase_resistance_ohm: float
    phase_inductance_h: float
    pole_pairs: int
    rotor_inertia_kg_m2: float
    peak_current_a: float
    current_time_constant_s: float
    brake_speed_scale_rad_s: float
    gearbox_ratio: float
    belt_ratio: float
    belt_driver_pitch_diameter_m: float
    belt_driven_pitch_diameter_m: float
    gearbox_efficiency: float
    belt_efficiency: float
    actuator_output_inertia_kg_m2: float
    ankle_pulley_inertia_kg_m2: float
    foot_inertia_kg_m2: float
    foot_mass_kg: float
    foot_com_distance_m: float
    foot_damping_nm_s_per_rad: float
    gravity_m_s2: float
    com_angle_at_zero_rad: float
    toe_lever_m: float
    actuator_backdrive_torque_nm: float
    coulomb_friction_nm: float
    stop_min_rad: float
    stop_max_rad: float
    stop_stiffness_nm_per_rad: float
    stop_damping_nm_s_per_rad: float
    spring_rate_n_per_m: float
    spring_lever_m: float
    spring_offset_rad: float
    load_masses_kg: tuple[float, ...]
    load_lever_m: float
    # the parallel spring at the ankle (design profiles, docs/design.md "Parallel spring"): -k (theta - theta_e)
    # beyond theta_e, dorsiflexion side only unless two-sided; stiffness 0 = none
    parallel_stiffness_nm_per_rad: float = 0.0
    parallel_engage_rad: float = 0.0
    parallel_two_sided: bool = False
    # gearbox free play at the actuator (gearbox) output, degrees; None: the bench imperfection's figure
    backlash_deg: float | None = None
    # the transmission's (gearbox x belt) efficiency when the ankle drives the rotor (power into the motor);
    # None: `efficiency` applied as the same torque gain in both directions (docs/plant.md, "Efficiency")
    efficiency_backdriven: float | None = None
    # opt-in imperfections (hal/virtual/plant/imperfections.py, docs/plant.md "Imperfections the fit does not
    # model"): friction above the Coulomb friction at zero speed, decaying as exp(-(w / speed)^2) (ankle side);
    # a torque ripple of this amplitude at the ankle, sinusoidal in the rotor angle; amplitudes 0 = off
    stribeck_peak_nm: float = 0.0
    stribeck_speed_rad_s: float = 0.02
    ripple_amplitude_nm: float = 0.0
    ripple_periods_per_rev: float = 140.0
    # belt compliance (hal/virtual/plant/belt.py, docs/plant.md): the tension members' stiffness per mm of belt width
    # (N per unit strain per mm), the belt's width, the pulleys' centre distance and the belt mode's damping
    # ratio; stiffness 0 = a rigid belt (off)
    belt_stiffness_n_per_mm: float = 0.0
    belt_width_mm: float = 10.0
    belt_center_distance_m: float = 0.080
    belt_damping_ratio: float = 0.05

    def __post_init__(self) -> None:
        """Check every value against its allowed range and the cross-field rules."""
        validate_plant_params(self)

    @property
    def total_ratio(self) -> float:
        """Motor revolutions per ankle revolution, N = gearbox_ratio * belt_ratio."""
        return self.gearbox_ratio * self.belt_ratio

    @property
    def efficiency(self) -> float:
        """Transmission efficiency from rotor to ankle (gearbox times belt)."""
        return self.gearbox_efficiency * self.belt_efficiency

    @property
    def output_torque_per_amp_nm(self) -> float:
        """Ankle torque per ampere of q-axis current: Kt * N * efficiency."""
        return self.kt_nm_per_a * self.total_ratio * self.efficiency

    @property
    def backdriven_torque_per_amp_nm(self) -> float:
        """Ankle torque per ampere while the ankle drives the rotor (motor torque against the motion).

        Power through the transmission loses a share in either direction: driving, the ankle gets
        eta_fwd Kt N i; backdriven, holding the rotor's Kt i takes Kt N i / eta_back at the ankle, so the motor
        receives eta_back of the ankle's power. Without ``efficiency_backdriven`` the forward gain serves both
        directions (the motor then receives 1 / eta_fwd of the ankle's power, more than is put in).
        """
        if self.efficiency_backdriven is None:
            return self.output_torque_per_amp_nm
        return self.kt_nm_per_a * self.total_ratio / self.efficiency_backdriven

    def output_torque_nm(self, current_a: float, direction: int) -> float:
        """The motor's torque at the ankle for q current and the ankle's direction of motion (+1/-1, 0 at rest)."""
        backdriven = current_a * direction < 0.0
        return (self.backdriven_torque_per_amp_nm if backdriven else self.output_torque_per_amp_nm) * current_a

    @property
    def reflected_inertia_kg_m2(self) -> float:
        """Transmission inertia seen at the ankle: J_m N^2 + J_out belt^2 + J_pulley."""
        return (
            self.rotor_inertia_kg_m2 * self.total_ratio**2
            + self.actuator_output_inertia_kg_m2 * self.belt_ratio**2
            + self.ankle_pulley_inertia_kg_m2
        )

    @property
    def foot_output_inertia_kg_m2(self) -> float:
        """Foot inertia about the ankle axis: J_c + m d^2."""
        return self.foot_inertia_kg_m2 + self.foot_mass_kg * self.foot_com_distance_m**2

    @property
    def output_inertia_kg_m2(self) -> float:
        """Total inertia at the ankle without bench load: foot plus reflected transmission."""
        return self.foot_output_inertia_kg_m2 + self.reflected_inertia_kg_m2

    @property
    def gravity_moment_nm(self) -> float:
        """Largest gravity torque of the foot, m g d."""
        return self.foot_mass_kg * self.gravity_m_s2 * self.foot_com_distance_m

    @property
    def static_friction_nm(self) -> float:
        """Breakaway friction at the ankle: the actuator's back-drive torque times the belt ratio."""
        return self.actuator_backdrive_torque_nm * self.belt_ratio

    def parallel_spring_torque_nm(self, angle_rad: float) -> float:
        """The parallel spring's moment at the ankle: -k (theta - theta_e) where engaged, else 0."""
        from hal.virtual.plant.integrator import parallel_spring

        return -parallel_spring(self.parallel_stiffness_nm_per_rad, self.parallel_engage_rad, self.parallel_two_sided,
                                angle_rad)

    @property
    def belt_span_m(self) -> float:
        """Length of each free span of the belt: the pulleys' common tangent, sqrt(C^2 - (R - r)^2)."""
        dr = 0.5 * (self.belt_driven_pitch_diameter_m - self.belt_driver_pitch_diameter_m)
        return math.sqrt(self.belt_center_distance_m**2 - dr * dr)

    @property
    def belt_stiffness_nm_per_rad(self) -> float:
        """The belt's torsional stiffness at the ankle pulley, both spans preloaded: 2 (EA / L) r_ankle^2; 0 = rigid
        (hal/virtual/plant/belt.py)."""
        if self.belt_stiffness_n_per_mm == 0.0:
            return 0.0
        ea_n = self.belt_stiffness_n_per_mm * self.belt_width_mm
        r = 0.5 * self.belt_driven_pitch_diameter_m
        return 2.0 * ea_n / self.belt_span_m * r * r

    @property
    def spring_stiffness_nm_per_rad(self) -> float:
        """Bench spring as a torsional stiffness at the ankle, k_l = k * lever^2."""
        return self.spring_rate_n_per_m * self.spring_lever_m**2


def _range_error(key: str, value: object, lo: float, hi: float, where: str = "") -> ValueError:
    """Build the ValueError that names a bad parameter, its value and the allowed range."""
    table = _RANGES[key][0] if key in _RANGES else "?"
    suffix = f" in {where}" if where else ""
    return ValueError(
        f"plant parameter {table}.{key} = {value!r} is outside the allowed range [{lo}, {hi}]{suffix}")


def validate_plant_params(p: PlantParams) -> None:
    """Raise ValueError naming the key, value and allowed range of the first bad parameter."""
    for f in fields(p):
        table, lo, hi = _RANGES[f.name]
        value = getattr(p, f.name)
        if f.name in _BOOLS:
            if not isinstance(value, bool):
                raise ValueError(f"plant parameter {table}.{f.name} = {value!r} must be true or false")
            continue
        if value is None and f.name in OPTIONAL:
            continue
        values = value if isinstance(value, tuple) and f.name == "load_masses_kg" else (value,)  # the one list
        for v in values:
            bad_type = isinstance(v, bool) or not isinstance(v, (int, float))
            if bad_type or not math.isfinite(v) or not lo <= v <= hi:
                raise _range_error(f.name, value, lo, hi)
        if f.name == "pole_pairs" and not isinstance(value, int):
            raise ValueError(
                f"plant parameter {table}.pole_pairs = {value!r} must be an integer in [{lo}, {hi}]")
    if p.coulomb_friction_nm > p.static_friction_nm:
        raise ValueError(
            f"plant parameter friction.coulomb_friction_nm = {p.coulomb_friction_nm!r} must not exceed the "
            f"static friction actuator_backdrive_torque_nm * belt_ratio = {p.static_friction_nm!r} "
            f"(allowed range [0, {p.static_friction_nm}])"
        )
    diameter_ratio = p.belt_driven_pitch_diameter_m / p.belt_driver_pitch_diameter_m
    lo_r, hi_r = diameter_ratio * (1 - BELT_RATIO_TOLERANCE), diameter_ratio * (1 + BELT_RATIO_TOLERANCE)
    if not lo_r <= p.belt_ratio <= hi_r:
        raise ValueError(
            f"plant parameter transmission.belt_ratio = {p.belt_ratio!r} disagrees with the pitch diameters "
            f"(ratio {diameter_ratio:.4f}); allowed range [{lo_r:.4f}, {hi_r:.4f}]"
        )
    reach = 0.5 * (p.belt_driven_pitch_diameter_m + p.belt_driver_pitch_diameter_m)
    if p.belt_stiffness_n_per_mm > 0.0 and not p.belt_center_distance_m > reach:
        raise ValueError(
            f"plant parameter belt.belt_center_distance_m = {p.belt_center_distance_m!r} puts the pulleys into each "
            f"other (pitch radii {reach:.4f} m together); allowed range ({reach:.4f}, 2.0]"
        )
    if p.stop_min_rad >= p.stop_max_rad:
        raise ValueError(
            f"plant parameter stops.stop_min_rad = {p.stop_min_rad!r} must be below "
            f"stop_max_rad = {p.stop_max_rad!r}"
        )


def default_profile_path() -> Path:
    """Path of the packaged profile ``plant_ak60_6.toml`` (package ``profiles``)."""
    from profiles import profile_path

    return profile_path(DEFAULT_PROFILE_NAME)


def plant_params_from_mapping(data: dict[str, Any], where: str = "") -> PlantParams:
    """Build PlantParams from a TOML-shaped mapping of tables; ValueError names missing/unknown keys."""
    at = f" {where}" if where else ""
    values: dict[str, Any] = {}
    for table_name, table in data.items():
        if not isinstance(table, dict):
            raise ValueError(f"plant profile{at}: top-level key {table_name!r} must be a table")
        for key, value in table.items():
            spec = _RANGES.get(key)
            if spec is None or spec[0] != table_name:
                raise ValueError(f"plant profile{at}: unknown key {table_name}.{key}")
            if isinstance(value, list):
                value = tuple(value)
            elif isinstance(value, int) and not isinstance(value, bool) and key != "pole_pairs" and key not in _BOOLS:
                value = float(value)
            values[key] = value
    missing = [f"{_RANGES[n][0]}.{n}" for n in _RANGES if n not in values and n not in OPTIONAL]
    if missing:
        raise ValueError(f"plant profile{at}: missing keys {', '.join(missing)}")
    if not isinstance(values["load_masses_kg"], tuple):
        lo, hi = _RANGES["load_masses_kg"][1:]
        raise _range_error("load_masses_kg", values["load_masses_kg"], lo, hi, where)
    try:
        return PlantParams(**values)
    except ValueError as exc:
        raise ValueError(f"{exc} in {where}" if where else str(exc)) from None


def load_plant_params(path: str | Path | None = None) -> PlantParams:
    """Load and validate a plant profile (default: the packaged AK60-6 profile)."""
    profile = Path(path) if path is not None else default_profile_path()
    from profiles import read_toml

    data = read_toml(profile, "plant profile")
    logger.debug("loaded plant profile %s", profile)
    return plant_params_from_mapping(data, where=str(profile))
