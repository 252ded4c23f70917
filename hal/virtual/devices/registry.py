"""Device models by name: what the virtual bench and ``sim://`` build (:data:`DEVICES`, docs/devices.md).

An entry is a :class:`DeviceModel`: the bench role the device plays (the peripheral it sits on), the
peripheral kind of that link, its default baud and a ``build(world, link, *, seed, config)`` function.
``VirtualBench(imu_model=NAME)`` and ``sim://NAME`` look the name up here, so a new device is one file
(its model and its ``DeviceModel``) plus one entry: in :data:`DEVICES`, through
:meth:`~hal.registry.Registry.register`, or from a separate package through the entry-point group
``pafp.devices``. The aliases ``motor`` and ``imu`` name the default device of each role.

A sensor on an ADC channel is a model of kind ``adc`` (role ``sensor``, baud 0): its
``build(ground, f_hz, *, seed, config)`` returns the part, whose ``outputs()`` maps each of its ADC channel
names to ``volts(t_cycles)``. The virtual bench and ``sim://ground-sensors`` put every registered ADC
sensor on the ADC, in registry order (:func:`adc_sensor_models`; hal/virtual/ground_sensors.py).
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

from hal.registry import Registry

__all__ = ["AK60_6", "BNO08X", "DEVICES", "KINDS", "DeviceModel", "adc_sensor_models", "device_model",
           "device_model_for"]

KINDS: dict[str, tuple[str, ...]] = {"uart": ("motor", "imu", "ground"), "adc": ("sensor",)}
"""Peripheral kind a device model may sit on -> the bench roles of that kind that carry a device (a sensor on
another peripheral is a new kind here with its roles, and a ``build`` taking what that peripheral needs)."""


@dataclass(frozen=True)
class DeviceModel:
    """A device model the virtual bench and ``sim://`` build by name."""

    role: str
    """The bench role it plays (for a UART device: ``motor`` or ``imu``)."""
    kind: str
    """The peripheral kind of its link (a key of :data:`KINDS`)."""
    baud: int
    """Default baud rate of its link (the device's own default); 0 for a kind that is not a UART."""
    build: Callable[..., Any]
    """On a UART, ``build(world, link, *, seed, config)``: the device on ``world``'s plant, transmitting on
    ``link``; ``config`` is the bench's configuration for the role (e.g. a ``Bno08xConfig``, None for the
    defaults). On the ADC, ``build(ground, f_hz, *, seed, config)``: the sensor under ``ground``
    (``at(t_s) -> (F_z, F_x, CoP)``) on a clock of f_hz ticks a second; its ``outputs()`` maps its channel
    names to ``volts(t_ticks)`` (``config``: the ground sensor profile's path, None for the shipped one)."""
    summary: str = ""
    """One line for help texts and tables."""

    def __post_init__(self) -> None:
        """Check the role, the kind, the baud and that build is callable."""
        if self.kind not in KINDS:
            raise ValueError(f"device model kind {self.kind!r} unknown: one of {list(KINDS)}")
        if self.role not in KINDS[self.kind]:
            raise ValueError(f"device model role {self.role!r} unknown on the {self.kind.upper()}: one of "
                             f"{list(KINDS[self.kind])}")
        lo, hi = (1, 20_000_000) if self.kind == "uart" else (0, 0)
        if isinstance(self.baud, bool) or not isinstance(self.baud, int) or not lo <= self.baud <= hi:
            raise ValueError(f"device model baud {self.baud!r} out of range {lo}..{hi} on the {self.kind.upper()}")
        if not callable(self.build):
            raise ValueError(f"device model build {self.build!r} is not callable")


def _build_ak60(world: Any, link: Any, *, seed: int = 0, config: Any = None) -> Any:
    from hal.virtual.devices.ak60 import Ak60

    return Ak60(world, config, link=link)


def _build_bno08x(world: Any, link: Any, *, seed: int = 0, config: Any = None) -> Any:
    from hal.virtual.devices.bno08x import Bno08x

    return Bno08x(world, config, seed=seed, link=link)


AK60_6 = DeviceModel("motor", "uart", 921_600, _build_ak60,
                     "CubeMars AK60-6 driver, VESC servo mode (PROTOCOLS.md C)")
BNO08X = DeviceModel("imu", "uart", 115_200, _build_bno08x,
                     "BNO08x IMU in UART-RVC, 100 Hz frames (PROTOCOLS.md D)")

DEVICES = Registry("device", {
    "ak60-6": "hal.virtual.devices.registry:AK60_6",
    "ak60": "hal.virtual.devices.registry:AK60_6",
    "motor": "hal.virtual.devices.registry:AK60_6",
    "bno08x": "hal.virtual.devices.registry:BNO08X",
    "bno085": "hal.virtual.devices.registry:BNO08X",
    "imu": "hal.virtual.devices.registry:BNO08X",
    "ground-sensors": "hal.virtual.devices.ground_models:GROUND_BOARD",
    "firmata": "hal.virtual.devices.ground_models:GROUND_BOARD",
    "ground": "hal.virtual.devices.ground_models:GROUND_BOARD",
    "load-cell": "hal.virtual.devices.ground_models:LOAD_CELL",
    "fsr-heel": "hal.virtual.devices.ground_models:FSR_HEEL",
    "fsr-toe": "hal.virtual.devices.ground_models:FSR_TOE",
}, group="pafp.devices")
"""Device name -> :class:`DeviceModel` (aliases point to the same model)."""


def device_model(name: str, where: str = "device") -> DeviceModel:
    """The model registered as name; ValueError naming where it came from and the choices otherwise."""
    model = DEVICES.load(name, where)
    if not isinstance(model, DeviceModel):
        raise ValueError(f"{where} {name!r}: {DEVICES.reference(name)} is a {type(model).__name__}, "
                         "not a hal.virtual.devices.registry.DeviceModel")
    return model


def device_model_for(role: str, name: str, where: str) -> DeviceModel:
    """device_model(name), checked to play ``role`` (``imu``, ``motor``); ValueError naming where otherwise."""
    model = device_model(name, where)
    if model.role != role:
        wanted = {"imu": "an IMU", "motor": "a motor"}.get(role, f"a {role} device")
        raise ValueError(f"{where} {name!r} is a {model.role} device, not {wanted} (the alias {role!r} names the "
                         "shipped one)")
    return model


def adc_sensor_models() -> list[tuple[str, DeviceModel]]:
    """Every registered ADC sensor (name, model), in registry order (shipped first), each model once."""
    seen: list[DeviceModel] = []
    out: list[tuple[str, DeviceModel]] = []
    for name in DEVICES:
        model = device_model(name)
        if model.kind == "adc" and not any(model is m for m in seen):
            seen.append(model)
            out.append((name, model))
    return out
