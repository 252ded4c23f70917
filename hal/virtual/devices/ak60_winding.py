"""The AK drive's safe behaviours as the winding makes them: duty (phase short at 0), regenerative brake, handbrake.

Each law gives the q-axis current the drive makes at the present rotor angle and speed; the device model
(:mod:`hal.virtual.devices.ak60`) evaluates it every ``winding_period_s`` and hands it to the plant, whose
current lag then stands for the winding's own (docs/devices.md, "Safe behaviours"). Motor constants are the
plant profile's DC-equivalent ones (``i = (v - Ke w) / R``, phase-to-phase R and L):

* **duty d** (VESC ``COMM_SET_DUTY``, CubeMars CAN servo ``SET_DUTY``): the bridge holds ``v_q = d V_in`` and
  ``v_d = 0``. In the steady state of the d-q winding at electrical speed ``w_e = p w``
  (``v_d = R i_d - w_e L i_q``, ``v_q = R i_q + w_e L i_d + Ke w``)::

      i_q = (d V_in - Ke w) R / (R^2 + (w_e L)^2)

  At ``d = 0`` all three phases are shorted through the low-side switches: the back-EMF drives a current that
  brakes, ``Ke w / R`` at low speed, falling as ``1 / (w_e L / R)^2`` above ``w_e = R / L`` (the inductance
  carries the current into the d axis, where it makes no torque). On the AK60-6 ``R / L`` = 1464 rad/s
  electrical, 105 rad/s at the rotor, 3.8 rad/s (218 deg/s) at the ankle: the short's braking torque peaks
  there.
* **regenerative brake I** (``COMM_SET_CURRENT_BRAKE``, CAN servo ``SET_CURRENT_BRAKE``; VESC
  ``mc_interface_set_brake_current``): the current loop asks ``-sign(w) I``, but in braking the modulation
  is held between 0 and the back-EMF (energy only flows out of the motor), so the most it can get is the
  shorted winding's current at that speed: ``|i_q| = min(I, |i_short(w)|)``; at a reversal (``w = 0``) all
  phases are shorted and the current is 0.
* **handbrake I** (``COMM_SET_HANDBRAKE``; VESC ``mcpwm_foc_set_handbrake``): an open-loop current vector of
  magnitude I at a fixed electrical angle (VESC forces the phase to 0). The rotor's d axis at electrical angle
  ``theta_e`` sees ``i_q = -I sin(theta_e)``: a holding torque that grows with the angle from the held
  position up to ``Kt I`` at 90 electrical degrees and falls beyond, so a larger load slips the rotor to the
  next pole (360 electrical degrees = 1/p of a rotor turn). It is a position hold, not a brake.

The sources (VESC ``mcpwm_foc.c``, ``mc_interface.c``, ``timeout.c``; the CubeMars AK manual's servo-mode
command lists) are cited in docs/devices.md; the laws above are written from them, not copied.
"""

from __future__ import annotations

import math

__all__ = ["Winding"]


class Winding:
    """The motor's winding constants and the three laws (currents in A, rotor angle in rad, speed in rad/s)."""

    def __init__(self, ke_v_s_per_rad: float, r_ohm: float, l_h: float, pole_pairs: int) -> None:
        """Take the DC-equivalent back-EMF constant, the phase-to-phase R and L, and the pole pairs."""
        self.ke = ke_v_s_per_rad
        self.r_ohm = r_ohm
        self.l_h = l_h
        self.pole_pairs = pole_pairs

    def duty_current_a(self, duty: float, v_in_v: float, rotor_velocity_rad_s: float) -> float:
        """Steady q current with ``v_q = duty V_in``, ``v_d = 0`` at this rotor speed (duty 0: the phase short).

        >>> w = Winding(0.0716, 0.202, 138e-6, 14)
        >>> round(w.duty_current_a(0.0, 24.0, 10.0), 3)  # slow: close to -Ke w / R = -3.545 A
        -3.512
        >>> round(w.duty_current_a(0.0, 24.0, 300.0), 3)  # fast: -Ke w / R would be -106 A
        -11.517
        """
        r = self.r_ohm
        x = self.pole_pairs * rotor_velocity_rad_s * self.l_h
        return (duty * v_in_v - self.ke * rotor_velocity_rad_s) * r / (r * r + x * x)

    def brake_current_a(self, brake_a: float, rotor_velocity_rad_s: float) -> float:
        """The regenerative brake's q current: against the motion, at most the short-circuit current.

        >>> w = Winding(0.0716, 0.202, 138e-6, 14)
        >>> w.brake_current_a(2.0, 100.0), round(w.brake_current_a(2.0, 1.0), 4), w.brake_current_a(2.0, 0.0)
        (-2.0, -0.3544, 0.0)
        """
        short = self.duty_current_a(0.0, 0.0, rotor_velocity_rad_s)  # opposes the motion, 0 at rest
        limit = abs(brake_a)
        return -limit if short < -limit else limit if short > limit else short

    def handbrake_current_a(self, current_a: float, rotor_angle_rad: float) -> float:
        """The q component of a current vector of magnitude current_a held at electrical angle 0.

        >>> w = Winding(0.0716, 0.202, 138e-6, 14)
        >>> round(w.handbrake_current_a(5.0, math.pi / 2 / 14), 6)  # 90 electrical degrees: all of it, restoring
        -5.0
        """
        return -abs(current_a) * math.sin(self.pole_pairs * rotor_angle_rad)
