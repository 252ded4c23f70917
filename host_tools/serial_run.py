"""Serial ("flash-equivalent") mode: the very firmware on real ports, its RTOS paced by the wall clock.

The composition root of serial mode, the sibling of `runner.py`. Roles bound to ``sim://`` are served in
this process by wall-clock virtual devices sharing one plant (`WallDevices`); every other binding is
opened with pyserial (`hal.binding.open_uart`). Each port must pass its start-up check
(`serial_checks`) before anything is written. The encoder, which a host cannot wire to a timer, reads
the motor's position feedback (``motor``: pid_pos is the actuator's angle before the 28:6 belt,
docs/devices.md) or the in-process plant (``sim``). A lowest-priority probe samples the run, handles a
lost link (stop after the safe command went out, or reopen with ``reconnect``) and is not firmware.
"""

from __future__ import annotations

import gc
import logging
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path

from firmware.app import Firmware
from firmware.config import FirmwareConfig, load_firmware_config
from firmware.control.reference import GaitReference
from firmware.drivers.motor import MotorFeedback
from hal.binding import open_uart
from hal.errors import HalError
from hal.interfaces import Board, Uart
from hal.interfaces import Watchdog as HalWatchdog
from hal.serial.sim_port import WallDevices, parse_sim_url
from hal.virtual.devices.encoder import EncoderMount
from hal.virtual.null import NullDigitalIn, NullDigitalOut
from hal.virtual.timer import VirtualEncoderTimer
from host_tools.jitter import TaskTimings, instrument
from host_tools.runner import PROBE_HZ, WATCHDOG_TIMEOUT_S, Probe, board_profile, kernel_health
from host_tools.serial_checks import EXPECTED, StartupError, check_imu, check_motor
from host_tools.serial_io import CaptureUart
from rtos import Scheduler, Task, Trace, WallClock, Watchdog
from rtos.scheduler import SchedulerNow

__all__ = ["BELT_RATIO", "FeedbackAngle", "SerialRunConfig", "SerialRunResult", "StartupError", "run_serial"]

log = logging.getLogger(__name__)

BELT_RATIO = 28 / 6  # rotor : output is 28 : 1 and the planetary 6 : 1, so pid_pos = 28/6 * ankle angle
STOP_AFTER_LOSS_S = 0.030  # after a lost link: zero current, the brake (10 ms later), then stop
RECONNECT_EVERY_S = 0.2
GC_EVERY_TICKS = 100  # probe ticks between two young-generation collections (the collector is off meanwhile)


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
    strides: int = 0  # whole gait strides completed (filled in after the run)

    def __post_init__(self) -> None:
        """Reject values serial mode cannot run."""
        if self.encoder not in ("motor", "sim"):
            raise ValueError(f"encoder {self.encoder!r} invalid: 'motor' (position feedback) or 'sim' (plant)")
        if not 0.1 <= self.duration_s <= 86_400:
            raise ValueError(f"duration {self.duration_s!r} s out of range: 0.1..86400")
        for name in ("baud", "imu_baud", "telemetry_baud"):
            v = getattr(self, name)
            if not isinstance(v, int) or not 1200 <= v <= 20_000_000:
                raise ValueError(f"{name} {v!r} out of range: an int in 1200..20000000")
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
    """The firmware's IWDG handle: kicks the RTOS watchdog."""

    def __init__(self, wd: Watchdog) -> None:
        self.wd = wd

    def kick(self) -> None:
        """Reload the watchdog."""
        self.wd.kick()


@dataclass
class LinkEvent:
    """A lost port: which role, its name, why, when the driver saw it and when the supervisor tripped."""

    role: str
    port: str
    reason: str
    lost_at_s: float | None
    detected_at_s: float | None
    reconnects: int = 0


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
    link: LinkEvent | None = None
    interrupted: bool = False
    telemetry_port_error: str = ""
    startup_bytes: dict[str, int] = field(default_factory=dict)
    bounds: list = field(default_factory=list)  # no response-time bounds: host times are measured


@dataclass
class _Ports:
    """The opened UARTs and, when a role is sim://, the in-process wall-clock devices."""

    motor: Uart
    imu: Uart
    telemetry: Uart | None
    devices: WallDevices | None

    def close(self) -> None:
        for u in (self.motor, self.imu, self.telemetry):
            if u is not None:
                u.close()
        if self.devices is not None:
            self.devices.close()


def _open_ports(cfg: SerialRunConfig) -> _Ports:
    """Open every port (sim:// roles in-process on one plant); StartupError naming a port that fails."""
    sim_roles = {r: parse_sim_url(u) for r, u in (("motor", cfg.motor), ("imu", cfg.imu)) if _is_sim(u)}
    for role, url in sim_roles.items():
        if url.role != role:
            raise StartupError(f"{role} port {getattr(cfg, role)!r}: serves a {url.role}; expected {EXPECTED[role]}")
    devices = None
    if sim_roles:
        devices = WallDevices(list(sim_roles), bauds={"motor": cfg.baud, "imu": cfg.imu_baud},
                              fixture=cfg.fixture, seed=cfg.seed)
    opened: dict[str, Uart] = {}
    try:
        for role, url, baud in (("motor", cfg.motor, cfg.baud), ("imu", cfg.imu, cfg.imu_baud),
                                ("telemetry", cfg.telemetry, cfg.telemetry_baud)):
            if url is None:
                continue
            if role in sim_roles:
                opened[role] = devices.uarts[role]  # type: ignore[union-attr]
                continue
            try:
                opened[role] = open_uart(url, baud, role=role)
            except (HalError, ValueError) as exc:
                raise StartupError(f"{role} port {url!r}: {exc}") from exc
    except BaseException:
        for u in opened.values():
            u.close()
        if devices is not None:
            devices.close()
        raise
    return _Ports(opened["motor"], opened["imu"], opened.get("telemetry"), devices)


def run_serial(cfg: SerialRunConfig, out: Path, progress: Callable[[float], None] | None = None) -> SerialRunResult:
    """Check the ports, then run the firmware on them for cfg.duration_s of wall time; outputs go to `out`.

    Raises StartupError (nothing written) when a port fails its check.
    """
    board_cfg = board_profile(cfg.board)
    f_cpu = int(board_cfg["f_cpu_hz"])
    fw_cfg = cfg.firmware or load_firmware_config()
    reference = (GaitReference.from_csv(cfg.reference_csv, stride_s=fw_cfg.stride_s) if cfg.reference_csv
                 else GaitReference.normative(stride_s=fw_cfg.stride_s))
    ports = _open_ports(cfg)
    try:
        seen = {"motor": check_motor(ports.motor, cfg.motor, timeout_s=cfg.startup_timeout_s),
                "imu": check_imu(ports.imu, cfg.imu, timeout_s=cfg.startup_timeout_s)}
    except BaseException:
        ports.close()
        raise
    out.mkdir(parents=True, exist_ok=True)
    capture = CaptureUart(out / "telemetry.bin", cfg.telemetry_baud, inner=ports.telemetry)
    try:
        return _run(cfg, ports, capture, f_cpu, fw_cfg, reference, seen, progress)
    finally:
        capture.close()
        ports.close()


def _run(cfg: SerialRunConfig, ports: _Ports, capture: CaptureUart, f_cpu: int, fw_cfg: FirmwareConfig,
         reference: GaitReference, seen: dict[str, int], progress: Callable[[float], None] | None) -> SerialRunResult:
    """Build the board, the firmware and the wall-clock RTOS on opened ports, run, collect."""
    clock = WallClock(f_cpu)
    now = SchedulerNow()  # the board is built before the scheduler: bound to it below
    wd = Watchdog(int(WATCHDOG_TIMEOUT_S * f_cpu))
    feedback_angle = FeedbackAngle()
    if cfg.encoder == "sim":
        assert ports.devices is not None
        devices = ports.devices
        encoder = VirtualEncoderTimer(devices.now, EncoderMount(devices.world).angle_rad)
    else:
        encoder = VirtualEncoderTimer(lambda: 0, feedback_angle.angle_rad)
    board = Board(motor_uart=ports.motor, imu_uart=ports.imu, telemetry_uart=capture, encoder=encoder,
                  estop=NullDigitalIn(False), led=NullDigitalOut(), watchdog=_KernelWatchdog(wd),
                  now_cycles=now, f_cpu_hz=f_cpu)
    fw = Firmware(board, fw_cfg, reference=reference)
    wd.on_reset = fw.on_watchdog_reset
    feedback_angle.feedback = fw.motor.feedback
    plant = ports.devices.world.plant if ports.devices is not None and ports.devices.motor is not None else None
    probe, link = Probe(), _LinkWatch(cfg, fw)
    timings = TaskTimings([t.name for t in fw.tasks], f_cpu, time.perf_counter_ns)

    def probe_body(job) -> None:  # bench instrument, not firmware
        t = job.start / f_cpu
        probe.sample(t, fw, plant.output_angle_rad(plant.latest_time_s) if plant is not None
                     else fw.out.fused_angle_rad)
        if link.step(t):
            sched.request_stop()
        if job.index % GC_EVERY_TICKS == 0:
            gc.collect(0)  # young objects only: tens of µs, never a full scan in the loop

    tasks = [instrument(t, timings) for t in fw.tasks]
    tasks.append(Task("serial_probe", 99, period=f_cpu // PROBE_HZ, cost=0, body=probe_body))
    trace = Trace(cfg.trace_capacity) if cfg.trace_capacity else None
    sched = Scheduler(tasks, clock, trace=trace, on_fault=lambda f: fw.on_task_fault(f.task, f.time),
                      seed=cfg.seed)
    now.bind(sched)
    fw.kernel_health = kernel_health(sched, fw)
    sched.add_watchdog(wd)
    interrupted = False
    gc_was_enabled = gc.isenabled()
    gc.collect()
    gc.freeze()  # what exists now is never scanned again; the probe collects the young generation
    gc.disable()
    started_unix = time.time()  # the wall clock is anchored at cycle 0 right after this
    wall0 = time.perf_counter()
    try:
        sched.run_until(int(cfg.duration_s * f_cpu), progress=progress)
    except KeyboardInterrupt:
        interrupted = True
        log.warning("interrupted at %.3f s", sched.now / f_cpu)
    finally:
        gc.unfreeze()
        if gc_was_enabled:
            gc.enable()
    wall = time.perf_counter() - wall0
    run_s = sched.now / f_cpu
    strides = 0
    if fw.gait_start_s is not None:
        strides = max(0, int((min(run_s, probe.t_s[-1] if probe.t_s else 0.0) - fw.gait_start_s)
                             // fw_cfg.stride_s))
    cfg.strides = strides
    return SerialRunResult(cfg, fw, sched, probe, timings, capture.captured(), run_s, wall, fw.gait_start_s,
                           started_unix, "plant" if plant is not None else "fused estimate", link.event,
                           interrupted, capture.inner_error, seen)


class _LinkWatch:
    """Watches for LINK_LOST: records the event; stops shortly after, or reopens the port with reconnect."""

    def __init__(self, cfg: SerialRunConfig, fw: Firmware) -> None:
        self.cfg, self.fw = cfg, fw
        self.event: LinkEvent | None = None
        self.stop_at: float | None = None
        self.next_try = 0.0

    def step(self, t: float) -> bool:
        """Called every probe tick at time t (s); True when the run should stop."""
        sup, fw = self.fw.supervisor, self.fw
        if self.event is None and (fw.motor.link_lost or fw.imu.link_lost) and sup.tripped_at_s is not None:
            drv, role = (fw.motor, "motor") if fw.motor.link_lost else (fw.imu, "imu")
            self.event = LinkEvent(role, getattr(self.cfg, role), drv.lost_reason, drv.lost_at_s,
                                   sup.tripped_at_s)
            log.warning("%s port %s lost at %.4f s: %s", role, self.event.port, t, drv.lost_reason)
            if not self.cfg.reconnect:
                self.stop_at = t + STOP_AFTER_LOSS_S
            self.next_try = t + RECONNECT_EVERY_S
        if self.stop_at is not None:
            return t >= self.stop_at
        if self.event is not None and self.cfg.reconnect and t >= self.next_try:
            self.next_try = t + RECONNECT_EVERY_S
            self._try_reopen()
        return False

    def _try_reopen(self) -> None:
        """Reopen every lost port that is back; the supervisor stays latched in SAFE."""
        cfg = self.cfg
        for role, drv, baud in (("motor", self.fw.motor, cfg.baud), ("imu", self.fw.imu, cfg.imu_baud)):
            if not drv.link_lost:
                continue
            try:
                uart = open_uart(getattr(cfg, role), baud, role=role)
            except (HalError, ValueError) as exc:
                log.debug("%s port not back yet: %s", role, exc)
                continue
            drv.uart.close()
            drv.relink(uart)
            assert self.event is not None
            self.event.reconnects += 1
            log.warning("%s port %s reopened; staying in the safe state", role, getattr(cfg, role))
