"""A virtual Open Source Leg in process: opensourceleg's actuator, load cell, IMU and encoder interfaces on pafp's
physics (issue 37; extra ``pafp[osl]``).

:class:`VirtualLeg` is the bench: one plant (a design profile's motor, belt and spring; by default the adult design
that walks 80 kg, profiles/designs/adult_80kg.toml) walking under the ground's moment of ``body_mass_kg``, the
AK motor's drive in MIT mode (its current loop, meter and two-node winding model; hal.virtual.devices.ak60_can)
and the ground reaction under the foot. The classes below implement opensourceleg's public interfaces on it, so a
controller written against the OSL API runs unchanged:

* :class:`VirtualActuator` (``ActuatorBase``): CURRENT, POSITION, IMPEDANCE and IDLE modes. Every command is a MIT
  frame to the drive (protocol.can_mit: its ranges and 12-bit steps); position and impedance are the drive's own law
  ``t = kp (p_des - p) + kd (v_des - v) + t_ff`` at its 1 kHz loop, as a Dephy or T-motor drive runs impedance; the
  readings are the drive's replies (position, velocity, torque, temperature on the wire). ``update()`` sends the
  present command and advances the leg by one loop period: call it once per loop, as on the real leg.
* :class:`VirtualEncoder` (``EncoderBase``): the joint encoder, 4000 counts a revolution (the bench's).
* :class:`VirtualLoadcell` (``LoadcellBase``): the pylon's forces and moment from the ground reaction (ideal: no
  noise; emulation-only). OSL's convention: compression reads negative ``fz``.
* :class:`VirtualIMU` (``IMUBase``): the foot's angular rate and gravity in the foot's frame (ideal).

Time: ``clock="virtual"`` (default) advances the plant by exactly one period per update, deterministic per seed and
faster than real time; ``clock="wall"`` advances it to the wall clock at each update (the loop's real timing).
Angles: the joint angle is the plant's (dorsiflexion positive); ``gear_ratio`` is motor to joint (planetary x belt).
"""

from __future__ import annotations

import math
import time
from pathlib import Path
from typing import Any

from opensourceleg.actuators.base import (
    CONTROL_MODE_CONFIGS,
    CONTROL_MODES,
    MOTOR_CONSTANTS,
    ActuatorBase,
    ControlModeConfig,
    requires,
)
from opensourceleg.sensors.base import EncoderBase, IMUBase, LoadcellBase

from hal.can import CanFrame
from hal.virtual.devices.ak60_can import Ak60Can, Ak60CanConfig
from hal.virtual.devices.world import World
from hal.virtual.plant import Plant
from hal.virtual.plant.walking import walk
from host_tools.serial_mode.can_emulate import WallCanBus
from host_tools.serial_mode.served_plant import served_plant
from host_tools.walk import ground_reaction, walking_load
from profiles import profile_path
from protocol import can_mit

__all__ = ["DEFAULT_DESIGN", "VirtualActuator", "VirtualEncoder", "VirtualIMU", "VirtualLeg", "VirtualLoadcell"]

DEFAULT_DESIGN = "designs/adult_80kg.toml"
TICKS_PER_S = 1_000_000  # the leg's clock: microseconds
GAIT_START_S = 0.5  # the walker's first stride begins here (the leg settles under its own weight first)
G_M_S2 = 9.81
ENCODER_COUNTS = 4000


class VirtualLeg:
    """The bench behind the OSL classes (module docstring)."""

    def __init__(self, *, profile: Path | str | None = None, body_mass_kg: float = 80.0, speed: str = "free",
                 seed: int = 0, frequency_hz: int = 500, clock: str = "virtual") -> None:
        """Build the plant, the drive and the ground; ValueError in one line for a bad value."""
        if clock not in ("virtual", "wall"):
            raise ValueError(f"clock {clock!r} unknown: 'virtual' or 'wall'")
        if isinstance(frequency_hz, bool) or not isinstance(frequency_hz, int) or not 50 <= frequency_hz <= 1000:
            raise ValueError(f"frequency_hz {frequency_hz!r} out of range: an int in 50..1000")
        from firmware.config import load_firmware_config

        path = Path(profile) if profile is not None else profile_path(DEFAULT_DESIGN)
        served = served_plant(seed=seed, profile=path)
        self.stride_s = load_firmware_config(path).stride_s
        self.load = walking_load(body_mass_kg, self.stride_s, None, speed)
        self.load.bind(lambda: GAIT_START_S)
        self.ground = ground_reaction(self.load, speed)
        o = served.options
        self.params = o["plant_params"]
        self.world = World(Plant(self.params, walk(self.load), initial_angle_rad=o["initial_angle_rad"],
                                 backlash_rad=o["backlash_rad"]), TICKS_PER_S)
        self.motor = served.motor
        self._replies = WallCanBus()
        self.drive = Ak60Can(self.world, self._replies, Ak60CanConfig(driver_id=1, mode="mit", limits=served.limits))
        served.attach_thermal(self.drive.core.meter)
        self.frequency_hz = frequency_hz
        self.period = TICKS_PER_S // frequency_hz
        self.clock = clock
        self._wall0 = time.perf_counter()
        self.reply = can_mit.MitReply(1, 0.0, 0.0, 0.0)
        self.send(can_mit.ENTER_MOTOR_MODE)

    @property
    def now(self) -> int:
        """The leg's present tick (microseconds since it was built)."""
        return max(0, self.world.now)

    @property
    def t_s(self) -> float:
        """The leg's present time in seconds."""
        return self.now / TICKS_PER_S

    def send(self, data: bytes) -> None:
        """Put a MIT frame to the drive on the bus now."""
        self.drive.on_frame(CanFrame(1, data), self.now + 1)

    def step(self) -> None:
        """One loop period (virtual clock) or up to the wall clock; the newest reply becomes the reading."""
        target = (self.now + self.period if self.clock == "virtual"
                  else max(self.now + 1, round((time.perf_counter() - self._wall0) * TICKS_PER_S)))
        self.world.advance_to(target)
        for frame in self._replies.due(target):
            if frame.arbitration_id == can_mit.MASTER_ID and frame.data[0] == 1:
                self.reply = can_mit.decode_reply(frame.data, self.drive.limits)

    def joint_angle_rad(self) -> float:
        """The ankle's angle now (emulation-only ground truth)."""
        return self.world.plant.output_angle_rad(self.t_s)

    def joint_velocity_rad_s(self) -> float:
        """The ankle's angular velocity now (emulation-only ground truth)."""
        return self.world.plant.output_velocity_rad_s(self.t_s)


def _mode(entry: Any = None) -> ControlModeConfig:
    return ControlModeConfig(entry_callback=entry or (lambda a: None), exit_callback=lambda a: a._hold_zero())


class VirtualActuator(ActuatorBase):
    """opensourceleg's ActuatorBase on the leg's drive (module docstring)."""

    def __init__(self, leg: VirtualLeg, tag: str = "ankle", offline: bool = False, **kwargs: Any) -> None:
        """The leg's motor behind the joint: gear ratio planetary x belt, the catalogue motor's Kt and limits."""
        self.leg = leg
        p = leg.params
        self._planetary, self._belt = p.gearbox_ratio, p.belt_ratio
        self._kt = p.kt_nm_per_a
        super().__init__(tag=tag, gear_ratio=p.total_ratio, frequency=leg.frequency_hz, offline=offline,
                         motor_constants=MOTOR_CONSTANTS(MOTOR_COUNT_PER_REV=2**16, NM_PER_AMP=self._kt,
                                                         MAX_CASE_TEMPERATURE=80.0,
                                                         MAX_WINDING_TEMPERATURE=leg.motor.max_winding_c),
                         **kwargs)
        self._command = can_mit.MitCommand()
        self._k_b = (0.0, 0.0)  # impedance at the actuator's output (N m/rad, N m s/rad)
        self._position_gains = (50.0, 1.0)

    @property
    def _CONTROL_MODE_CONFIGS(self) -> CONTROL_MODE_CONFIGS:
        return CONTROL_MODE_CONFIGS(IDLE=_mode(), CURRENT=_mode(), POSITION=_mode(), IMPEDANCE=_mode(),
                                    TORQUE=_mode())

    def start(self) -> None:
        """Open and stream (the drive is in motor mode since the leg was built)."""
        self._is_open = self._is_streaming = True

    def stop(self) -> None:
        """Zero command, then the drive's exit frame (torque off)."""
        self._hold_zero()
        self.leg.send(can_mit.encode_command(self._command, self.leg.drive.limits))
        self.leg.send(can_mit.EXIT_MOTOR_MODE)
        self._is_open = self._is_streaming = False

    def update(self) -> None:
        """Send the present command, advance the leg one period, read the drive's newest reply."""
        self.leg.send(can_mit.encode_command(self._command, self.leg.drive.limits))
        self.leg.step()

    def _hold_zero(self) -> None:
        self._command = can_mit.MitCommand()

    def home(self, *args: Any, **kwargs: Any) -> None:
        """The drive's zero frame: the present position becomes 0."""
        self.leg.send(can_mit.SET_ZERO)
        self._is_homed = True

    # commands -------------------------------------------------------------------------------------------------
    def set_motor_voltage(self, value: float) -> None:
        """Not offered by a MIT-mode drive."""
        raise NotImplementedError("the virtual drive runs MIT mode: current, position or impedance")

    @requires(CONTROL_MODES.CURRENT, CONTROL_MODES.TORQUE)
    def set_motor_current(self, value: float) -> None:
        """q current in A: the drive's feed-forward torque kt x i x planetary."""
        self._command = can_mit.MitCommand(t_ff=value * self._kt * self._planetary)

    @requires(CONTROL_MODES.CURRENT, CONTROL_MODES.TORQUE)
    def set_motor_torque(self, value: float) -> None:
        """Motor torque in N m (kt x i)."""
        self.set_motor_current(value / self._kt)

    @requires(CONTROL_MODES.CURRENT, CONTROL_MODES.TORQUE)
    def set_output_torque(self, value: float) -> None:
        """Joint torque in N m."""
        self.set_motor_torque(value / self.gear_ratio)

    @requires(CONTROL_MODES.POSITION, CONTROL_MODES.IMPEDANCE)
    def set_motor_position(self, value: float) -> None:
        """Rotor angle in rad: the drive's p_des at its output, with the position or impedance gains."""
        kp, kd = self._k_b if self.mode == CONTROL_MODES.IMPEDANCE else self._position_gains
        self._command = can_mit.MitCommand(p_des=value / self._planetary, kp=kp, kd=kd)

    def set_motor_velocity(self, value: float) -> None:
        """Not offered here (the OSL API's velocity mode is not among this drive's)."""
        raise NotImplementedError("the virtual drive runs MIT mode: current, position or impedance")

    def set_current_gains(self, kp: float, ki: float, kd: float, ff: float) -> None:
        """The drive's current loop is its own (the plant's): nothing to set."""

    @requires(CONTROL_MODES.POSITION)
    def set_position_gains(self, kp: float, ki: float = 0.0, kd: float = 0.0, ff: float = 0.0) -> None:
        """The drive's position gains at its output (N m/rad, N m s/rad)."""
        self._position_gains = (float(kp), float(kd))

    def _set_impedance_gains(self, k: float, b: float) -> None:
        self._k_b = (float(k), float(b))

    @requires(CONTROL_MODES.IMPEDANCE)
    def set_output_impedance(self, k: float, b: float) -> None:
        """Joint stiffness (N m/rad) and damping (N m s/rad), scaled through the belt to the drive's output."""
        self._set_impedance_gains(k / self._belt**2, b / self._belt**2)

    @requires(CONTROL_MODES.IMPEDANCE)
    def set_motor_impedance(self, k: float, b: float) -> None:
        """Rotor-side stiffness and damping, scaled through the planetary to the drive's output."""
        self._set_impedance_gains(k * self._planetary**2, b * self._planetary**2)

    # readings (the drive's replies) ---------------------------------------------------------------------------
    @property
    def motor_position(self) -> float:
        """Rotor angle (rad) from the reply's output angle."""
        return self.leg.reply.p * self._planetary

    @property
    def motor_velocity(self) -> float:
        """Rotor speed (rad/s) from the reply."""
        return self.leg.reply.v * self._planetary

    @property
    def motor_voltage(self) -> float:
        """Not on the MIT reply."""
        raise NotImplementedError("the MIT reply carries no voltage")

    @property
    def motor_current(self) -> float:
        """q current (A) from the reply's torque."""
        return self.leg.reply.t / (self._kt * self._planetary)

    @property
    def motor_torque(self) -> float:
        """Motor torque (N m) from the reply's torque at the drive's output."""
        return self.leg.reply.t / self._planetary

    @property
    def case_temperature(self) -> float:
        """The reply's temperature (deg C)."""
        return float(self.leg.reply.temperature_c)

    @property
    def winding_temperature(self) -> float:
        """The winding model's temperature (deg C; emulation-only, not on the wire)."""
        return self.leg.drive.core.meter.temp_motor_c


class _OnTheLeg:
    """What the virtual sensors share: they read the leg; nothing to open or close."""

    _is_streaming = False

    def start(self) -> None:
        """Stream (nothing to open)."""
        self._is_streaming = True

    def stop(self) -> None:
        """Stop streaming (nothing to close)."""
        self._is_streaming = False

    @property
    def is_streaming(self) -> bool:
        """Whether start() was called (and not stop())."""
        return self._is_streaming


class VirtualEncoder(_OnTheLeg, EncoderBase):
    """The joint encoder on the ankle pulley: 4000 counts a revolution, velocity over the last update."""

    def __init__(self, leg: VirtualLeg, tag: str = "joint_encoder", offline: bool = False) -> None:
        """Reads the leg's ankle angle."""
        super().__init__(tag=tag, offline=offline)
        self.leg = leg
        self._pos = self._vel = 0.0
        self._t = -1.0

    def update(self) -> None:
        """Count the angle now; the velocity is the counted change over the time since the last update."""
        step = 2 * math.pi / ENCODER_COUNTS
        pos = math.floor(self.leg.joint_angle_rad() / step) * step
        t = self.leg.t_s
        if self._t >= 0 and t > self._t:
            self._vel = (pos - self._pos) / (t - self._t)
        self._pos, self._t = pos, t

    @property
    def data(self) -> Any:
        """(position rad, velocity rad/s)."""
        return self._pos, self._vel

    @property
    def position(self) -> float:
        """Joint angle (rad)."""
        return self._pos

    @property
    def velocity(self) -> float:
        """Joint angular velocity (rad/s)."""
        return self._vel


class VirtualLoadcell(_OnTheLeg, LoadcellBase):
    """The pylon load cell (module docstring: ideal, compression negative)."""

    def __init__(self, leg: VirtualLeg, tag: str = "loadcell", offline: bool = False) -> None:
        """Reads the leg's ground reaction."""
        super().__init__(tag=tag, offline=offline)
        self.leg = leg
        self._f = (0.0, 0.0, 0.0)

    def update(self, *args: Any, **kwargs: Any) -> None:
        """The ground reaction now."""
        self._f = self.leg.ground.at(self.leg.t_s)

    def calibrate(self, *args: Any, **kwargs: Any) -> None:
        """Ideal: nothing to calibrate."""

    def reset(self) -> None:
        """Ideal: nothing to reset."""

    @property
    def data(self) -> Any:
        """(fx, fy, fz, mx, my, mz)."""
        return self.fx, self.fy, self.fz, self.mx, self.my, self.mz

    @property
    def fx(self) -> float:
        """Fore-aft force (N)."""
        return -self._f[1]

    @property
    def fy(self) -> float:
        """Medio-lateral force: none in this sagittal model."""
        return 0.0

    @property
    def fz(self) -> float:
        """Axial force (N), compression negative."""
        return -self._f[0]

    @property
    def mx(self) -> float:
        """Frontal moment: none in this sagittal model."""
        return 0.0

    @property
    def my(self) -> float:
        """Sagittal moment (N m) of the vertical force about the ankle: force x CoP."""
        return self._f[0] * self._f[2]

    @property
    def mz(self) -> float:
        """Transverse moment: none in this sagittal model."""
        return 0.0

    @property
    def is_calibrated(self) -> bool:
        """Ideal: always."""
        return True


class VirtualIMU(_OnTheLeg, IMUBase):
    """An IMU on the foot (ideal): the foot's pitch rate and gravity in its frame (x forward, z up at 0 rad)."""

    def __init__(self, leg: VirtualLeg, tag: str = "foot_imu", offline: bool = False) -> None:
        """Reads the leg's foot."""
        super().__init__(tag=tag, offline=offline)
        self.leg = leg
        self._th = self._w = 0.0

    def update(self) -> None:
        """The foot's angle and rate now."""
        self._th, self._w = self.leg.joint_angle_rad(), self.leg.joint_velocity_rad_s()

    @property
    def data(self) -> Any:
        """(acc x, y, z m/s^2, gyro x, y, z rad/s)."""
        return self.acc_x, self.acc_y, self.acc_z, self.gyro_x, self.gyro_y, self.gyro_z

    @property
    def acc_x(self) -> float:
        """Gravity along the foot's forward axis (m/s^2)."""
        return -G_M_S2 * math.sin(self._th)

    @property
    def acc_y(self) -> float:
        """Lateral: 0."""
        return 0.0

    @property
    def acc_z(self) -> float:
        """Gravity along the foot's up axis (m/s^2)."""
        return G_M_S2 * math.cos(self._th)

    @property
    def gyro_x(self) -> float:
        """Roll rate: 0."""
        return 0.0

    @property
    def gyro_y(self) -> float:
        """Pitch rate (rad/s, dorsiflexion positive)."""
        return self._w

    @property
    def gyro_z(self) -> float:
        """Yaw rate: 0."""
        return 0.0
