"""Runs the firmware on the virtual bench: build the world, the RTOS and the firmware, run, collect.

This is the composition root of virtual mode: the only place that knows the firmware, the virtual
bench and the kernel together. The firmware gets a `Board`; the kernel gets the firmware's tasks and
the bench's interrupt sources; a zero-cost bench probe (lowest priority, not part of the firmware)
samples the plant's true angle for the tracking metrics.
"""

from __future__ import annotations

import time
import tomllib
from collections.abc import Callable
from dataclasses import dataclass, field, replace
from pathlib import Path

from firmware.app import Firmware
from firmware.config import FirmwareConfig, load_firmware_config
from firmware.control.reference import GaitReference
from hal.virtual.bench import VirtualBench
from hal.virtual.plant.walking import walk
from host_tools.probe import Action, Probe, ProbeBody
from host_tools.walk import SCENARIOS, SPEEDS, all_speeds_path, walking_load
from host_tools.wire_capture import WireCapture
from rtos import Scheduler, Task, Trace, VirtualClock, Watchdog
from rtos.analysis import TaskBound, response_time_bounds
from rtos.scheduler import SchedulerNow
from rtos.stats import DeadlineHealth

__all__ = ["Probe", "RunConfig", "RunResult", "board_profile", "kernel_health", "run_virtual"]

PROFILES = Path(__file__).resolve().parents[1] / "profiles"
PROBE_HZ = 500
WATCHDOG_TIMEOUT_S = 0.050


def board_profile(name: str = "stm32f4") -> dict:
    """Load profiles/board_<name>.toml (clock and interrupt costs)."""
    path = PROFILES / f"board_{name}.toml"
    if not path.exists():
        choices = sorted(p.stem.removeprefix("board_") for p in PROFILES.glob("board_*.toml"))
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
    trace_capacity: int = 200_000
    setup: Callable[[VirtualBench, Firmware], None] | None = None  # fault injection, fixtures
    bench_options: dict = field(default_factory=dict)  # extra VirtualBench arguments (e.g. rx_buffer_size)
    # (time_s, action(bench, firmware)) run by the bench probe at the first probe tick >= time_s: faults
    # that must happen at their time (bytes on a line, a pressed switch), not at set-up
    actions: list[tuple[float, Action]] = field(default_factory=list)
    capture_dir: Path | None = None  # raw bytes of every port, both directions (host_tools/wire_capture.py)
    controller: object = None  # a built controller (None: the firmware profile's [controller])
    scenario: str = "suspended"  # or "walk": the ground's moment in stance (host_tools/walk.py)
    body_mass_kg: float = 80.0  # walk: the walker's mass (the moment scales with it)
    moment_csv: Path | None = None  # walk: the ankle moment per kg (default: the packaged normative curve)
    speed: str | None = None  # a speed group of the packaged data (host_tools/walk.py SPEEDS): reference and moment

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


def run_virtual(cfg: RunConfig, progress: Callable[[float], None] | None = None) -> RunResult:
    """Run the firmware on the virtual suspended-foot bench for cfg.strides strides."""
    board_cfg = board_profile(cfg.board)
    f_cpu = int(board_cfg["f_cpu_hz"])
    isr = dict(board_cfg.get("isr_cycles", {}))
    fw_cfg = cfg.firmware or load_firmware_config()
    reference = (GaitReference.from_csv(cfg.reference_csv, stride_s=fw_cfg.stride_s) if cfg.reference_csv
                 else GaitReference.from_csv(all_speeds_path(), stride_s=fw_cfg.stride_s,
                                             select={"speed_category": SPEEDS[cfg.speed]}) if cfg.speed
                 else GaitReference.normative(stride_s=fw_cfg.stride_s))
    clock = VirtualClock(f_cpu)
    now = SchedulerNow()  # the bench is built before the scheduler: bound to it below
    load = (walking_load(cfg.body_mass_kg, fw_cfg.stride_s, cfg.moment_csv, cfg.speed) if cfg.scenario == "walk"
            else None)
    bench = VirtualBench(now, f_cpu, motor_baud=cfg.baud, seed=cfg.seed,
                         systick_hz=int(board_cfg.get("systick_hz", 1000)),
                         **({"fixture": walk(load)} if load is not None else {}), **cfg.bench_options)
    wire = WireCapture(cfg.capture_dir, lambda: now() / f_cpu) if cfg.capture_dir is not None else None
    fw = Firmware(bench.board if wire is None else wire.tap_board(bench.board), fw_cfg, reference=reference,
                  controller=cfg.controller)
    if load is not None:
        load.bind(lambda: fw.gait_start_s)  # the walker's strides on the firmware's gait clock
    probe = Probe()
    # bench instrument, not firmware: zero cycles, lowest priority
    probe_body = ProbeBody(probe, bench, fw, f_cpu, sorted(cfg.actions, key=lambda a: a[0]))
    probe_task = Task("bench_probe", 99, period=f_cpu // PROBE_HZ, cost=0, body=probe_body)
    interrupts = bench.interrupt_sources(isr)
    trace = Trace(cfg.trace_capacity) if cfg.trace_capacity else None
    sched = Scheduler([*fw.tasks, probe_task], clock, interrupts=interrupts, trace=trace,
                      on_fault=lambda f: fw.on_task_fault(f.task, f.time), seed=cfg.seed)
    now.bind(sched)
    fw.kernel_health = kernel_health(sched, fw)
    wd = Watchdog(int(WATCHDOG_TIMEOUT_S * f_cpu), on_reset=fw.on_watchdog_reset)
    sched.add_watchdog(wd)
    bench.attach_watchdog(wd)
    # Analyse the declared task set (worst-case costs) before running, so a fault injected through a
    # cost model during the run cannot change the bound it is compared with.
    max_bytes = {"motor": 128, "imu": 128, "logger": 64}
    # the same interrupt model the scheduler counts (bench.interrupt_sources checked both ISR costs)
    byte_cycles = {name: (10 * f_cpu) // u.baud for name, u in bench.board.uarts().items() if name != "telemetry"}
    sporadic = [_Sporadic(f"{n}_rx", max(1, c), int(isr["uart_rx_byte"])) for n, c in byte_cycles.items()]
    sporadic.append(_Sporadic("systick", bench.mcu.systick.period_cycles, int(isr["systick"])))
    bounds = response_time_bounds(_analysis_tasks(fw, max_bytes), sporadic)
    if cfg.setup:
        cfg.setup(bench, fw)

    sim_s = cfg.settle_s + fw_cfg.startup_ramp_s + cfg.strides * fw_cfg.stride_s + 0.05
    wall0 = time.perf_counter()
    try:
        sched.run_until(int(sim_s * f_cpu), progress=progress)
    finally:
        if wire is not None:
            wire.close()
    wall = time.perf_counter() - wall0

    return RunResult(cfg, fw, bench, sched, bounds, probe, bench.telemetry_bytes(), sched.now / f_cpu, wall,
                     fw.gait_start_s)
