"""Runs the firmware on the virtual bench: build the world, the RTOS and the firmware, run, collect.

This is the composition root of virtual mode: the only place that knows the firmware, the virtual
bench and the kernel together. The firmware gets a `Board`; the kernel gets the firmware's tasks and
the bench's interrupt sources; a zero-cost bench probe (lowest priority, not part of the firmware)
samples the plant's true angle for the tracking metrics.

The scheduler runs in segments of SEGMENT_S simulated seconds (the outputs are the same byte for byte
as in one go); with ``RunConfig.stream_to`` set, what each segment produced goes to the files at once
(host_tools/reports/run_files.py), so a run's memory does not grow with its length, and ``should_stop`` is asked
between segments (a stop signal: the run ends there, marked incomplete).
"""

from __future__ import annotations

import math
import time
import tomllib
from collections.abc import Callable
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any

from firmware.app import Firmware
from firmware.config import FirmwareConfig, load_firmware_config
from firmware.control.reference import GaitReference
from firmware.control.registry import build_controller
from hal.virtual.bench import CAN_RX_CYCLES, VirtualBench
from hal.virtual.devices.bno08x_config import imu_reading_of
from hal.virtual.imperfections import Imperfections, load_imperfections
from hal.virtual.plant import load_plant_params
from hal.virtual.plant.battery import load_battery
from hal.virtual.plant.design import Design, plant_params_for
from hal.virtual.plant.draw import draw_plant, drawn_values
from hal.virtual.plant.imperfections import active as active_imperfections
from hal.virtual.plant.motors import load_motor
from hal.virtual.plant.readings import DRIVERS, geometry_of
from hal.virtual.plant.thermal import ThermalParams
from hal.virtual.plant.walking import walk
from host_tools.probe import Action, Probe, ProbeBody
from host_tools.reports.heat_log import HeatLog
from host_tools.reports.run_files import RunFiles
from host_tools.reports.tracking_stream import probe_stream
from host_tools.walk import SCENARIOS, SPEEDS, all_speeds_path, ground_reaction, walking_load
from host_tools.wire_capture import WireCapture
from profiles import profile_path, profile_paths
from rtos import Scheduler, Task, Trace, VirtualClock, Watchdog
from rtos.analysis import TaskBound, response_time_bounds
from rtos.scheduler import SchedulerNow
from rtos.stats import DeadlineHealth

__all__ = ["Probe", "RunConfig", "RunResult", "board_profile", "gait_reference", "kernel_health", "reference_record",
           "run_virtual"]

SENSOR_FAULTS = {"fsr_heel": ("open", "short"), "fsr_toe": ("open", "short"), "load_cell": ("open", "stuck_high")}
"""The ground sensors' faults a run can start with (hal/virtual/devices/fsr.py, load_cell.py)."""
PROBE_HZ = 500
SEGMENT_S = 1  # simulated seconds between two hand-overs to the files (and two checks of should_stop)
WATCHDOG_TIMEOUT_S = 0.050


def reference_record(csv: Path | None, speed: str | None) -> dict:
    """What a record's header says of the gait reference (`gait_reference` builds it back)."""
    return {"csv": None if csv is None else str(Path(csv).resolve()), "speed": speed}


def gait_reference(reference: dict, stride_s: float) -> GaitReference:
    """The gait reference of a run: a CSV, a speed group of the packaged data, or the normative curve."""
    csv, speed = reference.get("csv"), reference.get("speed")
    if csv:
        return GaitReference.from_csv(Path(csv), stride_s=stride_s)
    if speed:
        return GaitReference.from_csv(all_speeds_path(), stride_s=stride_s, select={"speed_category": SPEEDS[speed]})
    return GaitReference.normative(stride_s=stride_s)


def board_profile(name: str = "stm32f4") -> dict:
    """Load profiles/board_<name>.toml (clock and interrupt costs)."""
    path = profile_path(f"board_{name}.toml")
    if not path.is_file():
        choices = [p.stem.removeprefix("board_") for p in profile_paths("board_*.toml")]
        raise ValueError(f"board profile {name!r} not found: choose one of {choices}")
    return tomllib.loads(path.read_text(encoding="utf-8"))


@dataclass
class RunConfig:
    """What to run: strides of gait on the suspended-foot bench, link speed, profiles, seed."""

    strides: int = 10
    baud: int = 921600
    seed: int = 0
    board: str = "stm32f4"
    firmware: FirmwareConfig | None = None
    reference_csv: Path | None = None
    settle_s: float = 1.0  # time before the gait starts (sensors boot, start-up ramp)
    trace_capacity: int = 400_000  # the trace keeps at most this many jobs (0: no trace)
    trace_window_s: float | None = 20.0  # ... of the last this many seconds of the run (None: the whole run)
    trace_wire: bool = False  # the trace shows every UART and CAN frame too (host_tools/reports/wire_trace.py)
    stream_to: Path | None = None  # write telemetry.bin/.csv there as the run goes (see RunFiles)
    setup: Callable[[VirtualBench, Firmware], None] | None = None  # fault injection, fixtures
    bench_options: dict = field(default_factory=dict)  # extra VirtualBench arguments (e.g. rx_buffer_size)
    # (time_s, action(bench, firmware)) run by the bench probe at the first probe tick >= time_s: faults
    # that must happen at their time (bytes on a line, a pressed switch), not at set-up
    actions: list[tuple[float, Action]] = field(default_factory=list)
    capture_dir: Path | None = None  # raw bytes of every port, both directions (host_tools/wire_capture.py)
    record_to: Path | None = None  # record.bin there: every input the firmware saw, for `pafp replay`
    # the plant drawn from its tolerances with this seed (hal.virtual.plant.draw); None: the nominal plant
    plant_seed: int | None = None
    plant_file: Path | None = None  # a plant profile (e.g. one `pafp fit` wrote) instead of the packaged one
    # the bench's imperfections (None: profiles/bench_imperfections.toml, the real device) and those off
    imperfections: Imperfections | None = None
    ideal: tuple[str, ...] = ()
    controller: object = None  # a built controller (None: the firmware profile's [controller])
    scenario: str = "suspended"  # or "walk": the ground's moment in stance (host_tools/walk.py)
    body_mass_kg: float = 80.0  # walk: the walker's mass (the moment scales with it)
    moment_csv: Path | None = None  # walk: the ankle moment per kg (default: the packaged normative curve)
    speed: str | None = None  # a speed group of the packaged data (host_tools/walk.py SPEEDS): reference and moment
    population: str | None = None  # walk: "adult" or "child" moment curves (None: by body mass, host_tools/walk.py)
    # the load cell and heel/toe FSRs on the ADC (hal/virtual/ground_sensors.py); None: fitted when walking
    ground_sensors: bool | None = None
    sensor_faults: tuple[str, ...] = ()  # "PART:MODE" from the start, e.g. "fsr_heel:open" (SENSOR_FAULTS)
    # fault injectors and instruments (hal/virtual/faults), armed on the bench, the controller and the task costs
    faults: tuple = ()
    duration_s: float | None = None  # simulated time to run (None: settle + ramp + strides x stride + 50 ms)
    # the design profile's [design] (hal.virtual.plant.design): the plant is its motor, belt and spring around the
    # nominal foot, unless plant_file is given (which wins)
    design: Design | None = None
    ambient_c: float = 25.0  # the motor's surroundings: the winding starts at and cools towards it
    # a battery profile (profiles/batteries/ name or file) the motor draws from; None: the design's battery if it
    # names one, else the ideal supply (the plant profile's voltage behind the driver's source resistance)
    battery: str | Path | None = None
    thermal: bool = True  # the two-node winding model (hal.virtual.plant.thermal) behind the reported temperature

    def __post_init__(self) -> None:
        """Reject values the bench cannot run."""
        if not isinstance(self.strides, int) or not 1 <= self.strides <= 10_000:
            raise ValueError(f"strides {self.strides!r} out of range: an int in 1..10000")
        if not isinstance(self.baud, int) or not 9600 <= self.baud <= 3_000_000:
            raise ValueError(f"baud {self.baud!r} out of range: an int in 9600..3000000")
        if self.speed is not None and self.speed not in SPEEDS:
            raise ValueError(f"speed {self.speed!r} unknown: one of {list(SPEEDS)}")
        if self.scenario not in SCENARIOS:
            raise ValueError(f"scenario {self.scenario!r} unknown: one of {list(SCENARIOS)}")
        parts: dict[str, str] = {}
        for fault in self.sensor_faults:
            part, _, mode = fault.partition(":")
            if mode not in SENSOR_FAULTS.get(part, ()):
                raise ValueError(f"sensor fault {fault!r} unknown: PART:MODE, one of "
                                 f"{[f'{p}:{m}' for p, ms in SENSOR_FAULTS.items() for m in ms]}")
            if part in parts:  # one sensor has one mode: the last would silently win
                raise ValueError(f"sensor fault {fault!r}: {part} already has {parts[part]!r}: one fault per sensor")
            parts[part] = fault
        if self.sensor_faults and not self.sensors_fitted():
            raise ValueError("sensor faults need the ground sensors: walk, or fit them (ground_sensors)")
        if self.duration_s is not None and not (isinstance(self.duration_s, (int, float)) and
                                                0.0 < self.duration_s <= 86_400.0):
            raise ValueError(f"duration_s {self.duration_s!r} out of range: a number in (0, 86400] s")
        if isinstance(self.ambient_c, bool) or not isinstance(self.ambient_c, (int, float)) or \
                not -40.0 <= self.ambient_c <= 80.0:
            raise ValueError(f"ambient temperature {self.ambient_c!r} C out of range: a number in [-40, 80] C")
        if self.trace_window_s is not None and (isinstance(self.trace_window_s, bool) or not isinstance(
                self.trace_window_s, (int, float)) or not 0.0 < self.trace_window_s <= 86_400.0):
            raise ValueError(f"trace window {self.trace_window_s!r} s out of range: a number in (0, 86400] s")
        if self.plant_seed is not None and (isinstance(self.plant_seed, bool) or not isinstance(self.plant_seed, int)
                                            or not 0 <= self.plant_seed < 2**32):
            raise ValueError(f"plant seed {self.plant_seed!r} out of range: an int in 0..{2**32 - 1}")

    def sensors_fitted(self) -> bool:
        """Whether the bench has the ground sensors (by default when walking)."""
        return self.scenario == "walk" if self.ground_sensors is None else bool(self.ground_sensors)

    def design_bench_options(self) -> dict:
        """The virtual motor's MIT ranges when the design names a motor (its plant is in bench_setup)."""
        if self.design is None:
            return {}
        from protocol.can_mit import MitLimits

        m = self.design.motor_spec()
        return {"can_options": {"limits": MitLimits(m.p_max_rad, m.v_max_rad_s, m.t_max_nm)}}

    def _check_supply(self, rated_supply_v: float, motor_config: object) -> None:
        """ValueError (one line) when the run's battery would trip the motor driver's over-voltage limit at once."""
        battery = self.battery if self.battery is not None else getattr(self.design, "battery", None)
        if battery is None:
            return
        from hal.virtual.devices.ak60_config import Ak60Config

        pack = load_battery(battery)
        driver = motor_config if isinstance(motor_config, Ak60Config) else Ak60Config()
        driver.check_supply(pack.open_circuit_v(1.0), rated_supply_v, f"battery {battery}")

    def bench_setup(self) -> tuple[dict, dict]:
        """(VirtualBench arguments of the plant and the imperfections, their record for summary.json).

        Arguments given in bench_options win over both.
        """
        imp = (self.imperfections or load_imperfections()).without(self.ideal)
        nominal = load_plant_params(self.plant_file)
        if self.design is not None and self.firmware is not None:  # the firmware's ratings against the bench's motor
            from host_tools.design_profile import check_ratings

            check_ratings(self.design, self.firmware.motor, "design profile")
        if self.design is not None and self.plant_file is None:
            nominal = plant_params_for(self.design, nominal)
        params = nominal if self.plant_seed is None else draw_plant(nominal, self.plant_seed)
        options: dict = {"plant_params": params, **imp.bench_options(self.seed, params.backlash_deg),
                         **self.design_bench_options(),
                         **self.bench_options}
        params = options["plant_params"]
        self._check_supply(params.supply_voltage_v, options.get("motor_config"))
        record = {"plant": {"seed": self.plant_seed, "drawn": drawn_values(nominal, params),
                            "file": None if self.plant_file is None else str(self.plant_file),
                            **({} if self.design is None else
                               {"design": self.design.as_table(), "design_used": self.plant_file is None}),
                            "output_inertia_kg_m2": params.output_inertia_kg_m2,
                            "output_torque_per_amp_nm": params.output_torque_per_amp_nm,
                            "backlash_deg": round(math.degrees(options.get("backlash_rad", 0.0)), 9),
                            # the opt-in imperfections of its profile (hal/virtual/plant/imperfections.py)
                            "imperfections": list(active_imperfections(params))},
                  # the readings of the report the bench ran under (hal.virtual.plant.readings, docs/bench.md)
                  "readings": {"geometry": geometry_of(params), "driver": DRIVERS[0],
                               "imu": imu_reading_of(options["imu_config"])},
                  "imperfections": {**imp.as_dict(), "encoder_offset_rad": options.get("initial_angle_rad", 0.0)}}
        return options, record


@dataclass
class RunResult:
    """Everything a report needs from one run."""

    config: RunConfig
    firmware: Firmware
    bench: VirtualBench
    scheduler: Scheduler
    bounds: list[TaskBound]
    probe: Probe
    telemetry: bytes
    sim_time_s: float
    wall_time_s: float
    gait_start_s: float | None
    files: RunFiles | None = None  # the streamed files (then `telemetry` is empty and the probe drained)
    complete: bool = True  # False when should_stop ended the run early
    stopped_by: str | None = None  # what should_stop answered (a signal's name), when it ended the run
    bench_record: dict = field(default_factory=dict)  # the plant drawn and the imperfections (summary.json)
    # the thermal model, battery and heat log of the run (runner.attach_heat; host_tools/reports/thermal.py)
    heat: dict = field(default_factory=dict)
    timeline: Any = None  # what the trace shows beyond the scheduler's records (host_tools/reports/timeline.py)


def _analysis_tasks(fw: Firmware, max_bytes: dict[str, int]) -> list[Task]:
    """The task set with each cost model replaced by its worst case (bytes handled at most)."""
    return [replace(t, cost=t.cost(max_bytes.get(t.name, 0)) if callable(t.cost) else t.cost, body=None)
            for t in fw.tasks]


def kernel_health(sched: Scheduler, fw: Firmware) -> DeadlineHealth:
    """What the firmware asks the RTOS (misses, current streak) over the firmware's own tasks."""
    return DeadlineHealth([sched.stats[t.name] for t in fw.tasks])


@dataclass(frozen=True)
class _Sporadic:
    name: str
    period: int
    cost_cycles: int


def attach_heat(bench: VirtualBench, cfg: RunConfig) -> dict:
    """Fit the winding's thermal model and the battery the run asks for on the bench; return what was fitted.

    The thermal model takes the design's motor (``cfg.design.motor``) or the AK60-6 without a design; the
    battery is ``cfg.battery``, else the design's, else none (the ideal supply).
    """
    design = cfg.design  # a design profile's [design] table, or None
    motor = getattr(design, "motor", None) or "ak60_6"
    record: dict = {"ambient_c": float(cfg.ambient_c), "motor": motor, "thermal": cfg.thermal, "battery": None}
    if cfg.thermal:
        record["winding"] = bench.attach_thermal(ThermalParams.from_motor(load_motor(motor)), float(cfg.ambient_c))
    battery = cfg.battery if cfg.battery is not None else getattr(design, "battery", None)
    if battery is not None:
        record["battery"] = bench.attach_battery(load_battery(battery))
    return record


def _timeline(cfg: RunConfig, sched: Scheduler, fw: Firmware, bench: VirtualBench, rig: Any, f_cpu: int) -> Any:
    """The trace's timeline of a run, with a watch on the motor's commands from a trip on (on the faults' taps)."""
    from hal.virtual.faults.base import FaultRig
    from host_tools.reports.timeline import Timeline

    winding = bench.motor.meter.winding
    timeline = Timeline(sched, fw, f_cpu, cfg.trace_window_s,
                        winding=None if winding is None else lambda: float(winding.winding_c))
    rig = rig if rig is not None else FaultRig(bench, f_cpu)
    timeline.watch_from_trip(rig)
    if cfg.trace_wire:
        from host_tools.reports.wire_trace import WireTrace

        timeline.wire = WireTrace()
        timeline.wire.arm(rig)
    return timeline


def run_virtual(cfg: RunConfig, progress: Callable[[float], None] | None = None,
                should_stop: Callable[[], bool | str | None] | None = None) -> RunResult:
    """Run the firmware on the virtual suspended-foot bench for cfg.strides strides (or until should_stop() is
    true: a string it answers, e.g. a signal's name, is kept as ``RunResult.stopped_by``)."""
    board_cfg = board_profile(cfg.board)
    f_cpu = int(board_cfg["f_cpu_hz"])
    isr = dict(board_cfg.get("isr_cycles", {}))
    fw_cfg = cfg.firmware or load_firmware_config()
    reference = gait_reference(reference_record(cfg.reference_csv, cfg.speed), fw_cfg.stride_s)
    clock = VirtualClock(f_cpu)
    now = SchedulerNow()  # the bench is built before the scheduler: bound to it below
    load = (walking_load(cfg.body_mass_kg, fw_cfg.stride_s, cfg.moment_csv, cfg.speed, cfg.population)
            if cfg.scenario == "walk"
            else None)
    bench_options, bench_record = cfg.bench_setup()
    if load is not None:
        bench_options["fixture"] = walk(load)
        bench_options["ground"] = ground_reaction(load, cfg.speed)
    if cfg.sensors_fitted():
        from hal.virtual.ground_sensors import AdcSettings  # numpy and the sensor models: only when fitted

        bench_options.update(ground_sensors=True, adc=AdcSettings.from_board(board_cfg),
                             ground_profile=None if cfg.design is None else cfg.design.ground_profile)
    bench = VirtualBench(now, f_cpu, motor_baud=cfg.baud, seed=cfg.seed,
                         systick_hz=int(board_cfg.get("systick_hz", 1000)), motor_link=fw_cfg.motor_link,
                         can_id=fw_cfg.motor_can_id, **bench_options)
    bench_record["imperfections"]["imu_bias_rad"] = bench.imu.pitch_bias_rad  # drawn at power-up
    heat_record = attach_heat(bench, cfg)
    for fault in cfg.sensor_faults:
        part, _, mode = fault.partition(":")
        assert bench.ground_sensors is not None  # RunConfig checked
        bench.ground_sensors.set_fault(part, mode)
    wire = WireCapture(cfg.capture_dir, lambda: now() / f_cpu) if cfg.capture_dir is not None else None
    board = bench.board if wire is None else wire.tap_board(bench.board)
    recording = None
    if cfg.record_to is not None:
        from host_tools.recording import RunRecording

        recording = RunRecording(cfg.record_to, board, fw_cfg, "virtual",
                                 reference_record(cfg.reference_csv, cfg.speed), 0, {"seed": cfg.seed})
        board = recording.board
    controller, rig = cfg.controller, None
    if cfg.faults:
        from hal.virtual.faults.base import FaultRig

        rig = FaultRig(bench, f_cpu, controller if controller is not None else
                       build_controller(fw_cfg.controller, fw_cfg, fw_cfg.controller_params))
        for fault in cfg.faults:
            fault.arm(rig)
        controller = rig.controller
    fw = Firmware(board, fw_cfg, reference=reference, controller=controller)
    if rig is not None:
        fw.tasks = rig.tasks(fw.tasks)
    if load is not None:
        load.bind(lambda: fw.gait_start_s)  # the walker's strides on the firmware's gait clock
    probe = Probe()
    # bench instrument, not firmware: zero cycles, lowest priority
    probe_body = ProbeBody(probe, bench, fw, f_cpu, sorted(cfg.actions, key=lambda a: a[0]))
    heat = HeatLog(bench.motor.meter, fw.motor.feedback, lambda: fw.gait_start_s, fw_cfg.stride_s)
    probe_body.listeners.append(heat.sample)
    probe_task = Task("bench_probe", 99, period=f_cpu // PROBE_HZ, cost=0, body=probe_body)
    interrupts = bench.interrupt_sources(isr)
    # the probe's jobs are not recorded: the trace file never draws them (reports/timeline.py)
    trace = Trace(cfg.trace_capacity, skip=(probe_task.name,)) if cfg.trace_capacity else None
    tasks = fw.tasks if recording is None else recording.tasks(fw.tasks)
    sched = Scheduler([*tasks, probe_task], clock, interrupts=interrupts, trace=trace,
                      on_fault=lambda f: fw.on_task_fault(f.task, f.time), seed=cfg.seed)
    now.bind(sched)
    timeline = _timeline(cfg, sched, fw, bench, rig, f_cpu) if trace is not None else None
    if timeline is not None:
        probe_body.slow_listeners.append(timeline.sample)
    fw.kernel_health = kernel_health(sched, fw)
    if recording is not None:
        fw.kernel_health = recording.health(fw.kernel_health)
    wd = Watchdog(int(WATCHDOG_TIMEOUT_S * f_cpu), on_reset=fw.on_watchdog_reset)
    sched.add_watchdog(wd)
    bench.attach_watchdog(wd)
    # Analyse the declared task set (worst-case costs) before running, so a fault injected through a
    # cost model during the run cannot change the bound it is compared with.
    max_bytes = {"motor": 128, "imu": 128, "logger": 64}
    # the same interrupt model the scheduler counts (bench.interrupt_sources checked both ISR costs)
    byte_cycles = {name: (10 * f_cpu) // u.baud for name, u in bench.board.uarts().items() if name != "telemetry"}
    sporadic = [_Sporadic(f"{n}_rx", max(1, c), int(isr["uart_rx_byte"])) for n, c in byte_cycles.items()]
    if bench.can is not None:  # one RX interrupt per frame, frames at least an empty frame's 47 bits apart
        sporadic.append(_Sporadic("can_rx", max(1, 47 * f_cpu // bench.can.bitrate),
                                  int(isr.get("can_rx_frame", CAN_RX_CYCLES))))
    sporadic.append(_Sporadic("systick", bench.mcu.systick.period_cycles, int(isr["systick"])))
    bounds = response_time_bounds(_analysis_tasks(fw, max_bytes), sporadic)
    if cfg.setup:
        cfg.setup(bench, fw)

    sim_s = (cfg.settle_s + fw_cfg.startup_ramp_s + cfg.strides * fw_cfg.stride_s + 0.05 if cfg.duration_s is None
             else cfg.duration_s)
    t_end = int(sim_s * f_cpu)
    files = None
    if cfg.stream_to is not None:
        tracking = probe_stream(stride_s=fw_cfg.stride_s, strides=cfg.strides, dt_s=1.0 / PROBE_HZ,
                                expected_samples=int(sim_s * PROBE_HZ))
        files = RunFiles(cfg.stream_to, tracking, f_cpu, fw.published_names)
    wall = 0.0
    complete = True
    stopped_by = None
    segment = SEGMENT_S * f_cpu
    try:
        for t in [*range(segment, t_end, segment), t_end]:
            wall0 = time.perf_counter()
            sched.run_until(t)
            wall += time.perf_counter() - wall0
            if files is not None:
                files.drain(bench, probe, fw)
            if progress is not None:
                progress(t / t_end)
            reason = should_stop() if should_stop is not None else None
            if reason and t < t_end:
                complete = False
                stopped_by = reason if isinstance(reason, str) else "a stop request"
                break
    finally:
        if wire is not None:
            wire.close()
        if recording is not None:
            bench_record["record"] = recording.close({"complete": complete, "end_cycles": sched.now})
    if files is not None:
        files.close()
    bench_record["imperfections"]["backlash_crossings"] = bench.plant.raw.gap_crossings
    heat_record["log"] = heat
    telemetry = bench.telemetry_bytes() if files is None else b""
    return RunResult(cfg, fw, bench, sched, bounds, probe, telemetry, sched.now / f_cpu, wall, fw.gait_start_s,
                     files, complete, stopped_by=stopped_by, bench_record=bench_record, heat=heat_record,
                     timeline=timeline)
