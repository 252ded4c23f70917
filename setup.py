"""Build hook: compile the simulation's hot path to C extensions with mypyc (everything else is in pyproject.toml).

The modules listed in ``COMPILED`` run every virtual cycle: the scheduler loop (with the job record
its task bodies read and its watchdog), the interrupt interference solve, the virtual peripherals and
device models with their event base classes, the plant, the ADC with the ground sensors and the ground
reaction, the firmware's tasks, drivers and codecs, the shipped controllers (cascade, impedance) with
the observation they read, the load detector and the ground sensors' driver and event detector, and
the bench probe of a virtual run.
mypyc compiles the same typed Python source; the ``.py`` files stay the reference and run unchanged
when the build is skipped. ``PAFP_PURE_PYTHON=1 pip install -e .`` (or a machine without a C
compiler) gives the pure-Python package; ``host_tools.build_info`` tells which one is running.

What stays interpreted on purpose: the VESC message classes (built by ``__init_subclass__``
metaprogramming mypyc does not support; their frame decoder and their per-message scaling, packing and
unpacking, ``vesc_codec``, are compiled), the telemetry records (enum fields that compiled code would
store as plain ints; their framing, ``telemetry_frame``, is compiled), the configuration value classes and the plant
parameters (their checks must see the values as given: compiled code turns a bool into an int at the
boundary), the gait reference (tests replace its constructors; the curve it samples,
``firmware.control.curve``, is compiled), the RTOS task declarations (``rtos.task``: their checks must
see bools), the controller interface and registry and a user's controller class (the compiled control
task calls it through a Python call), the analysis and the host tools other than the probe.
"""

from __future__ import annotations

import os
import shutil
import sys
import sysconfig

from setuptools import setup

COMPILED = [
    "rtos/scheduler.py",
    "rtos/interrupts.py",
    "rtos/stats.py",
    "rtos/job.py",
    "rtos/watchdog.py",
    "hal/interfaces.py",
    "hal/can.py",
    "hal/virtual/gpio.py",
    "hal/virtual/events.py",
    "hal/virtual/irq.py",
    "hal/virtual/uart.py",
    "hal/virtual/line.py",
    "hal/virtual/can_bits.py",
    "hal/virtual/can_bus.py",
    "hal/virtual/can.py",
    "hal/virtual/timer.py",
    "hal/virtual/plant/integrator.py",
    "hal/virtual/plant/model.py",
    "hal/virtual/devices/world.py",
    "hal/virtual/devices/ak60.py",
    "hal/virtual/devices/ak60_loops.py",
    "hal/virtual/devices/ak60_meter.py",
    "hal/virtual/devices/ak60_values.py",
    "hal/virtual/devices/vesc_rx.py",
    "hal/virtual/devices/ak60_can.py",
    "hal/virtual/devices/bno08x.py",
    "hal/virtual/devices/encoder.py",
    "hal/virtual/adc.py",
    "hal/virtual/plant/ground.py",
    "hal/virtual/devices/load_cell.py",
    "hal/virtual/devices/fsr.py",
    "firmware/app.py",
    "firmware/tasks.py",
    "firmware/control/observation.py",
    "firmware/control/cascade.py",
    "firmware/control/gait_events.py",
    "firmware/control/impedance.py",
    "firmware/control/ground_events.py",
    "firmware/drivers/ground_sensors.py",
    "firmware/safety.py",
    "firmware/logger.py",
    "firmware/drivers/motor.py",
    "firmware/drivers/imu.py",
    "firmware/drivers/encoder.py",
    "firmware/drivers/link.py",
    "firmware/drivers/motor_link.py",
    "firmware/drivers/can_link.py",
    "firmware/drivers/can_servo.py",
    "firmware/drivers/can_mit.py",
    "firmware/control/pid.py",
    "firmware/control/estimation.py",
    "firmware/control/filters.py",
    "firmware/control/curve.py",
    "protocol/vesc_frame.py",
    "protocol/vesc_codec.py",
    "protocol/rvc.py",
    "protocol/cobs.py",
    "protocol/telemetry_frame.py",
    "host_tools/probe.py",
]


def _extensions() -> list:
    if os.environ.get("PAFP_PURE_PYTHON"):
        return []
    compiler = (os.environ.get("CC") or sysconfig.get_config_var("CC") or "cc").split()[0]
    if shutil.which(compiler) is None:
        print(f"pafp: no C compiler ({compiler}), installing the pure-Python package", file=sys.stderr)
        return []
    try:
        from mypyc.build import mypycify
    except ImportError:  # a build without the [build-system] requirements (e.g. --no-build-isolation)
        print("pafp: mypyc not available, installing the pure-Python package", file=sys.stderr)
        return []
    return mypycify(["--ignore-missing-imports", *COMPILED], opt_level="3")


setup(ext_modules=_extensions())
