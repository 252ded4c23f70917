"""The virtual bench's true values of `pafp fit`'s parameters: emulation only, the yardstick of the fit's tests and
benchmarks, never the fit's input."""

from __future__ import annotations

import math
from pathlib import Path

from hal.virtual.plant import load_plant_params

__all__ = ["truth_of"]


def truth_of(plant: list[str], seed: int = 0) -> dict[str, float]:
    """The bench's true values of the fit parameters for `pafp run`'s plant options (["--plant", FILE] or
    ["--plant-seed", N]) and its `--seed` (the noise seed: it draws the foot's angle at power-up, the encoder's
    offset).

    The torques (inertia, damping, friction, gravity) are in the base profile's torque per ampere, as the fit
    reports them: the current is the bench's only torque measure, so the fit sees each torque over the true
    torque per ampere times the base's (docs/calibration.md: the torque constant's scale is not identifiable).
    Seed 7 draws a torque per ampere 0.11 % above the base's (Kt, gearbox and belt efficiencies): within the
    gravity moment's interval of about 0.07 % that is what tells the two apart. The rotor's Kt/J_m is relative to
    the base's (the fit's Kt is the base's).
    """
    from host_tools.runner import RunConfig

    cfg = RunConfig(seed=seed, plant_file=Path(plant[1]) if plant[0] == "--plant" else None,
                    plant_seed=int(plant[1]) if plant[0] == "--plant-seed" else None)
    options, _ = cfg.bench_setup()
    p = options["plant_params"]
    base = load_plant_params()
    k = base.output_torque_per_amp_nm / p.output_torque_per_amp_nm
    return {"output_inertia_kg_m2": k * p.output_inertia_kg_m2,
            "foot_damping_nm_s_per_rad": k * p.foot_damping_nm_s_per_rad,
            "coulomb_friction_nm": k * p.coulomb_friction_nm, "static_friction_nm": k * p.static_friction_nm,
            "gravity_moment_nm": k * p.gravity_moment_nm, "current_time_constant_s": p.current_time_constant_s,
            "backlash_deg": math.degrees(options["backlash_rad"]),
            "rotor_accel_scale": (p.kt_nm_per_a / p.rotor_inertia_kg_m2)
            / (base.kt_nm_per_a / base.rotor_inertia_kg_m2),
            "encoder_offset_deg": math.degrees(options["initial_angle_rad"])}
