"""Firmware configuration from a TOML profile (rates, gains, safety limits, cycle costs)."""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass, field, fields
from pathlib import Path
from typing import Any

from firmware.control.filters import ORDER_RANGE
from firmware.control.pid import FeedforwardParams, PidGains
from firmware.control.validation import check_int_range, check_range, is_number
from firmware.safety import SafetyLimits
from profiles import profile_path, read_toml
from protocol.rvc import RVC_RATE_HZ

__all__ = ["DEFAULT_PROFILE", "SECTIONS", "TASK_NAMES", "CostModel", "FirmwareConfig", "load_firmware_config"]

DEFAULT_PROFILE = profile_path("firmware.toml")
RATE_FIELDS = ("control_hz", "imu_poll_hz", "logger_hz", "watchdog_kick_hz", "full_values_hz")  # [rates_hz] + "_hz"
SECTIONS = ("rates_hz", "control", "feedforward", "safety", "task_cycles", "motor", "controller")
"""The tables of a firmware profile ([control] holds the sub-tables position and velocity)."""
TASK_NAMES = ("encoder", "supervisor", "control", "motor", "imu", "logger", "watchdog")
"""The firmware's tasks (firmware.app's table): the names [task_cycles] may price."""
MAX_JOB_CYCLES = 10_000_000
"""Largest cost of one job, base + per_byte * 512 bytes (60 ms at 168 MHz: no task of ours comes near)."""
MAX_CURRENT_A = 100.0
"""Largest current command limit: above the AK60-6's 22.7 A peak, well inside the wire's int32 field."""
# [control] scalars: (lo, hi, lo_open, hi_open, unit); hi None = a bound from the rates, checked in FirmwareConfig
CONTROL_RANGES: dict[str, tuple[float, float, bool, bool, str]] = {
    "current_limit_a": (0.0, MAX_CURRENT_A, True, False, "A"),
    "velocity_limit_rad_s": (0.0, 100.0, True, False, "rad/s"),
    "imu_lowpass_hz": (0.0, RVC_RATE_HZ / 2, False, True, "Hz (0 = off; below the IMU's Nyquist)"),
    "estimator_offset_tau_s": (0.0, 1000.0, True, False, "s"),
    "velocity_cutoff_hz": (0.0, 5000.0, True, False, "Hz"),
    "stride_s": (0.2, 10.0, False, False, "s"),
    "startup_ramp_s": (0.0, 10.0, False, False, "s"),
    "com_angle_rad": (-math.pi, math.pi, False, False, "rad"),
}


@dataclass(frozen=True)
class CostModel:
    """Cycles of one job: `base + per_byte * bytes handled` (an estimate to calibrate with DWT->CYCCNT)."""

    base: int
    per_byte: int = 0

    def __post_init__(self) -> None:
        """Refuse a cost no job could have (negative, or over MAX_JOB_CYCLES with 512 bytes handled)."""
        check_int_range("base", self.base, 0, MAX_JOB_CYCLES)
        check_int_range("per_byte", self.per_byte, 0, MAX_JOB_CYCLES // 512)
        if self.base + 512 * self.per_byte > MAX_JOB_CYCLES:
            raise ValueError(f"base + 512 * per_byte = {self.base + 512 * self.per_byte} is not allowed: "
                             f"must be at most {MAX_JOB_CYCLES} cycles")

    def __call__(self, handled: object) -> int:
        """Price a job from what its body returned (bytes handled, or None)."""
        return self.base + self.per_byte * (handled if isinstance(handled, int) else 0)


@dataclass(frozen=True)
class FirmwareConfig:
    """Everything the firmware is configured with; see profiles/firmware.toml."""

    control_hz: int = 1000
    imu_poll_hz: int = 500
    logger_hz: int = 500
    watchdog_kick_hz: int = 100
    full_values_hz: int = 10
    current_limit_a: float = 12.0
    velocity_limit_rad_s: float = 8.0
    feedforward: bool = True
    imu_lowpass_hz: float = 0.0
    imu_lowpass_order: int = 2
    estimator_offset_tau_s: float = 2.0
    velocity_cutoff_hz: float = 40.0
    stride_s: float = 1.1
    startup_ramp_s: float = 0.5
    com_angle_rad: float = math.pi / 2
    position_gains: PidGains = PidGains(8.0, 2.0, 0.02, 0.004)
    velocity_gains: PidGains = PidGains(0.2, 3.0)
    feedforward_params: FeedforwardParams = FeedforwardParams(0.0495, 1.176, 0.150, 0.078, 28.0, 0.855)
    safety: SafetyLimits = SafetyLimits()
    task_cycles: dict[str, Callable[[object], int]] = field(default_factory=dict)  # CostModel or any such callable
    motor_link: str = "uart"  # [motor] link: a name of firmware.drivers.motor_links.MOTOR_LINKS
    motor_can_id: int = 1  # [motor] can_id: the motor's driver id on a CAN link
    controller: str = "cascade"  # a shipped controller's name (firmware.control.registry) or FILE.py:CLASS
    controller_params: dict[str, Any] = field(default_factory=dict)  # the profile's [controller] table

    def __post_init__(self) -> None:
        """Check every rate, control scalar and task name (profile keys: firmware/config.py's tables)."""
        for name in RATE_FIELDS:
            check_int_range(name, getattr(self, name), 1, 10_000)
        from firmware.drivers.motor_links import MOTOR_LINKS  # imports firmware.config

        MOTOR_LINKS.check(self.motor_link, "motor_link")  # ValueError naming the choices
        check_int_range("motor_can_id", self.motor_can_id, 0, 127)
        if self.full_values_hz > self.control_hz:
            raise ValueError(
                f"full_values_hz {self.full_values_hz} out of range: <= control_hz {self.control_hz}")
        _check_control(lambda name: getattr(self, name), self.control_hz)
        unknown = sorted(set(self.task_cycles) - set(TASK_NAMES))
        if unknown:
            raise ValueError(f"task {unknown[0]!r} is not a firmware task: one of {', '.join(TASK_NAMES)}")

    def cost(self, task: str) -> Callable[[object], int]:
        """The cost model of `task` (a small default if the profile does not name it)."""
        return self.task_cycles.get(task, CostModel(500))

    def with_changes(self, **changes: Any) -> FirmwareConfig:
        """A copy with some fields replaced (e.g. gains from `pafp tune`)."""
        from dataclasses import replace

        return replace(self, **changes)


def _check_control(value: Callable[[str], Any], control_hz: int) -> None:
    """Check the [control] scalars, read through value(name)."""
    for name, (lo, hi, lo_open, hi_open, unit) in CONTROL_RANGES.items():
        check_range(name, value(name), lo, hi, lo_open=lo_open, hi_open=hi_open, unit=unit)
    check_int_range("imu_lowpass_order", value("imu_lowpass_order"), *ORDER_RANGE)
    if not value("velocity_cutoff_hz") < control_hz / 2:
        raise ValueError(f"velocity_cutoff_hz = {value('velocity_cutoff_hz')!r} is not allowed: must be below "
                         f"control_hz / 2 = {control_hz / 2:g} Hz")
    if not isinstance(value("feedforward"), bool):
        raise ValueError(f"feedforward = {value('feedforward')!r} is not allowed: must be true or false")


def _gains(table: dict[str, Any], where: str) -> PidGains:
    try:
        return PidGains(**table)
    except TypeError as e:
        raise ValueError(f"[{where}] has no such key ({e})") from None


def _rates(table: dict[str, Any]) -> dict[str, Any]:
    """[rates_hz] keys as FirmwareConfig fields (`control` -> `control_hz`); ValueError names an unknown key."""
    out = {}
    for key, value in table.items():
        if f"{key}_hz" not in RATE_FIELDS:
            raise ValueError(f"[rates_hz] has no key {key!r}: the keys are "
                             f"{', '.join(f.removesuffix('_hz') for f in RATE_FIELDS)}")
        check_int_range(key, value, 1, 10_000)
        out[f"{key}_hz"] = value
    return out


def _safety(table: dict[str, Any]) -> dict[str, Any]:
    """[safety] keys as SafetyLimits fields (`*_deg` in degrees -> `*_rad`); ValueError names an unknown key."""
    known = {f.name for f in fields(SafetyLimits)}
    out = {}
    for key, value in table.items():
        degrees = key.endswith("_deg")
        name = key[:-len("_deg")] + "_rad" if degrees else key
        if name not in known:
            raise ValueError(f"[safety] has no key {key!r}")
        # a value that is no number goes on unconverted: SafetyLimits' check names it and its range
        out[name] = math.radians(value) if degrees and is_number(value) else value
    return out


def _control(table: dict[str, Any], control_hz: int) -> dict[str, Any]:
    """[control] scalars as FirmwareConfig fields, each checked; ValueError names an unknown key."""
    known = (*CONTROL_RANGES, "feedforward", "imu_lowpass_order")
    for key in table:
        if key not in known:
            raise ValueError(f"[control] has no key {key!r}: the keys are {', '.join(known)}, and the "
                             "tables [control.position], [control.velocity]")
    # the checks of FirmwareConfig that concern [control], made here so that the error names the section
    defaults = FirmwareConfig()
    _check_control(lambda name: table.get(name, getattr(defaults, name)), control_hz)
    return table


def _task_cycles(table: dict[str, Any]) -> dict[str, Callable[[object], int]]:
    """[task_cycles] as cost models: known task names only, each `{ base = N [, per_byte = M] }`."""
    out: dict[str, Callable[[object], int]] = {}
    for task, spec in table.items():
        if task not in TASK_NAMES:
            raise ValueError(f"task {task!r} is not a firmware task: one of {', '.join(TASK_NAMES)}")
        if not isinstance(spec, dict) or set(spec) - {"base", "per_byte"} or "base" not in spec:
            raise ValueError(f"{task} = {spec!r} is not allowed: must be {{ base = N }} or "
                             "{ base = N, per_byte = M } (cycles)")
        try:
            out[task] = CostModel(**spec)
        except ValueError as e:
            raise ValueError(f"{task}: {e}") from None
    return out


def _section(doc: dict[str, Any], name: str) -> dict[str, Any]:
    table = doc.get(name, {})
    if not isinstance(table, dict):
        raise ValueError(f"{name} must be a table [{name}], got {table!r}")
    return table


def _controller(table: dict[str, Any], profile: Path) -> dict[str, Any]:
    """[controller]: `name` (a shipped one or FILE.py:CLASS, a relative FILE taken from the profile's
    folder); every other key goes to the controller's constructor as a dict."""
    params = dict(table)
    name = params.pop("name", "cascade")
    if not isinstance(name, str):
        raise ValueError(f"name = {name!r} is not a string")
    file, sep, cls = name.rpartition(":")
    if sep and file.endswith(".py") and not Path(file).is_absolute():
        name = f"{profile.parent / file}:{cls}"
    return {"controller": name, "controller_params": params}


def load_firmware_config(path: str | Path | None = None) -> FirmwareConfig:
    """Read a firmware profile (default: profiles/firmware.toml); errors name the file, the section and the key."""
    p = Path(path) if path is not None else DEFAULT_PROFILE
    doc = read_toml(p, "firmware profile")
    unknown = sorted(set(doc) - set(SECTIONS))
    if unknown:
        raise ValueError(f"firmware profile {p}: unknown section [{unknown[0]}]: the sections are "
                         f"{', '.join(f'[{n}]' for n in SECTIONS)}")
    section = "rates_hz"
    try:
        rates = _rates(_section(doc, "rates_hz"))
        section = "control"
        ctl = dict(_section(doc, "control"))
        pos, vel = ctl.pop("position", {}), ctl.pop("velocity", {})
        control_hz = rates.get("control_hz", FirmwareConfig.control_hz)
        _control(ctl, control_hz if isinstance(control_hz, int) else FirmwareConfig.control_hz)
        section = "control.position"
        position_gains = _gains(pos, section)
        section = "control.velocity"
        velocity_gains = _gains(vel, section)
        section = "feedforward"
        try:
            feedforward_params = FeedforwardParams(**_section(doc, "feedforward"))
        except TypeError as e:
            raise ValueError(f"has no such key ({e})") from None
        section = "safety"
        try:
            safety = SafetyLimits(**_safety(_section(doc, "safety")))
        except TypeError as e:
            raise ValueError(f"has no such key ({e})") from None
        section = "task_cycles"
        task_cycles = _task_cycles(_section(doc, "task_cycles"))
        section = "motor"
        motor = _section(doc, "motor")
        unknown = sorted(set(motor) - {"link", "can_id"})
        if unknown:
            raise ValueError(f"has no key {unknown[0]!r}: its keys are link, can_id")
        links = {"motor_link": motor["link"]} if "link" in motor else {}
        if "can_id" in motor:
            links["motor_can_id"] = motor["can_id"]
        section = "controller"
        controller = _controller(_section(doc, "controller"), p)
        section = "rates_hz"  # what is left: checks across sections, which name their keys
        return FirmwareConfig(**rates, position_gains=position_gains, velocity_gains=velocity_gains,
                              feedforward_params=feedforward_params, safety=safety, task_cycles=task_cycles,
                              **links, **controller, **ctl)
    except ValueError as e:
        msg = str(e)
        where = "" if msg.startswith("[") else f"[{section}] "
        raise ValueError(f"firmware profile {p}: {where}{msg}") from None
