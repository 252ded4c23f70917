"""Serial ("flash-equivalent") mode: the very firmware on real ports, its RTOS paced by the wall clock.

The composition root of serial mode, the sibling of `runner.py`. Roles bound to ``sim://`` are served in
this process by wall-clock virtual devices sharing one plant (`WallDevices`); every other binding is
opened with pyserial (`hal.binding.open_uart`). Each port must pass its start-up check
(`serial_checks`) before anything is written. The encoder, which a host cannot wire to a timer, reads
the motor's position feedback (``motor``: pid_pos is the actuator's angle before the 28:6 belt,
docs/devices.md) or the in-process plant (``sim``). A lowest-priority probe samples the run, handles a
lost link (stop after the safe command went out, or reopen with ``reconnect``) and is not firmware.

Every way out of the loop ends in the firmware's stop path before a port closes: the end of the duration,
SIGINT / SIGTERM / SIGHUP (`StopSignals`), a lost port, an exception in a task. The stop path writes the
profile's safe state to the motor and waits until the port has sent them (`Firmware.stop`); the result
records the reason, the frames and how long after the signal they left (docs/serial_mode.md).
On the wall clock a late job is the host's stall: a deadline-miss streak and a watchdog expiry are
counted as warnings; the supervisor latches on the ages of the last command and the last feedback.
"""

from __future__ import annotations

import logging
import sys
import time
from collections.abc import Callable
from contextlib import suppress
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from firmware.app import Firmware
from firmware.config import FirmwareConfig, load_firmware_config
from firmware.control.reference import GaitReference
from firmware.drivers.motor import MotorFeedback
from hal.binding import open_uart
from hal.can import CanPort
from hal.errors import HalError
from hal.interfaces import Board, Uart
from hal.interfaces import Watchdog as HalWatchdog
from hal.pycan import is_can_url, open_can, parse_can_url
from hal.serial.sim_port import WallDevices, parse_sim_url
from hal.virtual.devices.encoder import EncoderMount
from hal.virtual.null import NullDigitalIn, NullDigitalOut, NullUart
from hal.virtual.timer import VirtualEncoderTimer
from host_tools.recording import RunRecording
from host_tools.runner import PROBE_HZ, WATCHDOG_TIMEOUT_S, Probe, board_profile, kernel_health, reference_record
from host_tools.serial_mode.fault_clock import FirmwareClock, follow_firmware
from host_tools.serial_mode.host_watchdog import HostWatchdog, WatchdogRecord, arm_watchdog
from host_tools.serial_mode.jitter import TaskTimings, instrument
from host_tools.serial_mode.link_watch import LinkEvent, LinkWatch
from host_tools.serial_mode.realtime import RealtimeSection, RealtimeSettings
from host_tools.serial_mode.serial_checks import EXPECTED, StartupError, check_imu, check_motor
from host_tools.serial_mode.serial_io import CaptureUart
from host_tools.serial_mode.stop_record import StopRecord, stop_record
from host_tools.stop_signals import StopSignals
from host_tools.wire_capture import WireCapture
from rtos import Scheduler, Task, Trace, WallClock, Watchdog
from rtos.scheduler import SchedulerNow

__all__ = ["BELT_RATIO", "EXIT_TASK_EXCEPTION", "FeedbackAngle", "SerialRunConfig",
           "SerialRunResult", "StartupError", "run_serial"]

log = logging.getLogger(__name__)

BELT_RATIO = 28 / 6  # the report's belt (rotor : output 28 : 1 over a 6 : 1 planetary): pid_pos = 28/6 * ankle angle;
# a run takes its profile's [safety] belt_ratio (a design's own belt)
GC_EVERY_TICKS = 100  # probe ticks between two young-generation collections (the collector is off meanwhile)
STOP_DRAIN_TIMEOUT_S = 0.5  # the stop path waits at most this long for the port to send the safe frames
EXIT_TASK_EXCEPTION = 3


@dataclass
class SerialRunConfig:
    """What to run in serial mode: the port bindings, the encoder source, duration and profiles."""

    motor: str
    imu: str
    telemetry: str | None = None
    encoder: str = "motor"
    duration_s: float = 10.0
    baud: int = 921600  # motor link
    imu_baud: int = 115200
    telemetry_baud: int = 921600
    seed: int = 0
    board: str = "stm32f4"
    firmware: FirmwareConfig | None = None
    reference_csv: Path | None = None
    reconnect: bool = False
    startup_timeout_s: float = 1.0
    trace_capacity: int = 200_000
    fixture: str = "suspended"
    capture_dir: Path | None = None  # raw bytes of every port, both directions (host_tools/wire_capture.py)
    record: bool = True  # record.bin in the run directory: every input the firmware saw (`pafp replay`)
    realtime: RealtimeSettings = field(default_factory=RealtimeSettings)
    strides: int = 0  # whole gait strides run in RUN (filled in after the run)
    ground: str | None = None  # the ground sensors' Firmata board (hal/serial/firmata_adc.py): a port or sim://
    ground_baud: int = 115200

    def __post_init__(self) -> None:
        """Reject values serial mode cannot run."""
        if self.encoder not in ("motor", "sim"):
            raise ValueError(f"encoder {self.encoder!r} invalid: 'motor' (position feedback) or 'sim' (plant)")
        if not 0.1 <= self.duration_s <= 86_400:
            raise ValueError(f"duration {self.duration_s!r} s out of range: 0.1..86400")
        for name in ("baud", "imu_baud", "telemetry_baud", "ground_baud"):
            v = getattr(self, name)
            if not isinstance(v, int) or not 1200 <= v <= 20_000_000:
                raise ValueError(f"{name} {v!r} out of range: an int in 1200..20000000")
        if is_can_url(self.motor):
            parse_can_url(self.motor, "--motor")  # ValueError naming the bad part
        if self.encoder == "sim" and not any(_is_sim(u) for u in (self.motor, self.imu)):
            raise ValueError("--encoder sim reads the plant, which exists here only when --motor or --imu is "
                             "sim://...; with both devices on real ports use --encoder motor")


def _is_sim(url: str | None) -> bool:
    return bool(url) and url.lower().startswith("sim://")  # type: ignore[union-attr]


class FeedbackAngle:
    """Output angle from the motor's position feedback, zero at the first reply (an incremental encoder).

    >>> fb = MotorFeedback(position_rad=BELT_RATIO * 0.1, received_s=0.0)
    >>> a = FeedbackAngle(); a.feedback = fb
    >>> a.angle_rad(0); fb.position_rad += BELT_RATIO * 0.2; round(a.angle_rad(0), 9)
    0.0
    0.2
    """

    def __init__(self, ratio: float = BELT_RATIO) -> None:
        """Angle = (pid_pos - pid_pos at the first reply) / ratio; 0 until the first reply."""
        self.ratio = ratio
        self.feedback: MotorFeedback | None = None
        self.zero_rad: float | None = None

    def angle_rad(self, t: int) -> float:
        """The output angle now (the time argument is ignored: the feedback is what it is)."""
        fb = self.feedback
        if fb is None or fb.received_s is None:
            return 0.0
        if self.zero_rad is None:
            self.zero_rad = fb.position_rad
        return (fb.position_rad - self.zero_rad) / self.ratio


class _KernelWatchdog(HalWatchdog):
    """The firmware's IWDG handle: kicks the RTOS watchdog and the host watchdog outside the loop."""

    def __init__(self, wd: Watchdog) -> None:
        self.wd = wd
        self.host: HostWatchdog | None = None

    def kick(self) -> None:
        """Reload the watchdogs."""
        self.wd.kick()
        if self.host is not None:
            self.host.kick()


@dataclass
class HostWarnings:
    """What the host's stalls did that is not a firmware fault on the wall clock (counted, not latched)."""

    watchdog_expiries: int = 0
    first_watchdog_s: float | None = None

    def on_watchdog(self, t_cycles: int, f_cpu_hz: int) -> None:
        """The RTOS watchdog expired: the host did not run the loop for its timeout. Count and log it."""
        self.watchdog_expiries += 1
        t = t_cycles / f_cpu_hz
        if self.first_watchdog_s is None:
            self.first_watchdog_s = t
        log.warning("watchdog expired at %.4f s: the host stalled the loop %.0f ms (a warning on the wall clock)",
                    t, WATCHDOG_TIMEOUT_S * 1e3)


@dataclass
class SerialRunResult:
    """Everything a report needs from one serial run (the attributes `report.summarise` reads)."""

    config: SerialRunConfig
    firmware: Firmware
    scheduler: Scheduler
    probe: Probe
    timings: TaskTimings
    telemetry: bytes
    sim_time_s: float
    wall_time_s: float
    gait_start_s: float | None
    started_unix_s: float
    angle_source: str
    stop: StopRecord
    warnings: HostWarnings
    realtime_granted: dict[str, object]
    link: LinkEvent | None = None
    host_watchdog: WatchdogRecord | None = None
    telemetry_port_error: str = ""
    startup_bytes: dict[str, int] = field(default_factory=dict)
    bounds: list = field(default_factory=list)  # no response-time bounds: host times are measured
    time_in_run_s: float = 0.0
    telemetry_file_error: OSError | None = None  # writing telemetry.bin failed (a full disk): the run went on
    capture_error: OSError | None = None  # a --capture file could not be written: the capture ended there
    record_error: OSError | None = None  # record.bin could not be written: the incomplete record was removed
    timeline: Any = None  # the trace's slow counters (host_tools/reports/timeline.py)

    @property
    def interrupted(self) -> bool:
        """True when a signal ended the run."""
        return self.stop.reason == "signal"

    @property
    def exit_code(self) -> int:
        """docs/hardware.md: 0 done as asked with no latched fault, 1 a latched fault, 3 a task raised,
        4 a port lost (without --reconnect), 128 + N signal N (129 SIGHUP, 130 SIGINT, 143 SIGTERM)."""
        if self.stop.reason == "signal":
            from host_tools.stop_signals import EXIT_CODES

            return EXIT_CODES.get(self.stop.signal or "", 130)
        if self.stop.reason == "exception":
            return EXIT_TASK_EXCEPTION
        if self.link is not None and not self.config.reconnect:
            return 4
        return 1 if self.firmware.supervisor.tripped_at_s is not None else 0


@dataclass
class _Ports:
    """The opened UARTs and, when a role is sim://, the in-process wall-clock devices."""

    motor: Uart
    imu: Uart
    telemetry: Uart | None
    devices: WallDevices | None
    can: CanPort | None = None  # the motor's CAN bus (--motor can://...; then motor is a NullUart)
    ground: Uart | None = None  # the ground sensors' Firmata board (--ground)
    untapped_motor: Uart | None = None  # the motor's port as opened, not a capture's tap (the host watchdog's)

    def close(self) -> None:
        for u in (self.motor, self.imu, self.telemetry, self.can, self.ground):
            if u is not None:
                u.close()
        if self.devices is not None:
            self.devices.close()


def _open_ports(cfg: SerialRunConfig, telemetry_uart: Uart | None = None) -> _Ports:
    """Open every port (sim:// roles in-process on one plant); StartupError naming a port that fails.

    `telemetry_uart`, when given, is the telemetry port already open (``--telemetry pty``).
    """
    sim_roles = {r: parse_sim_url(u) for r, u in (("motor", cfg.motor), ("imu", cfg.imu), ("ground", cfg.ground))
                 if _is_sim(u)}
    for role, url in sim_roles.items():
        if url.role != role:
            raise StartupError(f"{role} port {getattr(cfg, role)!r}: serves a {url.role}; expected "
                               f"{EXPECTED.get(role, 'sim://ground-sensors')}")
    devices = None
    if sim_roles:
        bauds = {"motor": cfg.baud, "imu": cfg.imu_baud, "ground": cfg.ground_baud}
        devices = WallDevices([u.device for u in sim_roles.values()], bauds=bauds,
                              fixture=cfg.fixture, seed=cfg.seed)
    opened: dict[str, Uart] = {}
    can_port: CanPort | None = None
    try:
        for role, url, baud in (("motor", cfg.motor, cfg.baud), ("imu", cfg.imu, cfg.imu_baud),
                                ("telemetry", cfg.telemetry, cfg.telemetry_baud),
                                ("ground", cfg.ground, cfg.ground_baud)):
            if role == "telemetry" and telemetry_uart is not None:
                opened[role] = telemetry_uart
                continue
            if url is None:
                continue
            if role == "motor" and is_can_url(url):  # the motor on a CAN bus: the firmware's driver is chosen by it
                try:
                    can_port = open_can(parse_can_url(url, "--motor"))
                except (HalError, ValueError) as exc:
                    raise StartupError(f"motor port {url!r}: {exc}") from exc
                opened[role] = NullUart(baud, "motor (on CAN)")
                continue
            if role in sim_roles:
                opened[role] = devices.uarts[role]  # type: ignore[union-attr]
                continue
            try:
                if role == "ground":  # no role of hal.binding (its sim:// is handled above): pyserial opens it
                    from hal.serial.backend import SerialUart

                    opened[role] = SerialUart(url, baud)
                else:
                    opened[role] = open_uart(url, baud, role=role)
            except (HalError, ValueError) as exc:
                raise StartupError(f"{role} port {url!r}: {exc}") from exc
    except BaseException:
        for u in opened.values():
            u.close()
        if can_port is not None:
            can_port.close()
        if devices is not None:
            devices.close()
        raise
    return _Ports(opened["motor"], opened["imu"], opened.get("telemetry"), devices, can_port, opened.get("ground"))


def run_serial(cfg: SerialRunConfig, out: Path, progress: Callable[[float], None] | None = None,
               telemetry_uart: Uart | None = None, signals: StopSignals | None = None) -> SerialRunResult:
    """Check the ports, then run the firmware on them for cfg.duration_s of wall time; outputs go to `out`.

    Raises StartupError (nothing written) when a port fails its check. `telemetry_uart`: an open telemetry
    port to use instead of opening ``cfg.telemetry`` (it is closed with the others). `signals`: stop
    signals already caught by the caller (entered); by default they are caught for the run alone.
    """
    if signals is None:
        with StopSignals() as own:
            return run_serial(cfg, out, progress, telemetry_uart, own)
    board_cfg = board_profile(cfg.board)
    f_cpu = int(board_cfg["f_cpu_hz"])
    fw_cfg = cfg.firmware or load_firmware_config()
    if is_can_url(cfg.motor):  # the driver of the URL's mode (firmware.drivers.motor_links)
        url = parse_can_url(cfg.motor, "--motor")
        fw_cfg = fw_cfg.with_changes(motor_link=f"can-{url.mode}", motor_can_id=url.driver_id)
    reference = (GaitReference.from_csv(cfg.reference_csv, stride_s=fw_cfg.stride_s) if cfg.reference_csv
                 else GaitReference.normative(stride_s=fw_cfg.stride_s))
    ports = _open_ports(cfg, telemetry_uart)
    # the capture starts with the ports, so a start-up check that fails (wrong baud) leaves its bytes too
    wire = WireCapture(cfg.capture_dir, _since_start(), side="host") if cfg.capture_dir is not None else None
    ports.untapped_motor = ports.motor
    if wire is not None:
        ports.imu = wire.tap("imu", ports.imu)
        if ports.can is not None:  # the motor's frames, as a candump log (the motor's UART stands unused)
            ports.can = wire.tap_can("motor", ports.can, f"can-{parse_can_url(cfg.motor, '--motor').mode}")
        else:
            ports.motor = wire.tap("motor", ports.motor)
    try:
        # over CAN no start-up check: a silent bus is caught by the supervisor (MOTOR_TIMEOUT)
        seen = {"motor": 0 if ports.can is not None else check_motor(ports.motor, cfg.motor,
                                                                     timeout_s=cfg.startup_timeout_s),
                "imu": check_imu(ports.imu, cfg.imu, timeout_s=cfg.startup_timeout_s)}
    except BaseException:
        ports.close()
        if wire is not None:
            wire.close()
        raise
    out.mkdir(parents=True, exist_ok=True)
    capture = CaptureUart(out / "telemetry.bin", cfg.telemetry_baud, inner=ports.telemetry)
    try:
        result = _run(cfg, ports, capture, wire, f_cpu, fw_cfg, reference, seen, progress, signals, out)
    finally:  # the stop path has run inside _run: the safe frames have left before any port closes
        capture.close()
        ports.close()
        if wire is not None:
            with suppress(OSError):  # kept in wire.error, reported after the outputs
                wire.close()
    result.telemetry_file_error = capture.file_error  # telemetry.bin could not be written (reported after)
    result.capture_error = wire.error if wire is not None else None
    return result


def _since_start() -> Callable[[], float]:
    """Seconds since now on the monotonic clock (the capture's time base; the run's starts a moment later)."""
    t0 = time.perf_counter()
    return lambda: time.perf_counter() - t0


def _run(cfg: SerialRunConfig, ports: _Ports, capture: CaptureUart, wire: WireCapture | None, f_cpu: int,
         fw_cfg: FirmwareConfig, reference: GaitReference, seen: dict[str, int],
         progress: Callable[[float], None] | None, signals: StopSignals, out: Path | None = None) -> SerialRunResult:
    """Build the board, the firmware and the wall-clock RTOS on opened ports, run, stop safely, collect."""
    clock = WallClock(f_cpu, spin_s=cfg.realtime.spin_s)
    now = SchedulerNow()  # the board is built before the scheduler: bound to it below
    wd = Watchdog(int(WATCHDOG_TIMEOUT_S * f_cpu))
    # the profile's belt (a design profile's [safety] belt_ratio is its own), as the firmware's plausibility check
    # of the output encoder against the motor's position takes it
    feedback_angle = FeedbackAngle(fw_cfg.safety.belt_ratio)
    if cfg.encoder == "sim":
        assert ports.devices is not None
        devices = ports.devices
        encoder = VirtualEncoderTimer(devices.now, EncoderMount(devices.world).angle_rad)
    else:
        encoder = VirtualEncoderTimer(lambda: 0, feedback_angle.angle_rad)
    telemetry: Uart = capture if wire is None else wire.tap("telemetry", capture)  # the others are tapped already
    adc = None
    if ports.ground is not None:  # imported only then: the sensors' models and numpy slow every start by 0.25 s
        from hal.serial.firmata_adc import FirmataAdc
        from hal.virtual.ground_sensors import ADC_CHANNELS

        adc = FirmataAdc(ports.ground, ADC_CHANNELS)
    kernel_wd = _KernelWatchdog(wd)
    board = Board(motor_uart=ports.motor, imu_uart=ports.imu, telemetry_uart=telemetry,
                  encoder=encoder, estop=NullDigitalIn(False), led=NullDigitalOut(), watchdog=kernel_wd,
                  now_cycles=now, f_cpu_hz=f_cpu, can=ports.can, adc=adc)
    recording, record_error = None, None
    if cfg.record and out is not None:
        recording = RunRecording(out, board, fw_cfg, "serial", reference_record(cfg.reference_csv, None), 0,
                                 {"seed": cfg.seed, "bindings": {"motor": cfg.motor, "imu": cfg.imu}})
        board = recording.board
    fw = Firmware(board, fw_cfg, reference=reference)
    fw.supervisor.latch_deadline_misses = False  # on the wall clock a late job is the host's (see module doc)
    warnings = HostWarnings()
    wd.on_reset = lambda t: warnings.on_watchdog(t, f_cpu)
    feedback_angle.feedback = fw.motor.feedback
    plant = ports.devices.world.plant if ports.devices is not None and ports.devices.motor is not None else None
    probe, link = Probe(), LinkWatch(cfg, fw, wire)
    timings = TaskTimings([t.name for t in fw.tasks], f_cpu, time.perf_counter_ns)
    section = RealtimeSection(cfg.realtime)

    def probe_body(job) -> None:  # bench instrument, not firmware
        t = job.start / f_cpu
        probe.sample(t, fw, plant.output_angle_rad(plant.latest_time_s) if plant is not None
                     else fw.out.fused_angle_rad)
        if link.step(t):
            sched.request_stop()
        if timeline is not None and job.index % 50 == 0:  # the trace's slow counters at 10 Hz, as a virtual run's
            timeline.sample(t)
        if job.index % GC_EVERY_TICKS == 0:
            section.collect_young()  # young objects only: tens of µs, never a full scan in the loop

    tasks = [instrument(t, timings) for t in (fw.tasks if recording is None else recording.tasks(fw.tasks))]
    probe_task = Task("serial_probe", 99, period=f_cpu // PROBE_HZ, cost=0, body=probe_body)
    tasks.append(probe_task)
    # the probe's jobs are not recorded: the trace file never draws them (reports/timeline.py)
    trace = Trace(cfg.trace_capacity, skip=(probe_task.name,)) if cfg.trace_capacity else None
    sched = Scheduler(tasks, clock, trace=trace, on_fault=lambda f: fw.on_task_fault(f.task, f.time),
                      seed=cfg.seed)
    now.bind(sched)
    from host_tools.reports.timeline import Timeline

    timeline = Timeline(sched, fw, f_cpu, None) if trace is not None else None
    fw_clock = FirmwareClock(lambda: sched.now, f_cpu)
    follow_firmware((ports.untapped_motor or ports.motor, ports.imu, ports.ground), fw, fw_clock, fw_cfg.stride_s)
    fw.kernel_health = kernel_health(sched, fw)
    if recording is not None:
        fw.kernel_health = recording.health(fw.kernel_health)
    sched.add_watchdog(wd)
    signals.on_stop = sched.request_stop
    armed = arm_watchdog(ports.untapped_motor or ports.motor, cfg.motor, board, fw_cfg, sched.request_stop,
                         lambda: timings.running)
    host_wd = armed if isinstance(armed, HostWatchdog) else None
    kernel_wd.host = host_wd
    error: BaseException | None = None
    failed_task: str | None = None
    with section:
        if host_wd is not None and signals.name is None:
            host_wd.start()  # before the anchor: starting a thread takes a few ms on a busy host
        started_unix = time.time()  # the wall clock is anchored at cycle 0 right after this
        wall0_ns = time.perf_counter_ns()
        try:
            if signals.name is None:  # a signal during the start-up: straight to the stop path
                fw_clock.started = True
                sched.run_until(int(cfg.duration_s * f_cpu), progress=progress)
        except BaseException as exc:  # a task raised (SystemExit too): the firmware's bug, reported after the stop path
            if isinstance(exc, KeyboardInterrupt) and (signals.name is not None or not signals.installed):
                if signals.name is None:  # Ctrl-C with no handler of ours in place (else: the second signal)
                    signals.name, signals.at_ns = "SIGINT", time.perf_counter_ns()
            else:
                error, failed_task = exc, timings.running or "serial_probe"  # the one body not instrumented
                log.error("task %s raised %r: stopping", failed_task, exc)
        finally:  # halted before the stop path, whose frames are then the last on the wire
            watch = host_wd.halt() if host_wd is not None else armed
        run_s = sched.now / f_cpu
        assert isinstance(watch, WatchdogRecord)
        if watch.fired_at_s is not None:
            fw.on_watchdog_reset(sched.now)  # the IWDG's job done from outside: the safe state latched
        stop = stop_record(signals, error, failed_task, link, run_s, wall0_ns, cfg.duration_s, watch)
        if recording is not None:
            recording.stop_section(sched.now)
        stop.safe = fw.stop(run_s, STOP_DRAIN_TIMEOUT_S)  # the stop path: on the wire before any port closes
        done_ns = time.perf_counter_ns()
        if host_wd is not None:
            host_wd.close()  # its thread and its handle
        if recording is not None:
            try:
                recording.close({"complete": stop.reason == "duration", "stop": stop.reason, "end_cycles": sched.now})
            except OSError as e:  # a full disk: an incomplete record is removed, reported after the outputs
                record_error = e
                with suppress(OSError):
                    recording.path.unlink()
        wall = (done_ns - wall0_ns) / 1e9
    period_s = fw.ts_s
    wire_s = (len(stop.safe.frames) * 10 / ports.motor.baud if ports.can is None
              else 2 * 160 / ports.can.bitrate)  # CAN: two frames, worst-case stuffing
    start_ns = signals.at_ns if signals.at_ns is not None else wall0_ns + round(stop.at_s * 1e9)
    stop.latency_ms = round(max(0, done_ns - start_ns) / 1e6, 3)
    stop.goal_ms = round((period_s + wire_s) * 1e3, 3)
    if stop.reason == "watchdog":  # its frames left when it fired: from the loop's last kick to them
        stop.latency_ms = watch.silent_ms
        stop.goal_ms = round(watch.timeout_ms + (sys.getswitchinterval() + wire_s) * 1e3, 3)
    if not stop.safe.on_wire:
        log.error("stop path: the safe frames did not all leave the motor port (%s)", stop.safe.error or
                  f"{stop.safe.written} of {len(stop.safe.frames)} bytes, drained {stop.safe.drained}")
    run_end = fw.supervisor.tripped_at_s if fw.supervisor.tripped_at_s is not None else run_s
    time_in_run = 0.0
    strides = 0
    if fw.gait_start_s is not None:
        time_in_run = max(0.0, run_end - fw.gait_start_s)
        strides = int(time_in_run // fw_cfg.stride_s)
    cfg.strides = strides
    return SerialRunResult(cfg, fw, sched, probe, timings, capture.captured(), run_s, wall, fw.gait_start_s,
                           started_unix, "plant" if plant is not None else "fused estimate", stop, warnings,
                           section.granted, link.event, watch, capture.inner_error, seen, time_in_run_s=time_in_run,
                           record_error=record_error, timeline=timeline)
