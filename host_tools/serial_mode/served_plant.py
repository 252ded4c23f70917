"""What `pafp emulate` serves: the plant, the motor's ratings and thermal model, its CAN ranges.

By default the packaged AK60-6 plant (``--plant``, ``--plant-seed``, ``--ideal`` as for `pafp run`). ``--motor
NAME`` puts a catalogue motor (profiles/motors/, or a motor profile's path) into it: Kt, Kv, R, L, rotor inertia,
pole pairs, peak current, gear ratio, back-drive torque (hal.virtual.plant.design.plant_params_for, with the
report's 30/140-tooth belt so that only the motor changes), its two-node winding model
(hal.virtual.plant.thermal) and its MIT ranges ([can_mit]). ``--profile DESIGN.toml`` serves a design profile's
[design]: its motor, belt and spring, as `pafp run --profile` builds its bench.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Any

from hal.virtual.plant.design import Design, load_design
from hal.virtual.plant.motors import MotorSpec, load_motor
from protocol.can_mit import MitLimits

__all__ = ["AMBIENT_C", "ServedPlant", "served_plant"]

AMBIENT_C = 25.0
"""The room the emulated motor starts in and relaxes to (as `pafp run`'s default --ambient)."""
REPORT_BELT = {"belt_driver_teeth": 30, "belt_driven_teeth": 140, "belt_pitch_mm": 2.0}
"""The report's belt (pitch diameters 19.10 and 89.13 mm, report 3.2.2), kept when only the motor is swapped."""


@dataclass(frozen=True)
class ServedPlant:
    """The bench options of the served plant (WallDevices / World arguments), its motor and its MIT ranges."""

    options: dict[str, Any]
    motor: MotorSpec
    limits: MitLimits

    def attach_thermal(self, meter: Any, ambient_c: float = AMBIENT_C) -> None:
        """Give the motor's meter this motor's winding model (the reported temperature follows it)."""
        from hal.virtual.plant.thermal import ThermalParams, WindingThermal

        meter.ambient_c = ambient_c
        meter.temp_fet_c = ambient_c
        meter.attach_thermal(WindingThermal(ThermalParams.from_motor(self.motor), ambient_c))


def served_plant(*, seed: int = 0, plant_seed: int | None = None, plant_file: Path | None = None,
                 ideal: tuple[str, ...] = (), motor: str | None = None, profile: Path | None = None) -> ServedPlant:
    """The plant `pafp emulate` serves; ValueError in one line for an unknown motor or a profile without [design]."""
    from host_tools.runner import RunConfig

    design = _design(motor, profile)
    options, _ = RunConfig(seed=seed, plant_seed=plant_seed, plant_file=plant_file, ideal=tuple(ideal),
                           design=design).bench_setup()
    spec = load_motor(design.motor if design is not None else "ak60_6")
    limits = MitLimits(spec.p_max_rad, spec.v_max_rad_s, spec.t_max_nm)
    keep = ("plant_params", "imu_config", "initial_angle_rad", "backlash_rad")
    return ServedPlant({k: options[k] for k in keep}, spec, limits)


def _design(motor: str | None, profile: Path | None) -> Design | None:
    if motor is not None and profile is not None:
        raise ValueError("--motor and --profile both name the motor: give one (a design profile's [design] has "
                         "its motor)")
    if profile is not None:
        design = load_design(profile)
        if design is None:
            raise ValueError(f"--profile {profile}: no [design] table (a design profile, profiles/designs/)")
        return design
    if motor is None:
        return None
    from hal.virtual.plant.design import design_from_mapping

    try:
        load_motor(motor)
    except (ValueError, OSError) as e:
        raise ValueError(f"--motor {motor!r}: {e}") from None
    return design_from_mapping({"motor": motor, **REPORT_BELT}, "--motor")
