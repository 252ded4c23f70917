"""Firmware configuration from a TOML profile (rates, gains, safety limits, cycle costs)."""

from __future__ import annotations

import math
import tomllib
from collections.abc import Callable
from dataclasses import dataclass, field, fields
from pathlib import Path
from typing import Any

from firmware.control.filters import ORDER_RANGE
from firmware.control.pid import FeedforwardParams, PidGains
from firmware.control.validation import check_int_range, is_number
from firmware.safety import SafetyLimits

__all__ = ["DEFAULT_PROFILE", "CostModel", "FirmwareConfig", "load_firmware_config"]

DEFAULT_PROFILE = Path(__file__).resolve().parents[1] / "profiles" / "firmware.toml"
RATE_FIELDS = ("control_hz", "imu_poll_hz", "logger_hz", "watchdog_kick_hz", "full_values_hz")  # [rates_hz] + "_hz"


@dataclass(frozen=True)
class CostModel:
    """Cycles of one job: `base + per_byte * bytes handled` (an estimate to calibrate with DWT->CYCCNT)."""

    base: int
    per_byte: int = 0

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
    controller: str = "cascade"  # a shipped controller's name (firmware.control.registry) or FILE.py:CLASS
    controller_params: dict[str, Any] = field(default_factory=dict)  # the profile's [controller] table

    def __post_init__(self) -> None:
        """Check the rates divide sensibly into the control rate."""
        for name in RATE_FIELDS:
            check_int_range(name, getattr(self, name), 1, 10_000)
        check_int_range("imu_lowpass_order", self.imu_lowpass_order, *ORDER_RANGE)
        if self.full_values_hz > self.control_hz:
            raise ValueError(
                f"full_values_hz {self.full_values_hz} out of range: <= control_hz {self.control_hz}")

    def cost(self, task: str) -> Callable[[object], int]:
        """The cost model of `task` (a small default if the profile does not name it)."""
        return self.task_cycles.get(task, CostModel(500))

    def with_changes(self, **changes: Any) -> FirmwareConfig:
        """A copy with some fields replaced (e.g. gains from `pafp tune`)."""
        from dataclasses import replace

        return replace(self, **changes)


def _gains(table: dict[str, Any], where: str) -> PidGains:
    try:
        return PidGains(**table)
    except TypeError as e:
        raise ValueError(f"[{where}] in the firmware profile: {e}") from None


def _rates(table: dict[str, Any]) -> dict[str, Any]:
    """[rates_hz] keys as FirmwareConfig fields (`control` -> `control_hz`); TypeError names an unknown key."""
    out = {}
    for key, value in table.items():
        if f"{key}_hz" not in RATE_FIELDS:
            raise TypeError(f"[rates_hz] has no key {key!r}")
        out[f"{key}_hz"] = value
    return out


def _safety(table: dict[str, Any]) -> dict[str, Any]:
    """[safety] keys as SafetyLimits fields (`*_deg` in degrees -> `*_rad`); TypeError names an unknown key."""
    known = {f.name for f in fields(SafetyLimits)}
    out = {}
    for key, value in table.items():
        degrees = key.endswith("_deg")
        name = key[:-len("_deg")] + "_rad" if degrees else key
        if name not in known:
            raise TypeError(f"[safety] has no key {key!r}")
        # a value that is no number goes on unconverted: SafetyLimits' check names it and its range
        out[name] = math.radians(value) if degrees and is_number(value) else value
    return out


def _controller(table: dict[str, Any], profile: Path) -> dict[str, Any]:
    """[controller]: `name` (a shipped one or FILE.py:CLASS, a relative FILE taken from the profile's
    folder); every other key goes to the controller's constructor as a dict."""
    params = dict(table)
    name = params.pop("name", "cascade")
    if not isinstance(name, str):
        raise ValueError(f"firmware profile {profile}: [controller] name = {name!r} is not a string")
    file, sep, cls = name.rpartition(":")
    if sep and file.endswith(".py") and not Path(file).is_absolute():
        name = f"{profile.parent / file}:{cls}"
    return {"controller": name, "controller_params": params}


def load_firmware_config(path: str | Path | None = None) -> FirmwareConfig:
    """Read a firmware profile (default: profiles/firmware.toml); errors name the file and the key."""
    p = Path(path) if path is not None else DEFAULT_PROFILE
    try:
        doc = tomllib.loads(p.read_text(encoding="utf-8"))
    except OSError as e:
        raise ValueError(f"cannot read firmware profile {p}: {e.strerror or e}") from None
    except tomllib.TOMLDecodeError as e:
        raise ValueError(f"firmware profile {p} is not valid TOML: {e}") from None
    try:
        rates, ctl, saf = doc.get("rates_hz", {}), doc.get("control", {}), doc.get("safety", {})
        controller = _controller(doc.get("controller", {}), p)
        ctl = dict(ctl)
        pos, vel = ctl.pop("position", {}), ctl.pop("velocity", {})
        return FirmwareConfig(
            **_rates(rates),
            position_gains=_gains(pos, "control.position"),
            velocity_gains=_gains(vel, "control.velocity"),
            feedforward_params=FeedforwardParams(**doc.get("feedforward", {})),
            safety=SafetyLimits(**_safety(saf)),
            task_cycles={k: CostModel(**v) for k, v in doc.get("task_cycles", {}).items()},
            **controller,
            **ctl,
        )
    except TypeError as e:
        raise ValueError(f"firmware profile {p}: unknown or missing key ({e})") from None
