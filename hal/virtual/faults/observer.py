"""The campaign's instrument on the virtual bench: the plant's truth at 1 kHz and every command the motor received.

Not a fault: it is armed like one (on the same taps) in both runs of a campaign point, the faulted one and its
fault-free pair, so the two are instrumented alike. It samples the ankle's true angle, velocity and output
torque (emulation only: a real bench would need a reference goniometer and a torque cell) and records, for
every current command that reached the motor (its frame's last byte or the CAN frame's end), whether it was a
safe command (zero current, the brake, duty 0, the handbrake, the position hold, MIT zero torque or damping): the
time the safe state left the wire is read from it.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from typing import Any

import numpy as np

from hal.can import CanFrame
from hal.virtual.events import EventDevice
from hal.virtual.faults.base import FaultRig
from hal.virtual.faults.taps import can_tap, peer_tap
from protocol import can_mit, can_servo, vesc

__all__ = ["Observer", "SAMPLE_HZ"]

SAMPLE_HZ = 1000
MIT_ZERO_NM = 0.01


class _Sampler(EventDevice):
    def __init__(self, world: Any, plant: Any, period: int, out: list[tuple[float, float, float, float]]) -> None:
        super().__init__()
        self.world, self.plant, self.period, self.out = world, plant, period, out
        self.nm_per_a = plant.params.output_torque_per_amp_nm
        self.next_event = period
        world.add(self)

    def run_event(self) -> None:
        t = self.next_event
        t_s = t / self.world.f_hz
        p = self.plant
        self.out.append((t_s, p.output_angle_rad(t_s), p.output_velocity_rad_s(t_s),
                         p.current_q_a(t_s) * self.nm_per_a))
        self.next_event = t + self.period


class Observer:
    """Plant truth at SAMPLE_HZ and the motor's received current commands (time, value, safe)."""

    NAME = "observer"

    def __init__(self, sample: bool = True, gate: Callable[[], bool] | None = None) -> None:
        """Nothing recorded yet. ``sample=False``: the commands only (no plant truth); ``gate``: record the commands
        only while it answers True (the trace's watch of the safe state: decoding nothing before a trip)."""
        self.samples: list[tuple[float, float, float, float]] = []  # t_s, angle_rad, velocity_rad_s, torque_nm
        self.commands: list[tuple[float, float, bool]] = []  # t_s, current_a (brake: its current), safe
        self.f_hz = 1
        self.sample = sample
        self.gate = gate

    def arm(self, rig: FaultRig) -> None:
        """Start the sampler and listen to the commands on the motor link."""
        bench = rig.bench
        self.f_hz = rig.f_cpu_hz
        if self.sample:
            _Sampler(bench.world, bench.plant.raw, rig.f_cpu_hz // SAMPLE_HZ, self.samples)
        if bench.can_bus is not None:
            self.mode = bench.motor_device.mode
            can_tap(rig).listeners.append(self._on_frame)
        else:
            self.decoder = vesc.Decoder("to-motor")
            peer_tap(rig).listeners.append(self._on_bytes)

    def _on_bytes(self, data: bytes, ends: Sequence[int]) -> None:
        if self.gate is not None and not self.gate():
            return
        start = 0
        while start < len(data):
            end = data.find(b"\x03", start)
            end = len(data) - 1 if end < 0 else end
            t_s = ends[end] / self.f_hz
            for msg in self.decoder.feed(data[start:end + 1]):
                if isinstance(msg, vesc.SetCurrent):
                    self.commands.append((t_s, msg.current_a, msg.current_a == 0.0))
                elif isinstance(msg, (vesc.SetCurrentBrake, vesc.SetHandbrake)):
                    self.commands.append((t_s, msg.current_a, True))
                elif isinstance(msg, vesc.SetDuty):  # duty 0: the phases shorted
                    self.commands.append((t_s, 0.0, msg.duty == 0.0))
                elif isinstance(msg, vesc.SetPos):  # the drive's position loop: the hold
                    self.commands.append((t_s, 0.0, True))
            start = end + 1

    def _on_frame(self, frame: CanFrame, t: int) -> None:
        if self.gate is not None and not self.gate():
            return
        t_s = t / self.f_hz
        if self.mode == "mit":
            if len(frame.data) != 8 or can_mit.special_frame(frame.data):
                return
            c = can_mit.decode_command(frame.data)
            # zero torque within the 12-bit torque field's step (0.009 N m on the AK60-6's +-18 N m)
            self.commands.append((t_s, c.t_ff, c.kp == 0.0 and abs(c.t_ff) < MIT_ZERO_NM))
            return
        try:
            c = can_servo.decode_command(frame.arbitration_id, frame.data)
        except ValueError:
            return
        if c.packet == can_servo.PacketId.SET_CURRENT:
            self.commands.append((t_s, c.value, c.value == 0.0))
        elif c.packet == can_servo.PacketId.SET_CURRENT_BRAKE:
            self.commands.append((t_s, c.value, True))
        elif c.packet == can_servo.PacketId.SET_DUTY:  # duty 0: the phases shorted
            self.commands.append((t_s, 0.0, c.value == 0.0))
        elif c.packet == can_servo.PacketId.SET_POS:  # the drive's position loop: the hold
            self.commands.append((t_s, 0.0, True))

    def arrays(self) -> dict[str, np.ndarray]:
        """The samples and commands as arrays."""
        s = np.asarray(self.samples, dtype=float).reshape(-1, 4)
        c = np.asarray([(t, i, float(safe)) for t, i, safe in self.commands], dtype=float).reshape(-1, 3)
        return {"t_s": s[:, 0], "angle_rad": s[:, 1], "velocity_rad_s": s[:, 2], "torque_nm": s[:, 3],
                "cmd_t_s": c[:, 0], "cmd_a": c[:, 1], "cmd_safe": c[:, 2] > 0.5}

    def safe_on_wire_s(self, from_s: float) -> float | None:
        """When the first safe command at or after from_s reached the motor (None: none did)."""
        for t_s, _i, safe in self.commands:
            if t_s >= from_s and safe:
                return t_s
        return None
