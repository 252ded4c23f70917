"""The plant's state records: the integrated state tuple, everything observable at one instant, and the step
integrated ahead of the committed one (hal/virtual/plant/model.py's `Plant` makes and reads them)."""

from __future__ import annotations

from dataclasses import dataclass

from mypy_extensions import mypyc_attr

#: (angle [rad], velocity [rad/s], q current [A], friction mode: +1/-1 sliding that way, 0 stuck, belt stretch [rad],
#: its rate [rad/s]): the ankle's, and the motor side's lead over the ankle at the ankle pulley (0, 0 with a rigid
#: belt; hal/virtual/plant/belt.py)
State = tuple[float, float, float, int, float, float]


@dataclass(frozen=True)
class PlantState:
    """Everything observable of the plant at one instant (SI, ankle/output side unless named motor)."""

    t_s: float
    output_angle_rad: float
    output_velocity_rad_s: float
    output_accel_rad_s2: float
    motor_angle_rad: float
    motor_velocity_rad_s: float
    current_q_a: float
    current_command_a: float
    motor_torque_nm: float  # electromagnetic torque on the rotor, Kt * i_q
    output_torque_nm: float  # the motor's torque at the ankle: Kt i_q N eta driving, Kt i_q N / eta_back backdriven
    external_torque_nm: float
    energy_j: float
    powered: bool
    stuck: bool
    in_contact: bool


@mypyc_attr(free_list_len=1, acyclic=True)  # one made per step ahead: allocation from a free list, no GC
class StepAhead:
    """The next grid step integrated ahead (not committed), for queries inside it and the next commit."""

    def __init__(self, t0: float, k: int, x1: State, a0: float, a1: float, target_a: float) -> None:
        """The step k of the grid that starts at t0: state at its end, accelerations at both ends, target."""
        self.t0 = t0
        self.k = k
        self.x1 = x1  # state at the next grid point
        self.a0 = a0  # acceleration at the step's start
        self.a1 = a1  # acceleration at the step's end
        self.target_a = target_a  # the current target held over the step

    def starts(self, t0: float, k: int) -> bool:
        """Whether this is step k of the grid that starts at t0."""
        return self.k == k and self.t0 == t0
