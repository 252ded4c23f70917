"""The firmware's task bodies and the state they share: what runs in each job of the task table.

`FirmwareTasks` holds the drivers, the estimator, the controller and the supervisor bound to a `Board`,
and one method per task body; `firmware.app.Firmware` adds the task table (priorities, periods,
deadlines, costs) and the events from outside it. The firmware is handed its board; it never imports a
backend.
"""

from __future__ import annotations

import logging
import math
from collections.abc import Callable
from dataclasses import dataclass
from typing import Final

from firmware.config import FirmwareConfig
from firmware.control.estimation import AngleEstimator
from firmware.control.filters import ButterworthLowPass
from firmware.control.gait_events import LoadDetector
from firmware.control.ground_events import GroundEvents
from firmware.control.interface import as_number, check_controller, describe_failure, published_names
from firmware.control.observation import MotorCommand, Observation
from firmware.control.pid import Feedforward
from firmware.control.reference import GaitReference, MinimumJerk, Trajectory
from firmware.control.registry import build_controller
from firmware.drivers.encoder import EncoderDriver
from firmware.drivers.ground_sensors import GroundSensorDriver
from firmware.drivers.imu import ImuDriver
from firmware.drivers.motor_links import make_motor_driver
from firmware.logger import TelemetryLogger
from firmware.safe_state import SafeCommand, SafePolicy
from firmware.safety import (
    FaultReason,
    FrozenImu,
    JamCheck,
    JamObserver,
    MotorEncoderGap,
    SafetyInputs,
    Supervisor,
    SupervisorState,
    ThermalGuard,
)
from hal.interfaces import Board
from protocol.rvc import RVC_RATE_HZ
from rtos import Job

log = logging.getLogger(__name__)

__all__ = ["ControlOutput", "FirmwareTasks", "KernelHealth"]

# enum members bound once for the per-period checks (Final: compiled, C statics, no module-dict lookup)
_INIT: Final = SupervisorState.INIT
_RUN: Final = SupervisorState.RUN
_SAFE: Final = SupervisorState.SAFE

KernelHealth = Callable[[], tuple[int, int]]
"""Returns (total deadline misses, longest current miss streak) as the RTOS sees them."""


@dataclass
class ControlOutput:
    """What the control task decided this period (read by the motor, logger and report)."""

    reference_rad: float = 0.0
    current_cmd_a: float = 0.0
    brake: bool = False
    fused_angle_rad: float = 0.0
    torque_est_nm: float = 0.0
    safe: SafeCommand | None = None  # in SAFE: the safe state's drive command (firmware/safe_state.py)


class FirmwareTasks:
    """The prosthesis firmware's state bound to `board`, and its task bodies (one method per task)."""

    def __init__(self, board: Board, config: FirmwareConfig, reference: GaitReference | None = None,
                 controller: object = None) -> None:
        """Bind drivers to the board's peripherals; take the controller (default: the profile's)."""
        self.board = board
        self.config = c = config
        self.f_cpu_hz = board.f_cpu_hz
        self.ts_s = 1.0 / c.control_hz
        self.reference = reference or GaitReference.normative(stride_s=c.stride_s)
        self._gait_curve = self.reference.curve  # sampled directly: compiled, not through the interpreted class
        self.encoder = EncoderDriver(board.encoder, self.ts_s, velocity_cutoff_hz=c.velocity_cutoff_hz)
        self.imu = ImuDriver(board.imu_uart)
        self.motor = make_motor_driver(board, c)  # the driver of the link the profile names (motor_links.MOTOR_LINKS)
        self.logger = TelemetryLogger(board.telemetry_uart)
        self.supervisor = sup = Supervisor(c.safety, c.thermal)
        # the profile's safe state on this link (refused here, before the run, if the link lacks it)
        sup.policy = SafePolicy.of(c.safety, self.motor.SAFE_BEHAVIOURS, c.motor_link)
        self.thermal = ThermalGuard(c.thermal)  # derating from the motor's reported winding temperature
        self.motor_encoder_gap = MotorEncoderGap(c.safety.belt_ratio)
        lim = c.safety
        self.frozen_imu = FrozenImu(lim.imu_frozen_motion_rad)
        self.jam = JamCheck(lim.jam_current_share, lim.jam_still_rad, lim.jam_reference_rad_s)
        self.estimator = AngleEstimator(self.ts_s, offset_tau_s=c.estimator_offset_tau_s)
        self.imu_filter = (ButterworthLowPass(c.imu_lowpass_order, c.imu_lowpass_hz, RVC_RATE_HZ)
                           if c.imu_lowpass_hz > 0 else None)
        if controller is None:
            controller = build_controller(c.controller, c, c.controller_params)
        check_controller(controller)
        self.controller: object = controller
        self._update: Callable[[Observation], object] = getattr(controller, "update")  # noqa: B009 -- typed object
        reset = getattr(controller, "reset", None)
        self._reset: Callable[[], object] | None = reset if callable(reset) else None
        self._published: dict[str, object] | None = getattr(controller, "published", None)
        self.published_names: tuple[str, ...] = published_names(controller)
        self.logger.extra_fields(len(self.published_names))
        self.controller_error = ""  # what failed, once a controller call raised or returned a bad value
        self.obs = Observation()
        self._current_limit_a = c.current_limit_a
        self._stride_s = c.stride_s
        feedforward = Feedforward(c.feedforward_params)
        self._nm_per_a = feedforward.nm_per_a  # output torque per motor amp
        self.jam_observer = JamObserver(feedforward.inertia_kg_m2, feedforward.nm_per_a, feedforward.backdriven_share,
                                        feedforward.gravity_moment_nm, c.com_angle_rad,
                                        (feedforward.spring_k, feedforward.spring_engage_rad,
                                         feedforward.spring_two_sided), lim.jam_observer_s,
                                        lim.jam_residual_peak_share * feedforward.nm_per_a * c.current_limit_a,
                                        lim.jam_residual_share, lim.jam_residual_m, lim.jam_slow_rad_s)
        self.load_detector = LoadDetector(self.ts_s, feedforward.nm_per_a, feedforward.inertia_kg_m2,
                                          feedforward.gravity_moment_nm, c.com_angle_rad, feedforward=feedforward)
        # gait events from the load cell and FSRs, on boards with the ADC; the load detector is the fallback
        self.ground_events: GroundEvents | None = (
            GroundEvents(GroundSensorDriver(board.adc, c.ground_sensors, self.ts_s)) if board.adc is not None else None)
        self._controller_state = _INIT  # the supervisor state the controller last saw (reset on a change)
        # what the kernel says of deadlines; the runner sets it once the scheduler exists
        self.kernel_health: KernelHealth = lambda: (0, 0)
        self.out = ControlOutput()
        self._safety_inputs = SafetyInputs(now_s=0.0, angle_rad=0.0)
        self.imu_pitch_rad = 0.0
        self.gait_start_s: float | None = None
        self._trajectory: Trajectory | None = None
        self._new_imu = False
        self._heartbeat = 0
        self._kicked_heartbeat = -1
        self.watchdog_resets = 0
        self.link_lost_seen_s: float | None = None

    def seconds(self, cycles: int) -> float:
        """Convert a cycle count of the board's clock to seconds."""
        return cycles / self.f_cpu_hz

    # Task bodies -------------------------------------------------------------------------------
    def encoder_task(self, job: Job) -> None:
        self.encoder.sample()

    def imu_task(self, job: Job) -> int:
        before = self.imu.decoder.stats.bytes_in
        if self.imu.poll(self.seconds(job.start)):
            pitch = self.imu.pitch_rad
            assert pitch is not None  # poll() returned frames
            self.imu_pitch_rad = self.imu_filter.step(pitch) if self.imu_filter else pitch
            self._new_imu = True
        return self.imu.decoder.stats.bytes_in - before

    def supervisor_task(self, job: Job) -> None:
        x = self._safety_inputs  # one object refilled each period (the supervisor keeps no reference)
        x.now_s = job.start / self.f_cpu_hz
        x.deadline_miss_streak = self.kernel_health()[1]
        feedback, estimator = self.motor.feedback, self.estimator
        x.angle_rad = self.out.fused_angle_rad
        x.current_meas_a = feedback.current_a
        x.last_motor_reply_s = feedback.received_s
        x.last_command_s = self.motor.last_command_s
        imu = self.imu
        x.last_imu_frame_s = imu.last_frame_s
        x.last_imu_poll_s = imu.last_poll_s
        x.imu_frozen_s = self.frozen_imu.update(imu.changed_s, imu.last_frame_s, self.encoder.angle_rad)
        out = self.out  # the last period's command and reference, against the encoder's angle now
        x.jam_s = self.jam.update(x.now_s, out.current_cmd_a, self._current_limit_a * self.thermal.factor,
                                  self.encoder.angle_rad, self.obs.reference_velocity_rad_s)
        x.jam_dorsiflexing = self.jam.dorsiflexing
        x.jam_torque_s = self._jam_torque_s(x.now_s, feedback.received_s, feedback.current_a)
        x.jam_residual_nm, x.jam_bound_nm = self.jam_observer.residual, self.jam_observer.bound
        x.loaded = self.obs.stance
        x.disagreement_rad = estimator.disagreement_rad  # 0.0 until the first IMU sample seeds it
        x.motor_encoder_gap_rad = self.motor_encoder_gap.update(self.encoder.angle_rad, feedback.position_rad,
                                                                feedback.received_s, x.now_s)
        x.motor_fault_code = feedback.fault
        x.motor_temp_c = self.thermal.fresh_c(feedback.temp_motor_c, feedback.temp_received_s, x.now_s)
        x.estop_pressed = self.board.estop.read()
        x.link_lost = link_lost = self.motor.link_lost or self.imu.link_lost
        if link_lost and self.link_lost_seen_s is None:
            self.link_lost_seen_s = x.now_s  # whatever the state: the latency of seeing it is never negative
        self.supervisor.check(x)

    def _jam_torque_s(self, now_s: float, reply_s: float | None, current_a: float) -> float:
        """The torque balance's jam time (JamObserver) while it can be judged: in RUN, with a healthy load cell (the
        ground's moment measured) and the motor's current fresh; else the observer starts again."""
        ground, observer = self.ground_events, self.jam_observer
        if self.supervisor.state is not _RUN or ground is None or not ground.healthy or reply_s is None \
                or now_s - reply_s > self.config.safety.motor_timeout_s:
            observer.reset()
            return 0.0
        d, encoder = ground.driver, self.encoder
        return observer.update(now_s, encoder.velocity_rad_s, encoder.angle_rad, current_a, d.moment_nm, d.force_n)

    def control_task(self, job: Job) -> None:
        now_s = job.start / self.f_cpu_hz
        self._heartbeat += 1
        ground = self.ground_events
        ground_stance = ground.update(now_s) if ground is not None else False  # from boot: the load cell tares
        imu = self.imu_pitch_rad if self._new_imu else None
        self._new_imu = False
        fused = self.estimator.update(self.encoder.angle_rad, imu)
        out = self.out
        out.fused_angle_rad = fused
        state = self.supervisor.state
        if state is _SAFE:
            # loaded: the ground sensors while healthy, else the load the motor current shows (quasi-static)
            fb = self.motor.feedback
            loaded = self.load_detector.update(now_s, fb.current_a, fused, 0.0, self.encoder.velocity_rad_s)
            if ground is not None and ground.healthy:
                loaded = ground_stance
            # the hold's target: the drive's own position report while fresh (an older one would move the foot back)
            seen = fb.received_s
            fresh = seen is not None and now_s - seen <= self.config.safety.motor_timeout_s
            cmd = self.supervisor.safe_command(now_s, loaded=loaded, drive_fault=fb.fault != 0,
                                               position_rad=fb.position_rad if fresh else None)
            out.current_cmd_a, out.brake, out.safe = cmd.current_a, cmd.brake, cmd
            if self._controller_state is not _SAFE:
                self._controller_state = _SAFE
                self._reset_controller(now_s)
            return
        if state is _INIT or not self.estimator.seeded:
            out.current_cmd_a, out.brake, out.reference_rad = 0.0, False, fused
            return
        gait_start_s = self.gait_start_s
        if self._trajectory is None or gait_start_s is None:  # first RUN period: glide to the gait's start
            ramp = self.config.startup_ramp_s
            self._trajectory = MinimumJerk(fused, self.reference.angle_rad(0.0), ramp, now_s)
            self.gait_start_s = gait_start_s = now_s + ramp
        gait_t = now_s - gait_start_s
        ref = self._trajectory.sample(now_s) if gait_t < 0 else self._gait_curve.sample(gait_t)
        out.reference_rad = ref[0]
        current_meas_a = self.motor.feedback.current_a
        detector = self.load_detector
        obs = self.obs
        obs.t_s = now_s
        obs.dt_s = self.ts_s
        obs.reference_rad = ref[0]
        obs.reference_velocity_rad_s = ref[1]
        obs.reference_acceleration_rad_s2 = ref[2]
        obs.angle_rad = fused
        obs.velocity_rad_s = self.encoder.velocity_rad_s
        obs.encoder_angle_rad = self.encoder.angle_rad
        obs.imu_pitch_rad = self.imu_pitch_rad
        obs.motor_current_a = current_meas_a
        obs.gait_phase = (gait_t / self._stride_s) % 1.0 if gait_t >= 0 else 0.0
        obs.stance = detector.update(now_s, current_meas_a, fused, ref[2], obs.velocity_rad_s)
        obs.load_torque_nm = detector.load_torque_nm
        if ground is not None:
            if ground.healthy:
                obs.stance = ground_stance
            obs.ground_sensors_ok = ground.healthy
            obs.heel_contact = ground.heel_on
            obs.toe_contact = ground.toe_on
            obs.axial_force_n = ground.driver.force_n
            obs.sagittal_moment_nm = ground.driver.moment_nm
        if self._controller_state is not _RUN:
            self._controller_state = _RUN
            if not self._reset_controller(now_s):
                return
        try:
            returned: object = self._update(obs)
        except BaseException as e:  # noqa: BLE001 -- sys.exit, KeyboardInterrupt, GeneratorExit too: latch SAFE
            self._controller_failed(now_s, e, None)
            return
        brake = False
        if isinstance(returned, float):
            current = returned
        elif isinstance(returned, MotorCommand) and isinstance(returned.current_a, (float, int)):
            current = float(returned.current_a)
            brake = returned.brake is True
        elif isinstance(returned, int) and not isinstance(returned, bool):
            current = float(returned)
        else:
            self._controller_failed(now_s, None, returned)
            return
        if not math.isfinite(current) or (brake and current < 0.0):
            self._controller_failed(now_s, None, returned)
            return
        fb = self.motor.feedback
        limit = self.thermal.limit_a(self._current_limit_a, fb.temp_motor_c, fb.temp_received_s, now_s)
        if current > limit:
            current = limit
        elif current < -limit:
            current = -limit
        out.current_cmd_a = current
        out.brake = brake

    def _reset_controller(self, now_s: float) -> bool:
        """Call the controller's reset() if it has one; False (and the safe state) if it raised."""
        reset = self._reset
        if reset is None:
            return True
        try:
            reset()
        except BaseException as e:  # noqa: BLE001 -- any failure of the controller latches the safe state
            self._controller_failed(now_s, e, None)
            return False
        return True

    def _controller_failed(self, now_s: float, error: BaseException | None, returned: object) -> None:
        """The controller raised (anything, sys.exit and KeyboardInterrupt included: the run is not the
        controller's to end) or returned a bad value: zero current now, the safe state latched."""
        if not self.controller_error:
            self.controller_error = describe_failure(self.controller, error, returned)
        out = self.out
        out.current_cmd_a, out.brake = 0.0, False
        sup = self.supervisor
        if sup.state is not _SAFE:
            sup.detail = self.controller_error
            sup.trip(FaultReason.CONTROLLER_ERROR, now_s)
        self._controller_state = _SAFE

    def motor_task(self, job: Job) -> int:
        now_s = job.start / self.f_cpu_hz
        before = self.motor.decoder.stats.bytes_in
        self.motor.poll(now_s)
        safe = self.out.safe
        if safe is None:
            written = self.motor.send(self.out.current_cmd_a, now_s, brake=self.out.brake)
        else:
            written = self.motor.send_safe(safe, now_s)
        self.out.torque_est_nm = self.motor.feedback.current_a * self._nm_per_a
        return written + self.motor.decoder.stats.bytes_in - before

    def logger_task(self, job: Job) -> int:
        out, sup, encoder = self.out, self.supervisor, self.encoder
        published = self._published
        if published is not None and self.published_names:
            extras = [as_number(published.get(name)) for name in self.published_names]
            return self.logger.log_values(
                job.start, out.reference_rad, encoder.angle_rad, self.imu_pitch_rad, out.fused_angle_rad,
                encoder.velocity_rad_s, out.current_cmd_a, self.motor.feedback.current_a, out.torque_est_nm,
                sup.state, sup.reason, self.kernel_health()[0], *extras)
        return self.logger.log_values(  # the fields in RECORD_FIELDS order (telemetry.TelemetryRecord)
            job.start,
            out.reference_rad,  # reference_rad
            encoder.angle_rad,  # encoder_angle_rad
            self.imu_pitch_rad,  # imu_pitch_rad
            out.fused_angle_rad,  # fused_angle_rad
            encoder.velocity_rad_s,  # velocity_rad_s
            out.current_cmd_a,  # current_cmd_a
            self.motor.feedback.current_a,  # current_meas_a
            out.torque_est_nm,  # torque_est_nm
            sup.state,  # supervisor_state
            sup.reason,  # fault_reason
            self.kernel_health()[0],  # deadline_misses
        )

    def watchdog_task(self, job: Job) -> None:
        if self._heartbeat != self._kicked_heartbeat:  # the control loop ran since the last kick
            self._kicked_heartbeat = self._heartbeat
            self.board.watchdog.kick()
        led = self.board.led
        if self.supervisor.state is _SAFE:
            led.write(True)
        elif job.index % 50 == 0:
            led.toggle()
