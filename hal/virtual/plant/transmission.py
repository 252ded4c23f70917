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

__all__ = ["BELT_RATED_N_PER_INCH", "BELT_RATED_N_PER_MM", "BELT_WIDTHS_MM", "MAX_SINGLE_STAGE_RATIO", "belt_tension_n",
           "belt_width_mm", "planetary_backdriven_efficiency", "planetary_stages", "rated_belt_tension_n"]

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
"""Stock widths per pitch (mm), narrowest first [I], not checked against a maker's stock list (none was reachable
here; the 5 mm pitch's 9, 15 and 25 mm are the standard widths a 5 mm HTD belt is sold in, XRobots/openDogV3 issue
12); a design's belt is the widest unless it names one (the design search checks the belt at its best: a narrower
belt only lowers the rating)."""

BELT_RATED_N_PER_INCH: dict[float, float] = {2.0: 111.0, 3.0: 507.0, 5.0: 712.0, 8.0: 1690.0}
"""Allowable working tension per inch (25.4 mm) of belt width, per pitch, of a neoprene GT (GT2/GT3 profile) belt
with fibreglass cord: SDP/SI (Stock Drive Products / Sterling Instrument), *Handbook of Timing Belts, Pulleys, Chains
and Sprockets*, Technical Section (sdp-si.com/D820/PDFS/Technical-Section.pdf), Table 3 "Allowable Working Tension
of Different Belt Constructions" (the same table: HTD 3M 285 N, 5M 454 N, 8M 792 N; MXL 80 N, XL 125 N). Read
through two independent secondary transcriptions of that table, not from the PDF itself. Cross-check against the
same handbook's rated-torque table: a 20-groove 2 mm GT pulley (12.73 mm pitch diameter) with a 6 mm belt is rated
about 0.18 N m at 10 rpm, and 111 N x 6 / 25.4 x 6.37 mm = 0.167 N m (8 % below). They are held here against the
effective tension (tight minus slack side) that `belt_tension_n` gives; the tight side carries the installation
tension as well, which this check leaves out (its error is on the optimistic side)."""

MM_PER_INCH = 25.4
BELT_RATED_N_PER_MM: dict[float, float] = {pitch: n / MM_PER_INCH for pitch, n in BELT_RATED_N_PER_INCH.items()}
"""Allowable working tension per mm of belt width, per pitch (BELT_RATED_N_PER_INCH / 25.4): 4.37, 19.96, 28.03 and
66.54 N/mm for the 2, 3, 5 and 8 mm pitches."""


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
    """The belt's rated working tension (BELT_RATED_N_PER_MM x width).

    >>> round(rated_belt_tension_n(5.0, 25.0), 1)  # 712 N per inch x 25 / 25.4
    700.8
    """
    return BELT_RATED_N_PER_MM[pitch_mm] * width_mm


def belt_tension_n(actuator_torque_nm: float, driver_pitch_diameter_m: float) -> float:
    """The belt's effective (tight-side minus slack-side) tension carrying the actuator's output torque."""
    return abs(actuator_torque_nm) / (0.5 * driver_pitch_diameter_m)
