"""The actuator's mass for the design search: the catalogue motor's mass plus estimates of the belt stage and the
parallel spring (docs/design.md, "Actuator mass"). Housing, bearings, shafts and fasteners are left out: they
differ little between the designs searched, so the estimate ranks designs, it does not weigh a prosthesis.

* **Pulleys**: aluminium (2700 kg/m³) disks of their pitch diameter ``teeth x pitch / pi`` and a face of the belt
  width plus 2 mm; the driver solid, the driven one lightened to half its disk (spokes or pockets).
* **Belt**: a strip of the belt's density (1200 kg/m³, polyurethane or neoprene with cords), ``BELT_WIDTH_M``
  wide and ``0.75 x pitch`` thick, as long as the open-belt length at a centre distance that leaves
  ``CLEARANCE_M`` between the pulleys' pitch circles.
* **Spring**: the steel (7850 kg/m³, E = 206 GPa) that stores the spring's largest energy at a working stress of
  800 MPa, as a leaf of uniform strength in bending (a third of the uniform-tension energy density
  sigma² / 2E): about 66 J/kg. The largest energy is ``k (stop - engage)² / 2`` at the foot's mechanical stop
  (the plant's stops; the other stop too when the spring is two-sided).
"""

from __future__ import annotations

import math

__all__ = ["ALUMINIUM_KG_M3", "SPRING_J_PER_KG", "actuator_mass"]

ALUMINIUM_KG_M3 = 2700.0
BELT_KG_M3 = 1200.0
BELT_WIDTH_M = 0.015
CLEARANCE_M = 0.010
STEEL_KG_M3, STEEL_E_PA, SPRING_STRESS_PA = 7850.0, 206e9, 800e6
SPRING_J_PER_KG = SPRING_STRESS_PA ** 2 / (2.0 * STEEL_E_PA) / 3.0 / STEEL_KG_M3
"""Energy a leaf spring of uniform strength stores per kg of steel at the working stress (about 66 J/kg)."""


def _disk_kg(diameter_m: float, fill: float) -> float:
    return ALUMINIUM_KG_M3 * math.pi * diameter_m ** 2 / 4.0 * (BELT_WIDTH_M + 0.002) * fill


def actuator_mass(motor_kg: float, driver_teeth: int, driven_teeth: int, pitch_mm: float, spring_nm_per_rad: float,
                  engage_deg: float, sided: str, stop_min_rad: float, stop_max_rad: float) -> dict[str, float]:
    """{motor_kg, transmission_kg, spring_kg, actuator_kg} of a design (kg, rounded to grams).

    >>> m = actuator_mass(0.368, 12, 56, 5.0, 0.0, 0.0, "one", -0.5, 0.5)
    >>> m["motor_kg"], m["spring_kg"], 0.05 < m["transmission_kg"] < 0.2
    (0.368, 0.0, True)
    """
    pitch = pitch_mm / 1000.0
    d1, d2 = driver_teeth * pitch / math.pi, driven_teeth * pitch / math.pi
    centre = (d1 + d2) / 2.0 + CLEARANCE_M
    length = 2.0 * centre + math.pi * (d1 + d2) / 2.0 + (d2 - d1) ** 2 / (4.0 * centre)
    belt = BELT_KG_M3 * length * BELT_WIDTH_M * 0.75 * pitch
    transmission = _disk_kg(d1, 1.0) + _disk_kg(d2, 0.5) + belt
    spring = 0.0
    if spring_nm_per_rad > 0.0:
        engage = math.radians(engage_deg)
        travel = max(stop_max_rad - engage, 0.0)
        if sided == "two":
            travel = max(travel, engage - stop_min_rad)
        spring = 0.5 * spring_nm_per_rad * travel ** 2 / SPRING_J_PER_KG
    total = motor_kg + transmission + spring
    return {"motor_kg": round(motor_kg, 3), "transmission_kg": round(transmission, 3), "spring_kg": round(spring, 3),
            "actuator_kg": round(total, 3)}
