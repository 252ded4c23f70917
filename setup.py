"""Build hook: compile the simulation's hot path to C extensions with mypyc (everything else is in pyproject.toml).

The modules listed in ``COMPILED`` run every virtual cycle: the scheduler loop (with its task slots, the job record
its task bodies read and its watchdog), the interrupt interference solve, the virtual peripherals and
device models with their event base classes, the plant, the ADC with the ground sensors and the ground
reaction, the firmware's tasks, drivers and codecs, the shipped controllers (cascade, impedance) with
the observation they read, the load detector and the ground sensors' driver and event detector, the
bench probe of a virtual run, the input record's recorder and replay (every call the firmware makes
goes through them in a recorded serial run and in `pafp replay`), and the plant's run over one window of
`pafp fit`'s simulation with the fit's backlash (each of a fit's ~400 simulations runs every window).
mypyc compiles the same typed Python source; the ``.py`` files stay the reference and run unchanged
when the build is skipped. ``PAFP_PURE_PYTHON=1 pip install -e .`` (or a machine without a C
compiler) gives the pure-Python package; ``host_tools.build_info`` tells which one is running.
docs/compiled.md states the rules the build imposes (what stays interpreted, and why) and how it builds.
"""

from __future__ import annotations

import os
import shutil
import sys
import sysconfig
import threading
from concurrent.futures import ThreadPoolExecutor
from typing import Any

from setuptools import setup
from setuptools.command.build_ext import build_ext

COMPILED = [
    "rtos/scheduler.py",
    "rtos/slot.py",
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
    "hal/virtual/plant/gap.py",
    "hal/virtual/plant/model.py",
    "hal/virtual/plant/state.py",
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
    "host_tools/calibration/fit_gap.py",
    "host_tools/calibration/fit_window.py",
    "hal/record/recorder.py",
    "hal/record/reader.py",
    "hal/record/streams.py",
    "hal/record/replay_peripherals.py",
    "hal/record/replay.py",
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
    # multi_file: one C file per module (and the mypyc runtime in its own files) instead of one 28 MB file, so
    # that the files compile in parallel (ParallelBuildExt); the modules stay one group (one shared library),
    # so calls between them stay direct C calls.
    return mypycify(["--ignore-missing-imports", *COMPILED], opt_level="3", multi_file=True)


def _jobs() -> int:
    """Compiler processes to run at once: PAFP_BUILD_JOBS, else the cores this process may use."""
    given = os.environ.get("PAFP_BUILD_JOBS", "")
    if given:
        if not given.isdigit() or int(given) < 1:
            sys.exit(f"pafp: PAFP_BUILD_JOBS={given!r} (from the environment) must be a whole number >= 1")
        return int(given)
    return len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else os.cpu_count() or 1


def _progress(line: str) -> None:
    """One line of build progress (``make install`` shows the lines starting with ``pafp build:``)."""
    print(f"pafp build: {line}", file=sys.stderr, flush=True)


class ParallelBuildExt(build_ext):
    """build_ext that compiles every C file of every extension in parallel, one compiler per core, with progress.

    setuptools' own ``--parallel`` builds whole extensions in parallel, but the compiled package is one large
    extension (the shared library of all the modules) and small shims, so the parallelism is taken per C file.
    """

    def build_extensions(self) -> None:
        jobs = _jobs()
        total = sum(len(ext.sources) for ext in self.extensions)
        _progress(f"compiling {total} C files of {len(self.extensions)} extensions, {jobs} at a time")
        compilers = threading.BoundedSemaphore(jobs)  # compiler processes at once, over all the extensions
        lock = threading.Lock()
        done = [0]
        compiler: Any = self.compiler
        serial_compile = compiler._compile

        def compile_one(obj: str, src: str, ext: str, cc_args: list, extra_postargs: list, pp_opts: list) -> None:
            with compilers:
                serial_compile(obj, src, ext, cc_args, extra_postargs, pp_opts)
            with lock:
                done[0] += 1
                _progress(f"[{done[0]}/{total}] {src}")

        def parallel_compile(sources: list, output_dir: str | None = None, macros: Any = None,
                             include_dirs: Any = None, debug: bool = False, extra_preargs: Any = None,
                             extra_postargs: Any = None, depends: Any = None) -> list:
            """CCompiler.compile with the files compiled on threads (each runs one compiler process)."""
            macros, objects, extra_postargs, pp_opts, build = compiler._setup_compile(
                output_dir, macros, include_dirs, sources, depends, extra_postargs)
            cc_args = compiler._get_cc_args(pp_opts, debug, extra_preargs)
            with ThreadPoolExecutor(max_workers=jobs) as pool:
                for future in [pool.submit(compile_one, obj, *build[obj], cc_args, extra_postargs, pp_opts)
                               for obj in objects if obj in build]:
                    future.result()
            return objects

        compiler.compile = parallel_compile
        self.parallel = jobs  # setuptools builds the extensions on that many threads
        super().build_extensions()
        _progress("done")


if __name__ == "__main__":  # setuptools runs this file as __main__; tests import ParallelBuildExt from it
    setup(ext_modules=_extensions(), cmdclass={"build_ext": ParallelBuildExt})
