"""What a controller sees each control period (`Observation`) and what it may return besides a current.

Compiled (setup.py): the control task refills one `Observation` every period, and a shipped controller
reads it every period. SI units on the output (ankle) side; a positive current drives the angle positive.
"""

from __future__ import annotations

__all__ = ["MotorCommand", "Observation"]


class Observation:
    """The controller's inputs for one control period (the firmware refills one object each period)."""

    def __init__(self) -> None:
        """All zero until the control task fills it."""
        self.t_s = 0.0  # time since boot
        self.dt_s = 0.0  # control period
        self.reference_rad = 0.0
        self.reference_velocity_rad_s = 0.0
        self.reference_acceleration_rad_s2 = 0.0
        self.angle_rad = 0.0  # the firmware's fused estimate (encoder + IMU)
        self.velocity_rad_s = 0.0  # encoder velocity, low-passed
        self.encoder_angle_rad = 0.0
        self.imu_pitch_rad = 0.0
        self.motor_current_a = 0.0  # measured, from the motor's last feedback
        self.gait_phase = 0.0  # 0..1 through the stride on the firmware's gait clock (0 before the gait)
        self.stance = False  # the firmware's load detector: the foot carries the body
        self.load_torque_nm = 0.0  # that detector's estimate of the external moment at the ankle
        # the ground sensors (load cell, heel/toe FSRs on the ADC), on boards that have them:
        self.ground_sensors_ok = False  # True while they are fitted and healthy: `stance` comes from them
        self.heel_contact = False  # heel FSR on
        self.toe_contact = False  # toe FSR on
        self.axial_force_n = 0.0  # load cell, compression positive
        self.sagittal_moment_nm = 0.0  # load cell, positive when the ground reaction is ahead of the pylon

    def __repr__(self) -> str:
        """Every field, for a user's print()."""
        names = ("t_s", "dt_s", "reference_rad", "reference_velocity_rad_s", "reference_acceleration_rad_s2",
                 "angle_rad", "velocity_rad_s", "encoder_angle_rad", "imu_pitch_rad", "motor_current_a",
                 "gait_phase", "stance", "load_torque_nm", "ground_sensors_ok", "heel_contact", "toe_contact",
                 "axial_force_n", "sagittal_moment_nm")
        return "Observation(" + ", ".join(f"{n}={getattr(self, n)!r}" for n in names) + ")"


class MotorCommand:
    """A command for a motor mode other than plain current: `brake=True` is the regenerative brake
    (VESC SET_CURRENT_BRAKE) at `current_a` (>= 0); `brake=False` is the same as returning the float."""

    def __init__(self, current_a: float, brake: bool = False) -> None:
        """Hold the current in amperes and the mode."""
        self.current_a = current_a
        self.brake = brake

    def __repr__(self) -> str:
        """The command as written."""
        return f"MotorCommand(current_a={self.current_a!r}, brake={self.brake!r})"
