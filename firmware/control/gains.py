"""Controller parameters as given in a profile: PID gains and the feed-forward's physical parameters.

Interpreted on purpose (docs/compiled.md, "Values checked as given"); the compiled controllers in
:mod:`firmware.control.pid` read them.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from firmware.control.validation import check_range

__all__ = ["FeedforwardParams", "PidGains"]


@dataclass(frozen=True)
class PidGains:
    """PID gains: kp [1/unit], ki [1/(unit s)], kd [s/unit], derivative filter time constant [s]."""

    kp: float
    ki: float = 0.0
    kd: float = 0.0
    derivative_tau_s: float = 0.0

    def __post_init__(self) -> None:
        """Validate that every gain and the filter time constant are finite and non-negative."""
        for name in ("kp", "ki", "kd", "derivative_tau_s"):
            check_range(name, getattr(self, name), 0.0, math.inf, hi_open=True)


@dataclass(frozen=True)
class FeedforwardParams:
    """Physical parameters of the gravity + inertia feed-forward, all at the ankle (output) axis."""

    inertia_kg_m2: float
    mass_kg: float
    lever_m: float
    torque_constant_nm_per_a: float
    gear_ratio: float
    efficiency: float
    gravity_m_s2: float = 9.8
    # a parallel spring at the ankle (a design profile's, docs/design.md): its moment -k (theta - theta_e) beyond the
    # engagement angle (dorsiflexion side only unless two-sided) is taken off what the motor is asked; 0 = none
    parallel_stiffness_nm_per_rad: float = 0.0
    parallel_engage_deg: float = 0.0
    parallel_two_sided: bool = False
    # the transmission's efficiency when the ankle drives the rotor (a design profile's: the planetary's by its
    # meshing losses x the belt's, hal/virtual/plant/transmission.py); None: `efficiency` in both directions
    efficiency_backdriven: float | None = None

    def __post_init__(self) -> None:
        """Validate the parameters (positive, efficiency in (0, 1], the spring's stiffness and angle)."""
        check_range("parallel_stiffness_nm_per_rad", self.parallel_stiffness_nm_per_rad, 0.0, 2000.0, unit="N m/rad")
        check_range("parallel_engage_deg", self.parallel_engage_deg, -30.0, 30.0, unit="deg")
        if not isinstance(self.parallel_two_sided, bool):
            raise ValueError(f"parallel_two_sided = {self.parallel_two_sided!r} is not allowed: must be true or false")
        for name in ("inertia_kg_m2", "mass_kg", "lever_m", "gravity_m_s2"):
            check_range(name, getattr(self, name), 0.0, math.inf, hi_open=True)
        for name in ("torque_constant_nm_per_a", "gear_ratio"):
            check_range(name, getattr(self, name), 0.0, math.inf, lo_open=True, hi_open=True)
        check_range("efficiency", self.efficiency, 0.0, 1.0, lo_open=True)
        if self.efficiency_backdriven is not None:
            check_range("efficiency_backdriven", self.efficiency_backdriven, 0.0, 1.0, lo_open=True)

    @property
    def backdriven_share(self) -> float:
        """The current a moment against the motion takes, as a share of what the driving efficiency would ask.

        Driving, the ankle gets Kt N eta_fwd per ampere; backdriven, holding the rotor's Kt i takes Kt N i / eta_back
        at the ankle, so a moment M against the motion needs M eta_back / (Kt N) = eta_fwd eta_back of the driving
        current (the plant's rule, hal/virtual/plant/params.py backdriven_torque_per_amp_nm). 1 without
        ``efficiency_backdriven``.

        >>> round(FeedforwardParams(0.05, 1.0, 0.1, 0.1, 28.0, 0.855, efficiency_backdriven=0.853).backdriven_share, 6)
        0.729315
        """
        if self.efficiency_backdriven is None:
            return 1.0
        return self.efficiency * self.efficiency_backdriven
