"""`pafp emulate motor --can`'s serving step (host_tools/serial_mode/can_emulate.py) on a clock the test moves:
frames are applied at their arrival against a world advanced to it, whatever the client sends and however late the
emulator is; what real servo-mode clients send is handled as the drive handles it (issue 37)."""

from __future__ import annotations

import struct

import pytest

from hal.can import CanFrame
from hal.pycan import CanUrl
from hal.virtual.devices.ak60 import DriveMode
from host_tools.serial_mode.can_emulate import WallCanMotor
from protocol import can_servo

POWER_ON = CanFrame(1, b"\xff" * 7 + b"\xfc", True)
POWER_OFF = CanFrame(1, b"\xff" * 7 + b"\xfd", True)


class _Port:
    """A CanPort double: frames queued by the test, frames sent kept."""

    def __init__(self) -> None:
        self.waiting: list[CanFrame] = []
        self.sent: list[CanFrame] = []

    def receive(self) -> CanFrame | None:
        return self.waiting.pop(0) if self.waiting else None

    def send(self, frame: CanFrame) -> bool:
        self.sent.append(frame)
        return True


def _servo(packet: int, payload: bytes) -> CanFrame:
    return CanFrame((packet << 8) | 1, payload, True)


@pytest.fixture
def emu():
    clock = [0]
    motor = WallCanMotor(_Port(), CanUrl("test", "x", 1, "servo"), clock_ns=lambda: clock[0])

    def at(ms: float, *frames: CanFrame) -> WallCanMotor:
        clock[0] = round(ms * 1e6)
        motor.port.waiting.extend(frames)
        motor.step()
        return motor

    return at


def test_a_loop_command_then_a_late_one_does_not_run_the_plant_backwards(emu) -> None:
    """The crash of issue 37: a loop command (SET_RPM) armed the core's 1 ms loop without telling the world, and a
    command 19 ms later woke that tick in the plant's past ("time ... is in the past")."""
    emu(1, _servo(3, struct.pack(">i", 1000)))
    emu(10, _servo(7, b"\x01"))  # opensourceleg's mode switch: unknown packet, ignored
    m = emu(20, _servo(1, struct.pack(">i", 1500)))
    assert m.device.core.mode is DriveMode.CURRENT and m.device.unknown_packets == 1
    m = emu(30)
    assert m.world.now == 30_000_000 and abs(m.device.core.meter.current_a - 1.5) < 0.05


def test_a_burst_that_finds_the_emulator_behind_is_applied_in_order_at_its_arrival(emu) -> None:
    emu(1, _servo(1, struct.pack(">i", 1000)))
    status_before = len(emu(2).port.sent)
    # 80 ms of silence, then a burst: of the 500 Hz status frames due from 4 ms to 82 ms only the latest goes out (the
    # others would only go out late, in a burst: superseded), then the burst acts at 82 ms
    m = emu(82, _servo(3, struct.pack(">i", 2000)), _servo(1, struct.pack(">i", -1000)),
            _servo(1, struct.pack(">i", 2500)))
    assert m.world.now == 82_000_000
    assert len(m.port.sent) - status_before == 1 and m.device.status_superseded == 39
    assert m.device.core.mode is DriveMode.CURRENT and m.device.frames_in == 4  # the last of the burst holds
    m = emu(90)
    assert abs(m.device.core.meter.current_a - 2.5) < 0.05


def test_servo_special_frames_origin_and_status(emu) -> None:
    m = emu(1, POWER_ON, _servo(1, struct.pack(">i", 2000)))
    assert m.device.special_frames == 1 and m.device.core.mode is DriveMode.CURRENT  # power-on is not SET_DUTY
    m = emu(50, POWER_OFF)
    assert m.device.core.mode is DriveMode.RELEASED and m.device.special_frames == 2
    m = emu(60, _servo(5, b"\x00"))
    assert m.device.core.origin_deg != 0.0  # the foot fell: SET_ORIGIN_HERE 0 took the present angle
    m = emu(70, _servo(5, b"\x02"))
    assert m.device.core.origin_deg == 0.0  # 2: the default zero
    m = emu(80, _servo(5, b"\x09"))
    assert m.device.ignored_frames == 1
    status = [can_servo.decode_status(f.data) for f in m.port.sent if f.arbitration_id == can_servo.status_id(1)]
    assert len(status) + m.device.status_superseded == 40  # 500 Hz up to 80 ms; the steps at 50, 60, 70 and 80 ms
    # each send the latest one due
    assert len(status) == 4 and all(s.temperature_c >= 20 and s.error == 0 for s in status)


def test_set_pos_spd_moves_at_the_commanded_speed(emu) -> None:
    """SET_POS_SPD's int16 speed is in units of 10 ERPM (manual 5.1.7): 100 -> 1000 ERPM = 1000/14 rpm at the
    rotor, 11.9 deg/s at the actuator's output (/6)."""
    frame = _servo(6, struct.pack(">ihh", 30 * 10_000, 100, 3000))  # 30 deg at 1000 ERPM, 30 000 ERPM/s
    emu(1, frame)
    angles = []
    for k in range(2, 251):
        angles.append(emu(k).device.core.pid_pos_deg())
    speed_deg_s = (angles[199] - angles[99]) / 0.1  # from 101 to 201 ms: cruising, far from the target
    assert speed_deg_s == pytest.approx(1000 / 14 / 60 * 360 / 6, rel=0.05)


def test_a_quiet_mit_motor_keeps_its_plant_integrated_so_the_first_reply_is_not_late() -> None:
    """An MIT-mode motor has no event before its first frame: nothing queried the plant, and the first power-on frame
    used to integrate the whole quiet spell (seconds of plant: 65 ms of CPU, over 200 ms under load) before its reply
    went out, longer than TMotorCANControl's start-up check waits (issue 37). Each step now integrates the plant up
    to its present."""
    clock = [0]
    m = WallCanMotor(_Port(), CanUrl("test", "x", 1, "mit"), clock_ns=lambda: clock[0])
    for ms in (1, 500, 1000, 2000):
        clock[0] = ms * 1_000_000
        m.step()
        assert m.world.plant.latest_time_s == ms / 1000  # integrated up to the world's present, no frame yet
    clock[0] = 2_000_001_000
    m.port.waiting.append(CanFrame(1, b"\xff" * 7 + b"\xfc"))  # MIT mode: enter motor mode
    m.step()
    clock[0] = 2_000_100_000
    m.step()
    assert [f.arbitration_id for f in m.port.sent] == [0] and m.device.motor_mode  # answered 50 us after it


@pytest.mark.parametrize(("convention", "wire_per_plant"), [("catalogue", 1.0), ("rms", 1.5 ** -0.5),
                                                             ("peak", 2 / 3 ** 0.5)])
def test_current_convention_scales_the_amps_on_the_wire_only(convention: str, wire_per_plant: float) -> None:
    """An AK80-9 served as opensourceleg sees it: with the RMS convention, 0.115 N m/A (its Kt_actual) times the amps
    it commands and reads is the torque the plant's motor makes (the catalogue's 0.095 N m/A x the plant's amps) within
    5 % (docs/hardware.md, "Current conventions")."""
    from hal.virtual.devices.ak60_can import Ak60CanConfig
    from host_tools.serial_mode.served_plant import served_plant

    served = served_plant(motor="ak80_9")
    clock = [0]
    m = WallCanMotor(_Port(), CanUrl("test", "x", 1, "servo"), clock_ns=lambda: clock[0], plant_options=served.options,
                     can_config=Ak60CanConfig(limits=served.limits, current_convention=convention))
    for ms in range(1, 41):
        clock[0] = ms * 1_000_000
        m.port.waiting.append(_servo(1, struct.pack(">i", 2000)))  # SET_CURRENT 2 A, every ms
        m.step()
    plant_a = m.world.plant.state_at(m.world.now / 1e9).current_q_a
    assert plant_a == pytest.approx(2.0 / wire_per_plant, rel=0.01)
    status = [can_servo.decode_status(f.data) for f in m.port.sent if f.arbitration_id == can_servo.status_id(1)]
    assert status[-1].current_a == pytest.approx(2.0, abs=0.02)  # the client reads back what it commanded
    if convention == "rms":
        sdk_torque = 0.115 * status[-1].current_a  # opensourceleg's AK80-9 Kt_actual (rotor side)
        assert sdk_torque == pytest.approx(served.motor.kt_nm_per_a * plant_a, rel=0.05)
