"""Transmission physics of a design: efficiency by power direction through a planetary stage and a belt, and the
belt's tension against its rating.

A planetary stage with the ring fixed, the sun driven and the carrier the output (the quasi-direct-drive
actuators' layout) has a ratio i = 1 + z_ring / z_sun. Its losses are those of the tooth meshes, which carry only
the power that flows through them in the carrier's frame (the "coupling power", (i - 1) / i of the input power).
With eta0 the meshing efficiency of the fixed-carrier train (the sun-planet-ring meshes, power flowing one way
through them), torque balance gives (H. W. Mueller, *Epicyclic Drive Trains*, Wayne State University Press 1982,
ch. 4; J. M. del Castillo, "The analytical expression of the efficiency of planetary gear trains", Mechanism and
Machine Theory 37 (2002) 197-214):

    driving   (sun in, carrier out):  eta_fwd  = (1 + (i - 1) eta0) / i
    backdriven (carrier in, sun out): eta_back = i / (1 + (i - 1) / eta0)

so eta_back follows from the catalogue's forward figure: eta0 = (i eta_fwd - 1) / (i - 1). For eta_fwd = 0.90 and
i = 6 or 10, eta0 = 0.88-0.89 and eta_back = 0.898: equal to eta_fwd to first order in the loss, far from
self-locking. A gearbox of a larger ratio is taken as two equal stages in series. A timing belt's losses
(bending hysteresis of the belt, tooth entry and exit) do not depend on which pulley drives [I]: eta_back = eta_fwd.

>>> round(planetary_backdriven_efficiency(0.90, 6.0), 4)
0.898
>>> round(planetary_backdriven_efficiency(1.0, 10.0), 4)
1.0
"""

from __future__ import annotations

import math

__all__ = ["BELT_RATED_N_PER_MM", "BELT_WIDTHS_MM", "MAX_SINGLE_STAGE_RATIO", "belt_tension_n", "belt_width_mm",
           "planetary_backdriven_efficiency", "planetary_stages", "rated_belt_tension_n"]

MAX_SINGLE_STAGE_RATIO = 10.0
"""Largest ratio built as one sun-planet-carrier stage [I]: a larger ratio needs planets too small for the sun
(catalogue single stages run from about 3:1 to 10:1); above it the gearbox is taken as equal stages in series."""


def planetary_stages(ratio: float) -> int:
    """How many equal stages a planetary gearbox of this ratio has (one up to MAX_SINGLE_STAGE_RATIO)."""
    if not ratio >= 1.0:
        raise ValueError(f"gear ratio {ratio!r} outside the allowed range [1, inf)")
    return max(1, math.ceil(math.log(ratio) / math.log(MAX_SINGLE_STAGE_RATIO) - 1e-9))


def planetary_backdriven_efficiency(efficiency: float, ratio: float) -> float:
    """The backdriven efficiency of a planetary gearbox from its forward efficiency and ratio (module docstring)."""
    if not 0.0 < efficiency <= 1.0:
        raise ValueError(f"gearbox efficiency {efficiency!r} outside the allowed range (0, 1]")
    n = planetary_stages(ratio)
    i = ratio ** (1.0 / n)
    if i == 1.0:
        return efficiency
    eta_stage = efficiency ** (1.0 / n)
    eta0 = (i * eta_stage - 1.0) / (i - 1.0)
    if eta0 <= 0.0:
        raise ValueError(f"gearbox efficiency {efficiency!r} is too low for a {ratio:g}:1 planetary: its meshes "
                         f"would be lossier than the whole stage (allowed range ({1.0 / i:.3f}, 1] per stage)")
    return (i / (1.0 + (i - 1.0) / eta0)) ** n


BELT_WIDTHS_MM: dict[float, tuple[float, ...]] = {
    2.0: (6.0, 9.0, 12.0),
    3.0: (9.0, 15.0),
    5.0: (9.0, 15.0, 25.0),
    8.0: (20.0, 30.0),
}
"""Stock widths per pitch (mm), narrowest first [I]; a design's belt is the widest unless it names one (the design
search checks the belt at its best: a narrower belt only lowers the rating)."""
BELT_RATED_N_PER_MM: dict[float, float] = {2.0: 20.0, 3.0: 30.0, 5.0: 50.0, 8.0: 90.0}
"""Rated working tension per mm of belt width, per pitch [I]: ASSUMED stand-ins of the order of the belt makers'
low-speed ratings for glass-cord GT2 belts, NOT read from a maker's table. A 6 mm GT2 belt is rated 120 N here
against its breaking load of about 1 kN (FarmBot's acceptance test of its 6 mm GT2 belt: 100 kg - 20 kg hung
weight, genesis.farm.bot/v1.6/bom/drivetrain/belt). The only belt rating held with the project, the report's
(section 3.2.1: "Gates PowerGrip GT3 charts", 30 N m on its 19.1 mm driver pulley, 9 N m after a length factor of
0.3), is ~940 N of effective tension for a belt whose pitch and width the report leaves inconsistent (an "HTD
10 mm" belt of 36 teeth on pulleys of 2 mm pitch): it cannot give a rating per mm of a 5 mm pitch. What replaces
these: the rated torque tables of the Gates PowerGrip GT3 Drive Design Manual (2014, "Power Rating Tables": 5 mm
pitch pp. 46-47, 8 mm pp. 48-50; the 2 and 3 mm pitches in the PowerGrip GT2 manual no. 17195) by small-sprocket
grooves and rpm, with their width and length-correction factors, over the small sprocket's pitch radius."""


def belt_width_mm(pitch_mm: float, width_mm: float | None = None) -> float:
    """The belt's width: the given stock width of the pitch, or the pitch's widest."""
    widths = BELT_WIDTHS_MM[pitch_mm]
    if width_mm is None:
        return widths[-1]
    if width_mm not in widths:
        raise ValueError(f"belt width {width_mm!r} mm is not allowed for the {pitch_mm:g} mm pitch: one of "
                         f"{', '.join(f'{w:g}' for w in widths)}")
    return width_mm


def rated_belt_tension_n(pitch_mm: float, width_mm: float) -> float:
    """The belt's rated working tension (BELT_RATED_N_PER_MM x width)."""
    return BELT_RATED_N_PER_MM[pitch_mm] * width_mm


def belt_tension_n(actuator_torque_nm: float, driver_pitch_diameter_m: float) -> float:
    """The belt's effective (tight-side minus slack-side) tension carrying the actuator's output torque."""
    return abs(actuator_torque_nm) / (0.5 * driver_pitch_diameter_m)
