"""The bench probe of a virtual run: samples the firmware's outputs and the plant's true angle (compiled).

The probe is a bench instrument, not firmware: :func:`host_tools.runner.run_virtual` gives it a
zero-cost task of the lowest priority whose body is a :class:`ProbeBody`. It runs every PROBE_HZ,
so it is compiled with the hot path (the serial run fills a :class:`Probe` as well).
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass, field, fields

import numpy as np

from firmware.app import Firmware
from hal.virtual.bench import VirtualBench
from rtos import Job

__all__ = ["Action", "Probe", "ProbeBody"]

#: A fault to inject at its time: called as action(bench, firmware).
Action = Callable[[VirtualBench, Firmware], None]


@dataclass
class Probe:
    """Samples of the run at PROBE_HZ: time, reference, the angles (true and as the firmware has them),
    currents and the supervisor's state.

    ``encoder_angle_rad`` is the encoder driver's angle (zero where the pulley was at power-up),
    ``imu_pitch_rad`` the newest IMU frame's pitch as the driver decoded it (NaN before the first
    frame; before the firmware's own low-pass, if any), ``supervisor_state`` the SupervisorState value.
    """

    t_s: list[float] = field(default_factory=list)
    reference_rad: list[float] = field(default_factory=list)
    true_angle_rad: list[float] = field(default_factory=list)
    fused_angle_rad: list[float] = field(default_factory=list)
    encoder_angle_rad: list[float] = field(default_factory=list)
    imu_pitch_rad: list[float] = field(default_factory=list)
    current_cmd_a: list[float] = field(default_factory=list)
    current_meas_a: list[float] = field(default_factory=list)
    supervisor_state: list[int] = field(default_factory=list)

    def sample(self, t_s: float, fw: Firmware, true_angle_rad: float) -> None:
        """Record one sample of the firmware's outputs and the true (or best known) angle at t_s."""
        out = fw.out
        self.t_s.append(t_s)
        self.reference_rad.append(out.reference_rad)
        self.true_angle_rad.append(true_angle_rad)
        self.fused_angle_rad.append(out.fused_angle_rad)
        self.encoder_angle_rad.append(fw.encoder.angle_rad)
        pitch = fw.imu.pitch_rad
        self.imu_pitch_rad.append(math.nan if pitch is None else pitch)
        self.current_cmd_a.append(out.current_cmd_a)
        self.current_meas_a.append(fw.motor.feedback.current_a)
        self.supervisor_state.append(int(fw.supervisor.state))

    def arrays(self) -> dict[str, np.ndarray]:
        """The samples as numpy arrays, by field name."""
        return {f.name: np.asarray(getattr(self, f.name)) for f in fields(self)}


class ProbeBody:
    """The probe task's body: run the actions due, bring the world up to the job's start, take a sample.

    ``actions`` are (time_s, action) pairs sorted by time; each runs once, at the first job at or after
    its time, before the sample.
    """

    def __init__(self, probe: Probe, bench: VirtualBench, fw: Firmware, f_cpu_hz: int,
                 actions: list[tuple[float, Action]]) -> None:
        """Sample into probe from bench and fw; job start cycles are converted with f_cpu_hz."""
        self.probe = probe
        self.bench = bench
        self.fw = fw
        self.f_cpu_hz = f_cpu_hz
        self.actions = actions
        self.world = bench.world
        self.plant = bench.plant.raw  # the probe brings the world up to its job's start itself
        self.listeners: list[Callable[[float], None]] = []  # called with the time of every listen_every-th sample
        self.listen_every = 10  # the heat log at 50 Hz: per-stride rows to 20 ms, at a tenth of the calls
        self._until_listen = 1
        self.slow_listeners: list[Callable[[float], None]] = []  # ... of every slow_every-th of those
        self.slow_every = 5  # the trace's timeline at 10 Hz (its SAMPLE_S)
        self._until_slow = 1

    def __call__(self, job: Job) -> None:
        """Run the actions due, advance the world to job.start, record one sample."""
        start = job.start
        t = start / self.f_cpu_hz
        actions = self.actions
        while actions and actions[0][0] <= t:
            actions.pop(0)[1](self.bench, self.fw)
        self.world.advance_to(start)
        self.probe.sample(t, self.fw, self.plant.output_angle_rad(t))
        self._until_listen -= 1
        if self._until_listen <= 0:
            self._until_listen = self.listen_every
            for listener in self.listeners:
                listener(t)
            self._until_slow -= 1
            if self._until_slow <= 0:
                self._until_slow = self.slow_every
                for listener in self.slow_listeners:
                    listener(t)
