"""BNO08x in UART-RVC mode (115200 8N1, output only) on the foot: boot banner, then 19-byte frames at 100 Hz.

Mounting convention (docs/devices.md): the sensor sits on the foot, ``lever_arm_m`` in front of the
ankle axis along the sole; its x axis points to the toe, z out of the sole upwards, so at rest with the
foot level it reads z = +g. The shank is held vertical on the bench, so the foot's pitch equals the ankle
angle: reported ``pitch = pitch_sign * (theta + mounting_offset_rad)``, dorsiflexion (toe up) positive
with the default sign. Accelerations include gravity (the datasheet's example reads z = 977 mg at rest):
the specific force of the sensor point ``r (-sin th, cos th) alpha - r (cos th, sin th) omega^2 + (0, g)``
in the sensor axes rotated by ``theta + mounting_offset_rad``; y = 0; clipped to the +-8 g full scale.

The sensor's first-order lag (report eq 3.42, tau = 19.5 ms) is applied to pitch: the true pitch is
sampled every ``substep_s`` and at every frame time, and the lag is integrated exactly for an input
that is linear between samples (``y1 = u1 - m tau + (y0 - u0 + m tau) e^(-h/tau)``, m the slope).
With ``hold_interval_s`` (the sample-hold reading of report 3.5.4) the pitch is instead held at its value
at every multiple of that interval (interpolated between samples) and not lagged. Accelerations are not
lagged. Noise and biases are Gaussian from ``random.Random(seed)``: the same seed
gives byte-identical output. With ``bias_drift_sigma_rad`` the pitch bias also drifts, a first-order
Gauss-Markov process updated at every frame (``d = d a + sigma sqrt(1 - a^2) n``, ``a = e^(-T/tau)``),
starting from a stationary draw. The frame period is ``1/rate_hz`` plus a uniform jitter in
``+-period_jitter_s``; ``silence`` keeps the line quiet while the sensor goes on counting its index.
"""

from __future__ import annotations

import math
import random
from collections.abc import Sequence
from typing import Final

from hal.virtual.devices.bno08x_config import BANNER_LINES, Bno08xConfig
from hal.virtual.devices.world import NEVER, Link, World
from hal.virtual.events import EventDevice
from protocol.rvc import RvcFrame

__all__ = ["BANNER_LINES", "Bno08x", "Bno08xConfig"]

STANDARD_GRAVITY: Final = 9.80665
_FULL_SCALE_MPS2: Final = 8 * STANDARD_GRAVITY  # BNO08x accelerometer range +-8 g
_TURN: Final = 2.0 * math.pi  # one turn: yaw and roll wrap into +-pi


class Bno08x(EventDevice):
    """The BNO08x in UART-RVC mode: a world device and an output-only UART peer."""

    def __init__(self, world: World, config: Bno08xConfig | None = None, *, seed: int = 0,
                 link: Link | None = None) -> None:
        """Power the sensor up at the plant's present time; its banner follows after boot_delay_s."""
        super().__init__()
        self.world = world
        self.config = cfg = config if config is not None else Bno08xConfig()
        self.plant = plant = world.plant
        self.link = link
        self._rng = random.Random(seed)
        gauss = self._rng.gauss
        self.pitch_bias_rad = cfg.pitch_bias_rad + gauss(0.0, cfg.bias_sigma_rad)
        self.accel_bias_mps2 = tuple(gauss(0.0, cfg.accel_bias_sigma_mps2) for _ in range(3))
        self._drift_sigma = cfg.bias_drift_sigma_rad
        self.pitch_drift_rad = gauss(0.0, self._drift_sigma) if self._drift_sigma > 0.0 else 0.0
        self._drift_a = math.exp(-1.0 / (cfg.rate_hz * cfg.bias_drift_tau_s))  # per nominal frame period
        self._drift_b = self._drift_sigma * math.sqrt(1.0 - self._drift_a * self._drift_a)
        self._g = plant.params.gravity_m_s2
        t0_s = plant.latest_time_s
        t0 = world.ticks(t0_s)
        self._period = world.ticks(1.0 / cfg.rate_hz)
        self._jitter = world.ticks(cfg.period_jitter_s)
        self._substep = max(1, world.ticks(cfg.substep_s))
        self._banner_at = t0 + world.ticks(cfg.boot_delay_s)
        self._frame_at = self._banner_at + self._period
        self._sample_at = min(t0 + self._substep, self._frame_at)
        u0 = self._true_pitch(plant.output_angle_rad(t0_s))
        self._lag_t_s, self._lag_u, self.lagged_pitch_rad = t0_s, u0, u0
        self._hold_next_s = t0_s + cfg.hold_interval_s  # the next hold instant (sample-hold reading)
        self.index = 0
        self.frames_sent = 0
        self.frames_silenced = 0
        self.bytes_ignored = 0
        self._silences: list[tuple[int, int]] = []
        self.next_event = min(self._banner_at, self._sample_at)
        world.add(self)

    # ------------------------------------------------------------------ UART peer
    def connect(self, link: Link | None) -> None:
        """Send the output through link (None: frames are built and dropped)."""
        self.link = link

    def on_bytes(self, data: bytes, end_times_cycles: Sequence[int]) -> None:
        """Ignore bytes from the MCU (RVC is output only); they are only counted."""
        self.bytes_ignored += len(data)

    def advance_to(self, t_cycles: int) -> None:
        """Bring the whole world (this sensor included) up to t_cycles."""
        self.world.advance_to(t_cycles)

    def silence(self, t_s: float, duration_s: float = math.inf) -> None:
        """Send nothing from t_s for duration_s (a loose connector); the index keeps counting."""
        if not (math.isfinite(t_s) and t_s >= 0.0) or not duration_s > 0.0:
            raise ValueError(f"silence(t_s={t_s!r}, duration_s={duration_s!r}): need t_s >= 0 finite and "
                             "duration_s > 0")
        start = self.world.ticks(t_s)
        end = NEVER if math.isinf(duration_s) else start + self.world.ticks(duration_s)
        self._silences.append((start, end))

    # -------------------------------------------------------------- world device
    def _true_pitch(self, angle_rad: float) -> float:
        return self.config.pitch_sign * (angle_rad + self.config.mounting_offset_rad)

    def run_event(self) -> None:
        """Print the banner, or sample the pitch (and send a frame when it is a frame time)."""
        t = self.next_event
        if t >= self._banner_at:
            self._banner_at = NEVER
            text = "".join(line + "\r\n" for line in self.config.banner)
            self._transmit(text.encode("ascii"), t)
        if t >= self._sample_at:
            self._sample(t)
        self.next_event = min(self._banner_at, self._sample_at)

    def _sample(self, t: int) -> None:
        t_s = t / self.world.f_hz
        plant = self.plant
        theta = plant.output_angle_rad(t_s)
        u = self._true_pitch(theta)
        dt = t_s - self._lag_t_s
        tau = self.config.lag_time_constant_s
        hold = self.config.hold_interval_s
        if hold > 0.0:
            if dt > 0.0 and t_s >= self._hold_next_s:  # the latest hold instant: the input at it, linear between
                th = self._hold_next_s + math.floor((t_s - self._hold_next_s) / hold) * hold
                self.lagged_pitch_rad = self._lag_u + (u - self._lag_u) * (th - self._lag_t_s) / dt
                self._hold_next_s = th + hold
            if dt > 0.0:
                self._lag_t_s, self._lag_u = t_s, u
        elif dt > 0.0:
            if tau > 0.0:
                m = (u - self._lag_u) / dt
                self.lagged_pitch_rad = u - m * tau + (self.lagged_pitch_rad - self._lag_u + m * tau) * math.exp(
                    -dt / tau)
            else:
                self.lagged_pitch_rad = u
            self._lag_t_s, self._lag_u = t_s, u
        if t >= self._frame_at:
            self._frame(t, t_s, theta)
            period = self._period
            if self._jitter:
                period += self._rng.randint(-self._jitter, self._jitter)
            self._frame_at = t + period
        self._sample_at = min(t + self._substep, self._frame_at)

    def _frame(self, t: int, t_s: float, theta: float) -> None:
        cfg, plant, gauss = self.config, self.plant, self._rng.gauss
        omega = plant.output_velocity_rad_s(t_s)
        alpha = plant.output_accel_rad_s2(t_s)
        r, g = cfg.lever_arm_m, self._g
        fx = -r * alpha * math.sin(theta) - r * omega * omega * math.cos(theta)
        fz = r * alpha * math.cos(theta) - r * omega * omega * math.sin(theta) + g
        phi = theta + cfg.mounting_offset_rad
        c, s = math.cos(phi), math.sin(phi)
        bx, by, bz = self.accel_bias_mps2
        sa, sp = cfg.accel_noise_mps2, cfg.pitch_noise_rad
        ax = _clip(fx * c + fz * s + bx + gauss(0.0, sa))
        ay = _clip(by + gauss(0.0, sa))
        az = _clip(-fx * s + fz * c + bz + gauss(0.0, sa))
        yaw = math.remainder(cfg.yaw_rad + gauss(0.0, sp), _TURN)  # the sensor reports yaw and roll in +-180 deg
        if self._drift_sigma > 0.0:
            self.pitch_drift_rad = self.pitch_drift_rad * self._drift_a + self._drift_b * gauss(0.0, 1.0)
        pitch = self.lagged_pitch_rad + self.pitch_bias_rad + self.pitch_drift_rad + gauss(0.0, sp)
        roll = math.remainder(cfg.roll_rad + gauss(0.0, sp), _TURN)
        frame = RvcFrame(self.index, yaw, pitch, roll, ax, ay, az).encode()
        self.index = (self.index + 1) & 0xFF
        if any(a <= t < b for a, b in self._silences):
            self.frames_silenced += 1
            return
        self.frames_sent += 1
        self._transmit(frame, t)

    def _transmit(self, data: bytes, start: int) -> None:
        if self.link is not None:
            self.link.transmit_to_mcu(data, start)


def _clip(accel_mps2: float) -> float:
    """Clip an acceleration to the accelerometer's +-8 g full scale."""
    return max(-_FULL_SCALE_MPS2, min(_FULL_SCALE_MPS2, accel_mps2))
