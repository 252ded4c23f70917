"""Firmware configuration from a TOML profile (rates, gains, safety limits, cycle costs)."""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import MISSING, dataclass, field, fields
from pathlib import Path
from typing import Any

from firmware.control.filters import ORDER_RANGE
from firmware.control.pid import FeedforwardParams, PidGains
from firmware.control.validation import check_int_range, check_range, is_number
from firmware.drivers.ground_sensor_config import GroundSensorConfig
from firmware.motor_ratings import RATING_KEYS, MotorRatings
from firmware.safety import SafetyLimits
from firmware.safety_limits import ANGLE_LIMIT_RAD, PEAK_CURRENT_A, TIMEOUT_MAX_S, ThermalLimits
from profiles import profile_path, read_toml
from protocol.rvc import RVC_RATE_HZ

__all__ = ["DEFAULT_PROFILE", "SECTIONS", "TASK_NAMES", "CostModel", "FirmwareConfig", "load_firmware_config"]

DEFAULT_PROFILE = profile_path("firmware.toml")
RATE_FIELDS = ("control_hz", "imu_poll_hz", "logger_hz", "watchdog_kick_hz", "full_values_hz")  # [rates_hz] + "_hz"
SECTIONS = ("rates_hz", "control", "feedforward", "safety", "task_cycles", "motor", "controller", "ground_sensors",
            "host_watchdog", "thermal")
"""The tables of a firmware profile ([control] holds the sub-tables position and velocity)."""
HOST_SECTIONS = ("design",)
"""Tables a firmware profile may carry for the host, never read by the firmware: [design] (a design profile's motor,
belt and spring, checked by hal.virtual.plant.design.load_design where the bench is built; docs/design.md)."""
TASK_NAMES = ("encoder", "supervisor", "control", "motor", "imu", "logger", "watchdog")
"""The firmware's tasks (firmware.app's table): the names [task_cycles] may price."""
MAX_JOB_CYCLES = 10_000_000
"""Largest cost of one job, base + per_byte * 512 bytes (60 ms at 168 MHz: no task of ours comes near)."""
HOST_WATCHDOG_RANGE_S = (0.03, 0.5)
"""[host_watchdog] timeout_s: above the 10 ms kick interval plus the 20 ms age limits, at most half the motor's
own 1 s command timeout (docs/serial_mode.md, "The host watchdog")."""
MAX_CAN_ID = 127
"""Largest [motor] can_id: the driver id is the low byte of a servo-mode CAN id and MIT mode's 11-bit id (PROTOCOLS.md
section G); the firmware keeps to 0..127."""
MAX_VELOCITY_RAD_S = 560 * 2 * math.pi / 60 / (14 / 3)
"""Largest ankle velocity limit: the AK60-6's no-load output speed, 560 rpm (maker, PROTOCOLS.md section C), through
the 14:3 belt = 12.6 rad/s; the drive cannot go faster, so a higher limit would never act. With another motor in
[motor] (or another [safety] belt_ratio) the bound is that motor's no-load speed through that belt."""
# [control] scalars: (lo, hi, lo_open, hi_open, unit); the first two rows are the AK60-6's bounds, replaced by the
# profile's motor and belt in _check_control
CONTROL_RANGES: dict[str, tuple[float, float, bool, bool, str]] = {
    "current_limit_a": (0.0, PEAK_CURRENT_A, True, False, "A (the AK60-6's peak current)"),
    "velocity_limit_rad_s": (0.0, MAX_VELOCITY_RAD_S, True, False, "rad/s (the AK60-6's no-load speed at the ankle)"),
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
    thermal: ThermalLimits = ThermalLimits()  # [thermal]: derating and OVER_TEMPERATURE (firmware.safety_limits)
    task_cycles: dict[str, Callable[[object], int]] = field(default_factory=dict)  # CostModel or any such callable
    motor_link: str = "uart"  # [motor] link: a name of firmware.drivers.motor_links.MOTOR_LINKS
    motor_can_id: int = 1  # [motor] can_id: the motor's driver id on a CAN link
    controller: str = "cascade"  # a shipped controller's name (firmware.control.registry) or FILE.py:CLASS
    controller_params: dict[str, Any] = field(default_factory=dict)  # the profile's [controller] table
    ground_sensors: GroundSensorConfig = GroundSensorConfig()  # [ground_sensors]: used on boards with the ADC
    host_watchdog_s: float = 0.1  # [host_watchdog] timeout_s: serial mode's watchdog outside the loop

    def __post_init__(self) -> None:
        """Check every rate, control scalar and task name (profile keys: firmware/config.py's tables)."""
        for name in RATE_FIELDS:
            check_int_range(name, getattr(self, name), 1, 10_000)
        from firmware.drivers.motor_links import MOTOR_LINKS  # imports firmware.config

        MOTOR_LINKS.check(self.motor_link, "motor_link")  # ValueError naming the choices
        check_int_range("motor_can_id", self.motor_can_id, 0, MAX_CAN_ID)
        streak_max = max(1, int(TIMEOUT_MAX_S * self.control_hz))
        if self.safety.deadline_miss_streak > streak_max:
            raise ValueError(f"[safety] deadline_miss_streak = {self.safety.deadline_miss_streak} is not allowed: "
                             f"must be an integer in [1, {streak_max}] ({TIMEOUT_MAX_S:g} s of control periods "
                             f"at {self.control_hz} Hz, the longest age limit)")
        if self.full_values_hz > self.control_hz:
            raise ValueError(
                f"full_values_hz {self.full_values_hz} out of range: <= control_hz {self.control_hz}")
        _check_control(lambda name: getattr(self, name), self.control_hz, self.safety.motor, self.safety.belt_ratio)
        check_range("host_watchdog_s", self.host_watchdog_s, *HOST_WATCHDOG_RANGE_S, unit="s")
        unknown = sorted(set(self.task_cycles) - set(TASK_NAMES))
        if unknown:
            raise ValueError(f"task {unknown[0]!r} is not a firmware task: one of {', '.join(TASK_NAMES)}")

    @property
    def motor(self) -> MotorRatings:
        """The motor's ratings ([motor] of the profile; the AK60-6's by default)."""
        return self.safety.motor

    def cost(self, task: str) -> Callable[[object], int]:
        """The cost model of `task` (a small default if the profile does not name it)."""
        return self.task_cycles.get(task, CostModel(500))

    def with_changes(self, **changes: Any) -> FirmwareConfig:
        """A copy with some fields replaced (e.g. gains from `pafp tune`)."""
        from dataclasses import replace

        return replace(self, **changes)


def _check_control(value: Callable[[str], Any], control_hz: int, motor: MotorRatings | None = None,
                   belt_ratio: float | None = None) -> None:
    """Check the [control] scalars, read through value(name); the current and velocity bounds are the motor's."""
    ranges = dict(CONTROL_RANGES)
    if motor is not None and motor != MotorRatings():  # the AK60-6's bounds are the table's (its 14:3 belt)
        name = "AK60-6" if motor.model == "ak60_6" else motor.model
        ranges["current_limit_a"] = (0.0, motor.peak_current_a, True, False, f"A (the {name}'s peak current)")
        ranges["velocity_limit_rad_s"] = (0.0, motor.no_load_ankle_speed_rad_s(belt_ratio or SafetyLimits.belt_ratio),
                                          True, False, f"rad/s (the {name}'s no-load speed at the ankle)")
    for name, (lo, hi, lo_open, hi_open, unit) in ranges.items():
        check_range(name, value(name), lo, hi, lo_open=lo_open, hi_open=hi_open, unit=unit)
    check_int_range("imu_lowpass_order", value("imu_lowpass_order"), *ORDER_RANGE)
    if not value("velocity_cutoff_hz") < control_hz / 2:
        raise ValueError(f"velocity_cutoff_hz = {value('velocity_cutoff_hz')!r} is not allowed: must be below "
                         f"control_hz / 2 = {control_hz / 2:g} Hz")
    if not isinstance(value("feedforward"), bool):
        raise ValueError(f"feedforward = {value('feedforward')!r} is not allowed: must be true or false")


def _parameters(cls: Callable[..., Any], table: dict[str, Any]) -> Any:
    """cls(**table) for a dataclass of parameters; ValueError naming an unknown or a missing key and the keys."""
    if not isinstance(table, dict):
        raise ValueError(f"= {table!r}: expected a table of the keys {', '.join(f.name for f in fields(cls))}")
    keys = [f.name for f in fields(cls)]  # type: ignore[arg-type]
    required = [f.name for f in fields(cls) if f.default is MISSING]  # type: ignore[arg-type]
    unknown = [k for k in table if k not in keys]
    if unknown:
        raise ValueError(f"has no key {unknown[0]!r}: the keys are {', '.join(keys)}")
    missing = [k for k in required if k not in table]
    if missing:
        raise ValueError(f"needs {', '.join(missing)} (required; the keys are {', '.join(keys)})")
    return cls(**table)


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
    """[safety] keys as SafetyLimits fields (`*_deg` in degrees -> `*_rad`); ValueError names an unknown key.

    The angles are checked here in the profile's degrees, so that a message names the key as written.
    """
    known = {f.name for f in fields(SafetyLimits)} - {"motor"}
    out = {}
    for key, value in table.items():
        degrees = key.endswith("_deg")
        name = key[:-len("_deg")] + "_rad" if degrees else key
        if name not in known:
            raise ValueError(f"[safety] has no key {key!r}: the keys are {', '.join(_safety_keys())}")
        # a value that is no number goes on unconverted: the check names it and its range
        out[name] = math.radians(value) if degrees and is_number(value) else value
    limit_deg = math.degrees(ANGLE_LIMIT_RAD)
    for key in ("angle_min_deg", "angle_max_deg"):
        if key in table:
            check_range(key, table[key], -limit_deg, limit_deg, unit="deg (the foot along the shank)")
    if "disagreement_deg" in table:
        lo, hi = (table.get(k, math.degrees(getattr(SafetyLimits, k.replace("_deg", "_rad"))))
                  for k in ("angle_min_deg", "angle_max_deg"))
        check_range("disagreement_deg", table["disagreement_deg"], 0.0, hi - lo, lo_open=True,
                    unit="deg (the span of the angle limits)")
    return out


def _safety_keys() -> list[str]:
    """The [safety] keys of a profile: SafetyLimits' fields, angles in degrees."""
    return [f.name.removesuffix("_rad") + "_deg" if f.name.endswith("_rad") else f.name for f in fields(SafetyLimits)
            if f.name != "motor"]


def _control(table: dict[str, Any], control_hz: int, motor: MotorRatings, belt_ratio: float) -> dict[str, Any]:
    """[control] scalars as FirmwareConfig fields, each checked; ValueError names an unknown key."""
    known = (*CONTROL_RANGES, "feedforward", "imu_lowpass_order")
    for key in table:
        if key not in known:
            raise ValueError(f"[control] has no key {key!r}: the keys are {', '.join(known)}, and the "
                             "tables [control.position], [control.velocity]")
    # the checks of FirmwareConfig that concern [control], made here so that the error names the section
    defaults = FirmwareConfig()
    _check_control(lambda name: table.get(name, getattr(defaults, name)), control_hz, motor, belt_ratio)
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


def _host_watchdog(table: dict[str, Any]) -> dict[str, Any]:
    """[host_watchdog]: `timeout_s`, checked against HOST_WATCHDOG_RANGE_S."""
    unknown = sorted(set(table) - {"timeout_s"})
    if unknown:
        raise ValueError(f"has no key {unknown[0]!r}: its key is timeout_s")
    if "timeout_s" not in table:
        return {}
    return {"host_watchdog_s": check_range("timeout_s", table["timeout_s"], *HOST_WATCHDOG_RANGE_S, unit="s")}


def load_firmware_config(path: str | Path | None = None) -> FirmwareConfig:
    """Read a firmware profile (default: profiles/firmware.toml); errors name the file, the section and the key."""
    p = Path(path) if path is not None else DEFAULT_PROFILE
    doc = read_toml(p, "firmware profile")
    if not doc:
        raise ValueError(f"firmware profile {p} is empty: no section of {', '.join(f'[{n}]' for n in SECTIONS)} "
                         "(start from the shipped profiles/firmware.toml)")
    unknown = sorted(set(doc) - set(SECTIONS) - set(HOST_SECTIONS))
    if unknown:
        raise ValueError(f"firmware profile {p}: unknown section [{unknown[0]}]: the sections are "
                         f"{', '.join(f'[{n}]' for n in SECTIONS + HOST_SECTIONS)}")
    for name in HOST_SECTIONS:
        if name in doc and not isinstance(doc[name], dict):
            raise ValueError(f"firmware profile {p}: {name} must be a table [{name}], got {doc[name]!r}")
    section = "rates_hz"
    try:
        rates = _rates(_section(doc, "rates_hz"))
        section = "motor"
        motor = _section(doc, "motor")
        unknown = sorted(set(motor) - {"link", "can_id", *RATING_KEYS})
        if unknown:
            raise ValueError(f"has no key {unknown[0]!r}: its keys are link, can_id, {', '.join(RATING_KEYS)}")
        ratings = MotorRatings.from_table(motor)
        section = "safety"
        safety_table = _safety(_section(doc, "safety"))
        belt_ratio = safety_table.get("belt_ratio", SafetyLimits.belt_ratio)
        section = "control"
        ctl = dict(_section(doc, "control"))
        pos, vel = ctl.pop("position", {}), ctl.pop("velocity", {})
        control_hz = rates.get("control_hz", FirmwareConfig.control_hz)
        _control(ctl, control_hz if isinstance(control_hz, int) else FirmwareConfig.control_hz, ratings,
                 belt_ratio if is_number(belt_ratio) and belt_ratio > 0 else SafetyLimits.belt_ratio)
        section = "control.position"
        position_gains = _parameters(PidGains, pos)
        section = "control.velocity"
        velocity_gains = _parameters(PidGains, vel)
        section = "feedforward"
        feedforward_params = _parameters(FeedforwardParams, _section(doc, "feedforward"))
        section = "safety"
        safety = SafetyLimits(**safety_table, motor=ratings)
        section = "thermal"
        thermal = _parameters(ThermalLimits, _section(doc, "thermal"))
        section = "task_cycles"
        task_cycles = _task_cycles(_section(doc, "task_cycles"))
        section = "motor"
        links = {"motor_link": motor["link"]} if "link" in motor else {}
        if "link" in motor:
            from firmware.drivers.motor_links import MOTOR_LINKS  # imports firmware.config

            MOTOR_LINKS.check(motor["link"], "link")  # ValueError naming the choices, blamed on [motor]
        if "can_id" in motor:
            links["motor_can_id"] = check_int_range("can_id", motor["can_id"], 0, MAX_CAN_ID)
        section = "controller"
        controller = _controller(_section(doc, "controller"), p)
        section = "ground_sensors"
        ground_sensors = GroundSensorConfig.from_table(_section(doc, "ground_sensors"))
        section = "host_watchdog"
        host_watchdog = _host_watchdog(_section(doc, "host_watchdog"))
        section = "rates_hz"  # what is left: checks across sections, which name their keys
        return FirmwareConfig(**rates, position_gains=position_gains, velocity_gains=velocity_gains,
                              feedforward_params=feedforward_params, safety=safety, thermal=thermal,
                              task_cycles=task_cycles, **links, **controller, **host_watchdog, **ctl,
                              ground_sensors=ground_sensors)
    except ValueError as e:
        msg = str(e)
        where = "" if msg.startswith("[") else f"[{section}] "
        raise ValueError(f"firmware profile {p}: {where}{msg}") from None
