"""Fault injectors by name: one registry (hal/registry.py) of ``name -> "module:Class"``, each class imported
only when used.

A new injector is a new module here (a subclass of :class:`~hal.virtual.faults.base.Injector` that acts where
its fault happens and notes what it changed) plus one entry below, or, from a separate package, an entry point
of the group ``pafp.faults``; docs/safety.md says how to write one.
"""

from __future__ import annotations

import math
from typing import Any

from hal.registry import Registry

__all__ = ["INJECTORS", "injector_class", "make_injector"]

INJECTORS = Registry("fault", {
    "imu_frozen": "hal.virtual.faults.imu_frozen:ImuFrozen",
    "imu_silent": "hal.virtual.faults.imu_silent:ImuSilent",
    "imu_bias_step": "hal.virtual.faults.imu_bias_step:ImuBiasStep",
    "imu_corrupt": "hal.virtual.faults.imu_corrupt:ImuCorrupt",
    "encoder_glitch": "hal.virtual.faults.encoder_glitch:EncoderGlitch",
    "encoder_stuck": "hal.virtual.faults.encoder_stuck:EncoderStuck",
    "encoder_reversed": "hal.virtual.faults.encoder_reversed:EncoderReversed",
    "motor_replies_lost": "hal.virtual.faults.motor_replies_lost:MotorRepliesLost",
    "motor_frames_corrupt": "hal.virtual.faults.motor_frames_corrupt:MotorFramesCorrupt",
    "motor_over_temp": "hal.virtual.faults.motor_over_temp:MotorOverTemp",
    "motor_fault_code": "hal.virtual.faults.motor_fault_code:MotorFaultCode",
    "motor_stall": "hal.virtual.faults.motor_stall:MotorStall",
    "supply_sag": "hal.virtual.faults.supply_sag:SupplySag",
    "task_overrun": "hal.virtual.faults.task_overrun:TaskOverrun",
    "controller_raise": "hal.virtual.faults.controller_raise:ControllerRaise",
    "controller_nan": "hal.virtual.faults.controller_nan:ControllerNan",
    "can_bus_off": "hal.virtual.faults.can_bus_off:CanBusOff",
    "can_error_passive": "hal.virtual.faults.can_error_passive:CanErrorPassive",
}, group="pafp.faults")
"""Every injector: name -> "module:Class"."""


def injector_class(name: str) -> Any:
    """The injector class called name; ValueError naming the choices otherwise."""
    return INJECTORS.load(name, "fault")


def make_injector(name: str, onset_s: float, duration_s: float = math.inf, seed: int = 0, **params: Any) -> Any:
    """An injector of fault name acting from onset_s for duration_s (ValueError names a bad value)."""
    return injector_class(name)(onset_s, duration_s, seed, **params)
