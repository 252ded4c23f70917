"""BNO08x UART-RVC model: banner, 100 Hz frames, lagged pitch, accelerations, seeded noise, silence."""

from __future__ import annotations

import math

import pytest
from doubles import SpyLink

from hal.virtual.devices.bno08x import BANNER_LINES, Bno08x, Bno08xConfig
from hal.virtual.devices.world import World
from hal.virtual.plant import Plant
from hal.virtual.uart import VirtualUart
from protocol.rvc import RvcDecoder, RvcFrame

F = 168_000_000
TAU = 0.0195
QUIET = Bno08xConfig(pitch_noise_rad=0.0, accel_noise_mps2=0.0)
MG = 9.80665 / 1000


class Rig:
    """A world with the BNO08x on a VirtualUart at 115200 baud; the test moves the MCU clock ``t``."""

    def __init__(self, plant: object = None, config: Bno08xConfig | None = None, seed: int = 0) -> None:
        self.t = 0
        self.world = World(plant if plant is not None else Plant(), F)  # type: ignore[arg-type]
        self.imu = Bno08x(self.world, config, seed=seed)
        self.uart = VirtualUart(lambda: self.t, F, 115_200, rx_buffer_size=1 << 16)
        self.uart.connect(self.imu)
        self.imu.connect(self.uart)

    def read_until(self, t_s: float) -> bytes:
        self.t = round(t_s * F)
        return self.uart.read()


def test_banner_then_frames_at_100_hz() -> None:
    rig = Rig()
    data = rig.read_until(0.015)
    banner = "".join(line + "\r\n" for line in BANNER_LINES).encode()
    assert data.startswith(banner) and len(data) == len(banner) + 19
    assert data[len(banner):len(banner) + 2] == b"\xaa\xaa"
    decoder = RvcDecoder()
    frames = decoder.feed(data + rig.read_until(1.002))
    assert decoder.stats.banner_bytes == len(banner)
    assert len(frames) == 100 and [f.index for f in frames] == list(range(100))
    assert decoder.stats.lost_frames == decoder.stats.checksum_errors == decoder.stats.dropped_bytes == 0


def test_frame_starts_are_exactly_periodic_or_jittered_by_seed() -> None:
    spy = SpyLink()
    rig = Rig()
    rig.imu.connect(spy)
    rig.world.advance_to(round(0.5 * F))
    starts = [s for d, s in spy.sent if d[:2] == b"\xaa\xaa"]
    assert {b - a for a, b in zip(starts, starts[1:], strict=False)} == {round(0.01 * F)}
    jittery = []
    for seed in (1, 1, 2):
        spy = SpyLink()
        rig = Rig(config=Bno08xConfig(period_jitter_s=0.001), seed=seed)
        rig.imu.connect(spy)
        rig.world.advance_to(round(0.5 * F))
        starts = [s for d, s in spy.sent if d[:2] == b"\xaa\xaa"]
        gaps = [b - a for a, b in zip(starts, starts[1:], strict=False)]
        assert all(0.009 * F <= g <= 0.011 * F for g in gaps) and len(set(gaps)) > 10
        jittery.append(gaps)
    assert jittery[0] == jittery[1] != jittery[2]


class StepPlant(Plant):
    """A plant whose ankle steps from 0 to 0.2 rad at t = 0.1 s and never moves otherwise."""

    def output_angle_rad(self, t_s: float) -> float:
        return 0.2 if t_s >= 0.1 else 0.0

    def output_velocity_rad_s(self, t_s: float) -> float:
        return 0.0

    def output_accel_rad_s2(self, t_s: float) -> float:
        return 0.0


def test_pitch_step_response_has_the_19_5_ms_lag() -> None:
    rig = Rig(StepPlant(), QUIET)
    frames = RvcDecoder().feed(rig.read_until(0.3))
    h = 0.0025  # the step lies in one sampling substep: a ramp over [0.0975, 0.1]
    y_at_step = 0.2 - 0.2 / h * TAU * (1 - math.exp(-h / TAU))
    for k, frame in enumerate(frames):
        t = 0.01 * (k + 1)
        if t < 0.1:
            assert frame.pitch_rad == 0.0
            continue
        exact = 0.2 - (0.2 - y_at_step) * math.exp(-(t - 0.1) / TAU)
        ideal = 0.2 * (1 - math.exp(-(t - 0.1) / TAU))
        assert frame.pitch_rad == pytest.approx(exact, abs=2e-4)  # 0.01 deg wire truncation
        assert abs(frame.pitch_rad - ideal) <= 0.2 * 0.07
    at_20ms = frames[11].pitch_rad  # t = 0.12 s; the ramp's centre is h/2 before 0.1 s
    tau_seen = (0.02 + h / 2) / -math.log(1 - at_20ms / 0.2)
    assert tau_seen == pytest.approx(TAU, rel=0.02)


def test_pitch_follows_the_falling_foot_through_the_lag() -> None:
    """Against an independent reference: a twin plant sampled every 0.1 ms, lag integrated finely."""
    rig = Rig(Plant(initial_angle_rad=0.5), QUIET)
    frames = RvcDecoder().feed(rig.read_until(0.6))
    twin = Plant(initial_angle_rad=0.5)
    y, u_prev, t_prev, dt = 0.5, 0.5, 0.0, 1e-4
    errors = []
    for k, frame in enumerate(frames):
        t_frame = 0.01 * (k + 1)
        while t_prev < t_frame - 1e-12:
            t = min(t_prev + dt, t_frame)
            u = twin.output_angle_rad(t)
            m = (u - u_prev) / (t - t_prev)
            y = u - m * TAU + (y - u_prev + m * TAU) * math.exp(-(t - t_prev) / TAU)
            t_prev, u_prev = t, u
        errors.append(abs(frame.pitch_rad - y))
    assert max(errors) < math.radians(0.015)  # one 0.01 deg wire LSB + the substep interpolation
    assert frames[-1].pitch_rad < -0.45  # the foot fell to the plantarflexion stop


def test_sample_hold_reading_holds_the_pitch_every_interval_without_lag() -> None:
    """Report 3.5.4 read as a sample interval: the pitch sampled every 19.5 ms and held, no lag."""
    from hal.virtual.devices.bno08x_config import imu_reading_of, with_imu_reading

    hold = with_imu_reading(QUIET, "sample-hold")
    assert hold.lag_time_constant_s == 0.0 and hold.hold_interval_s == TAU and imu_reading_of(hold) == "sample-hold"
    assert imu_reading_of(with_imu_reading(hold, "first-order-lag")) == "first-order-lag"
    rig = Rig(StepPlant(), hold)
    frames = RvcDecoder().feed(rig.read_until(0.3))
    for k, frame in enumerate(frames):
        t = 0.01 * (k + 1)
        held_at = math.floor(t / TAU + 1e-9) * TAU  # the latest hold instant
        if held_at < 0.0975:  # held before the step's substep ramp: 0
            assert frame.pitch_rad == 0.0, t
        elif held_at >= 0.1:  # held after it: the whole step, no lag
            assert frame.pitch_rad == pytest.approx(0.2, abs=2e-4), t
    first = next(k for k, f in enumerate(frames) if f.pitch_rad > 0.1)
    assert 0.01 * (first + 1) == pytest.approx(0.12, abs=1e-9)  # the hold instants 97.5 ms (before), 117 ms
    with pytest.raises(ValueError, match="hold_interval_s"):
        Bno08xConfig(hold_interval_s=-1.0)


def test_accelerations_include_gravity_and_the_lever_arm() -> None:
    rig = Rig(Plant(initial_angle_rad=0.5), QUIET)
    frames = RvcDecoder().feed(rig.read_until(0.6))
    twin = Plant(initial_angle_rad=0.5)
    r, g = QUIET.lever_arm_m, 9.8
    for k, frame in enumerate(frames):
        t = 0.01 * (k + 1)
        th, w, a = twin.output_angle_rad(t), twin.output_velocity_rad_s(t), twin.output_accel_rad_s2(t)
        assert frame.accel_x_mps2 == pytest.approx(-r * w * w + g * math.sin(th), abs=MG * 1.01)
        assert frame.accel_z_mps2 == pytest.approx(r * a + g * math.cos(th), abs=MG * 1.01)
        assert frame.accel_y_mps2 == 0.0
    rest = frames[-1]
    assert math.hypot(rest.accel_x_mps2, rest.accel_z_mps2) == pytest.approx(9.8, abs=2 * MG)  # truncation


def test_same_seed_same_bytes_other_seed_other_noise() -> None:
    runs = [Rig(Plant(initial_angle_rad=0.2), seed=s).read_until(0.3) for s in (7, 7, 8)]
    assert runs[0] == runs[1] != runs[2]
    a, b = (RvcDecoder().feed(r) for r in (runs[0], runs[2]))
    assert [f.index for f in a] == [f.index for f in b]
    assert sum(x.pitch_rad != y.pitch_rad for x, y in zip(a, b, strict=True)) > len(a) // 2
    quiet = RvcDecoder().feed(Rig(Plant(), QUIET).read_until(0.1))
    assert all(f.yaw_rad == f.roll_rad == 0.0 for f in quiet)


def test_bias_and_mounting_offset() -> None:
    cfg = Bno08xConfig(pitch_noise_rad=0.0, accel_noise_mps2=0.0, mounting_offset_rad=0.1, pitch_bias_rad=0.01,
                       pitch_sign=-1)
    plant = Plant(initial_angle_rad=-0.5235987755982988)  # resting on the plantarflexion stop
    frames = RvcDecoder().feed(Rig(plant, cfg).read_until(0.2))
    expected = -(plant.output_angle_rad(0.2) + 0.1) + 0.01
    assert frames[-1].pitch_rad == pytest.approx(expected, abs=5e-4)


def test_silence_drops_frames_but_the_index_runs_on() -> None:
    rig = Rig()
    rig.imu.silence(0.095, 0.05)
    decoder = RvcDecoder()
    frames = decoder.feed(rig.read_until(0.3))
    assert len(frames) == 24 and rig.imu.frames_silenced == 5  # 29 sent by 0.3 s, 0.10..0.14 s silent
    assert decoder.stats.lost_frames == 5
    with pytest.raises(ValueError, match="duration_s"):
        rig.imu.silence(0.4, 0.0)


def test_output_only_and_config_checks() -> None:
    rig = Rig()
    rig.uart.write(b"\x7e\x00\x7e")
    rig.read_until(0.05)
    assert rig.imu.bytes_ignored == 3
    with pytest.raises(ValueError, match="rate_hz"):
        Bno08xConfig(rate_hz=0.0)
    with pytest.raises(ValueError, match="pitch_sign"):
        Bno08xConfig(pitch_sign=2)
    with pytest.raises(ValueError, match="half"):
        Bno08xConfig(period_jitter_s=0.006)
    with pytest.raises(ValueError, match=r"rate_hz = True is outside"):  # a bool is no rate, compiled or not
        Bno08xConfig(rate_hz=True)  # type: ignore[arg-type]
    assert isinstance(RvcFrame.from_bytes(rig.read_until(0.06)[-19:]), RvcFrame)


def test_yaw_and_roll_at_half_a_turn_stay_within_the_sensors_range() -> None:
    """Mounted at yaw and roll 180 deg, the noise crosses +-180: the sensor reports them wrapped (+-180 deg,
    datasheet §1.3.5.2), and the firmware's decoder, which skips frames outside those ranges, keeps every frame."""
    rig = Rig(config=Bno08xConfig(yaw_rad=math.pi, roll_rad=-math.pi), seed=3)
    decoder = RvcDecoder()
    frames = decoder.feed(rig.read_until(1.002))
    assert len(frames) == 100 and decoder.stats.range_errors == 0
    yaws = [f.yaw_rad for f in frames]
    assert min(yaws) < -3.0 and max(yaws) > 3.0  # both sides of the wrap: the test can fail
