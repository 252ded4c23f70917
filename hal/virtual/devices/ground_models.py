"""The ground sensors' device models: the Firmata acquisition board (a UART device) and the ADC sensors under the
foot (pylon load cell, heel and toe FSRs), registered by name in :data:`hal.virtual.devices.registry.DEVICES`.

They live beside the registry, not in it: their builders use :mod:`hal.virtual.ground_sensors`, which itself reads
the registry for the ADC sensors to wire (registry -> this module by name only, so no import circle).
"""

from __future__ import annotations

from typing import Any

from hal.virtual.devices.firmata_board import FirmataBoard
from hal.virtual.devices.load_cell import LoadCell
from hal.virtual.devices.registry import DeviceModel
from hal.virtual.ground_sensors import AdcSettings, foot_fsr, load_ground_profile, wire_ground_sensors
from hal.virtual.plant.ground import NoGround

__all__ = ["FSR_HEEL", "FSR_TOE", "GROUND_BOARD", "LOAD_CELL"]


def _build_ground_board(world: Any, link: Any, *, seed: int = 0, config: Any = None) -> Any:
    sensors = wire_ground_sensors(None, world.f_hz, NoGround(), AdcSettings(), seed=seed)
    return FirmataBoard(world, sensors.codes_at, len(sensors.adc.channels), link=link)


def _build_load_cell(ground: Any, f_hz: int, *, seed: int = 0, config: Any = None) -> Any:
    return LoadCell(load_ground_profile(config)[0], ground, f_hz, seed)


def _build_fsr_heel(ground: Any, f_hz: int, *, seed: int = 0, config: Any = None) -> Any:
    return foot_fsr(ground, f_hz, "fsr_heel", config)


def _build_fsr_toe(ground: Any, f_hz: int, *, seed: int = 0, config: Any = None) -> Any:
    return foot_fsr(ground, f_hz, "fsr_toe", config)


GROUND_BOARD = DeviceModel("ground", "uart", 115_200, _build_ground_board,
                           "load cell and heel/toe FSRs, unloaded, behind a Firmata board (docs/hardware.md)")

LOAD_CELL = DeviceModel("sensor", "adc", 0, _build_load_cell,
                        "pylon load cell: axial force and sagittal moment (channels load_force, load_moment)")
FSR_HEEL = DeviceModel("sensor", "adc", 0, _build_fsr_heel, "heel FSR in its divider (channel fsr_heel)")
FSR_TOE = DeviceModel("sensor", "adc", 0, _build_fsr_toe, "toe FSR in its divider (channel fsr_toe)")
