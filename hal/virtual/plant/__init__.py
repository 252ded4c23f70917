"""Plant of the virtual bench: AK60-6 motor and driver, 6:1 gearbox, 4.67:1 belt, foot, bench fixtures."""

from hal.virtual.plant.fixtures import (
    Fixture,
    FixtureKind,
    TorqueProfile,
    backdrive,
    impulse,
    spring_bench,
    suspended,
)
from hal.virtual.plant.model import MAX_STEP_S, Plant, PlantState
from hal.virtual.plant.params import PlantParams, default_profile_path, load_plant_params

__all__ = [
    "MAX_STEP_S",
    "Fixture",
    "FixtureKind",
    "Plant",
    "PlantParams",
    "PlantState",
    "TorqueProfile",
    "backdrive",
    "default_profile_path",
    "impulse",
    "load_plant_params",
    "spring_bench",
    "suspended",
]
