"""The AK drive's safe behaviours on the plant: torque against speed (phase short, regenerative brake, MIT damping)
and against angle (handbrake, the MIT hold), and the drive's own command timeout
(hal/virtual/devices/ak60_winding.py)."""

from __future__ import annotations

import math

import pytest
from test_ak60 import F, Rig

from firmware.drivers.can_mit import CanMitDriver
from firmware.safe_state import SafeCommand, SafePolicy
from hal.can import CanFrame, CanPort
from hal.virtual.devices.ak60 import DriveMode
from hal.virtual.devices.ak60_can import Ak60Can, Ak60CanConfig
from hal.virtual.devices.ak60_config import Ak60Config
from hal.virtual.devices.ak60_winding import Winding
from hal.virtual.devices.world import World
from hal.virtual.plant import Plant
from protocol import can_mit, can_servo
from protocol.vesc import SetCurrent, SetCurrentBrake, SetDuty, SetHandbrake


def _loaded(rig: Rig, load_nm: float, message: object, until_s: float) -> list[tuple[float, float, float, float]]:
    """Command message at 1 ms under a constant ankle load; (t, ankle angle, rotor speed, q current) every 10 ms."""
    rig.plant.set_external_torque(load_nm, 0.0)
    rig.at(0.001)
    rig.send(message.encode())  # type: ignore[attr-defined]
    rows = []
    for k in range(1, int(until_s / 0.01) + 1):
        tick = round((0.001 + 0.01 * k) * F)
        rig.world.advance_to(tick)
        st = rig.plant.state_at(tick / F)
        rows.append((tick / F, st.output_angle_rad, st.motor_velocity_rad_s, st.current_q_a))
    return rows


def _winding(rig: Rig) -> Winding:
    p = rig.plant.params
    return Winding(p.ke_v_s_per_rad, p.phase_resistance_ohm, p.phase_inductance_h, p.pole_pairs)


@pytest.mark.parametrize("load_nm", [6.0, 15.0])
def test_duty_zero_shorts_the_winding_its_current_is_the_back_emf_through_r_and_l(load_nm: float) -> None:
    rig = Rig()
    rows = _loaded(rig, load_nm, SetDuty(0.0), 0.3)
    winding = _winding(rig)
    _, angle, w, i = rows[-1]
    assert rig.motor.mode is DriveMode.DUTY
    assert w > 1.0 and abs(angle) < math.radians(30.0)  # a steady speed, not in a stop
    assert i == pytest.approx(winding.duty_current_a(0.0, 24.0, w), rel=0.01)
    assert rows[-1][2] == pytest.approx(rows[-5][2], rel=0.02)  # the short balances the load: steady speed
    assert 0.5 * load_nm < abs(i * rig.plant.params.output_torque_per_amp_nm) < load_nm  # friction takes the rest


def test_the_short_brakes_harder_with_speed_until_r_over_l_then_less() -> None:
    winding = Winding(0.0716, 0.202, 138e-6, 14)
    peak_w = 0.202 / (14 * 138e-6)  # rotor rad/s where w_e L = R
    speeds = [0.25 * peak_w, 0.5 * peak_w, peak_w, 2.0 * peak_w, 4.0 * peak_w]
    currents = [-winding.duty_current_a(0.0, 24.0, w) for w in speeds]
    assert currents[:3] == sorted(currents[:3]) and currents[2:] == sorted(currents[2:], reverse=True)
    assert currents[2] == pytest.approx(0.0716 / (2 * 14 * 138e-6), rel=1e-9)  # Ke / (2 p L): 18.5 A
    # a load beyond the short's largest braking torque runs the foot into its stop; one below it is held
    held, runaway = Rig(), Rig()
    _loaded(held, 20.0, SetDuty(0.0), 0.2)
    rows = _loaded(runaway, 45.0, SetDuty(0.0), 0.2)
    assert held.plant.state_at(held.t / F + 0.201).in_contact is False
    assert max(r[2] for r in rows) > 2.0 * peak_w  # past the peak: the inductance lets it run


def test_regenerative_brake_is_the_short_below_its_cap_and_the_cap_above() -> None:
    short, brake = Rig(), Rig()
    rows_short = _loaded(short, 3.0, SetDuty(0.0), 0.2)
    rows_brake = _loaded(brake, 3.0, SetCurrentBrake(2.0), 0.2)
    assert rows_brake[-1][2] == pytest.approx(rows_short[-1][2], rel=0.02)  # same speed: the short's current
    assert abs(rows_brake[-1][3]) < 2.0
    fast = _loaded(Rig(), 6.0, SetCurrentBrake(2.0), 0.2)
    assert fast[-1][3] == pytest.approx(-2.0, abs=1e-3)  # capped at the brake current
    assert fast[-1][2] > fast[len(fast) // 2][2] > 0.0  # and the load keeps accelerating it


def test_the_brake_current_at_rest_is_zero() -> None:
    rig = Rig(initial_angle_rad=0.6283)  # pressed against the dorsiflexion stop: at rest
    rig.plant.set_external_torque(5.0, 0.0)
    rig.send(SetCurrentBrake(5.0).encode())
    rig.at(0.3)
    rig.world.advance_to(rig.t)
    assert abs(rig.plant.current_q_a(rig.t / F)) < 1e-3  # 5 A asked: the shorted winding carries nothing at rest


def test_handbrake_holds_the_rotor_within_90_electrical_degrees_and_slips_beyond() -> None:
    p = Rig().plant.params
    holding_nm = p.output_torque_per_amp_nm * 5.0  # Kt I N eta: 9.4 N m at 5 A on the AK60-6
    pole_deg = 360.0 / p.pole_pairs / p.total_ratio  # one pole pitch at the ankle: 0.93 deg
    rig = Rig()
    rows = _loaded(rig, 0.5 * holding_nm, SetHandbrake(5.0), 0.3)
    assert rig.motor.mode is DriveMode.HANDBRAKE
    assert all(abs(math.degrees(r[1])) < 0.25 * pole_deg for r in rows)  # inside 90 electrical degrees
    assert abs(rows[-1][2]) < 0.01  # and still
    slip = _loaded(Rig(), 1.3 * holding_nm, SetHandbrake(5.0), 0.3)
    assert max(abs(math.degrees(r[1])) for r in slip) > 10.0 * pole_deg  # slipped pole after pole


def _mit(kd: float, load_nm: float, until_s: float) -> tuple[Ak60Can, float, float]:
    """An AK60-6 in MIT mode told kp = 0, kd under a constant ankle load; (device, output speed, torque) at the end."""
    plant = Plant()
    world = World(plant, F)
    dev = Ak60Can(world, None, Ak60CanConfig(mode="mit"))
    plant.set_external_torque(load_nm, 0.0)
    dev.on_frame(CanFrame(1, can_mit.ENTER_MOTOR_MODE), 1000)
    dev.on_frame(CanFrame(1, can_mit.encode_command(can_mit.MitCommand(kd=kd), can_mit.AK60_6)), 2000)
    end = round(until_s * F)
    world.advance_to(end)
    st = plant.state_at(end / F)
    gear = plant.params.gearbox_ratio
    torque = st.current_q_a * plant.params.kt_nm_per_a * gear  # the law's torque at the planetary's output
    return dev, st.motor_velocity_rad_s / gear, torque


def test_mit_damping_is_a_torque_against_speed() -> None:
    dev, v, torque = _mit(kd=2.0, load_nm=6.0, until_s=0.2)
    assert dev.core.mode is DriveMode.CURRENT and v > 0.1
    assert torque == pytest.approx(-2.0 * v, rel=0.05)  # kd (v_des - v), v_des = 0
    _, v_soft, _ = _mit(kd=0.5, load_nm=6.0, until_s=0.2)
    assert v_soft > 2.0 * v  # less damping, faster under the same load


def test_the_timeout_brakes_with_the_timeout_brake_current_or_releases() -> None:
    for brake_a, mode in [(3.0, DriveMode.BRAKE), (0.0, DriveMode.RELEASED)]:
        rig = Rig(Ak60Config(timeout_s=0.05, timeout_brake_current_a=brake_a), initial_angle_rad=0.4)
        rig.send(SetCurrent(1.0).encode())
        rig.at(0.049)
        rig.world.advance_to(rig.t)
        assert rig.motor.mode is DriveMode.CURRENT
        rig.at(0.06)
        rig.world.advance_to(rig.t)
        assert rig.motor.mode is mode and rig.motor.timed_out


def test_can_servo_duty_and_brake_take_the_winding_laws() -> None:
    plant = Plant()
    world = World(plant, F)
    dev = Ak60Can(world, None, Ak60CanConfig(mode="servo"))
    for k, (packet, value, mode) in enumerate([(can_servo.PacketId.SET_DUTY, 0.0, DriveMode.DUTY),
                                               (can_servo.PacketId.SET_CURRENT_BRAKE, 2.0, DriveMode.BRAKE)]):
        t = round((k + 1) * 0.01 * F)
        dev.on_frame(CanFrame(can_servo.command_id(packet, 1), can_servo.encode_command(packet, value), True), t)
        world.advance_to(t + 10)
        assert dev.core.mode is mode


class _Port(CanPort):
    """Keeps what the firmware's driver sends."""

    def __init__(self) -> None:
        super().__init__(1_000_000)
        self.sent: list[CanFrame] = []

    def _send(self, frame: CanFrame) -> bool:
        self.sent.append(frame)
        return True

    def _receive(self) -> CanFrame | None:
        return None


def _mit_hold(kp: float, load_nm: float, until_s: float = 0.5) -> tuple[float, float, float]:
    """The firmware's MIT hold (safe_state = "hold" on CAN MIT, taken at the reported position 0) on an AK60-6 under
    a constant ankle load: (output position, output speed, the law's torque at the planetary's output) at the end."""
    policy = SafePolicy("hold", CanMitDriver.SAFE_BEHAVIOURS, "can-mit", brake_current_a=2.0, brake_delay_s=0.01,
                        damping_kd=1.0, hold_kp=kp)
    # the damper stands in for brake_delay_s after the trip, then the hold about the position reported then
    assert policy.command(0.005, 0.0, loaded=True, drive_fault=False, position_rad=0.0) == \
        SafeCommand("damping", kd=1.0)
    hold = policy.command(0.011, 0.0, loaded=True, drive_fault=False, position_rad=0.0)
    assert hold == SafeCommand("hold", kd=1.0, position_rad=0.0, kp=kp)
    port = _Port()
    driver = CanMitDriver(port)
    driver.send_safe(hold, 0.011)
    assert [f.data for f in port.sent] == [can_mit.ENTER_MOTOR_MODE,
                                           can_mit.encode_command(can_mit.MitCommand(kp=kp, kd=1.0), can_mit.AK60_6)]
    plant = Plant()
    world = World(plant, F)
    dev = Ak60Can(world, None, Ak60CanConfig(mode="mit"))
    plant.set_external_torque(load_nm, 0.0)
    for k, frame in enumerate(port.sent):
        dev.on_frame(frame, 1000 * (k + 1))
    end = round(until_s * F)
    world.advance_to(end)
    st = plant.state_at(end / F)
    gear = plant.params.gearbox_ratio
    return st.motor_angle_rad / gear, st.motor_velocity_rad_s / gear, st.current_q_a * plant.params.kt_nm_per_a * gear


def test_the_mit_hold_is_a_spring_and_damper_about_the_reported_position() -> None:
    p, v, torque = _mit_hold(kp=20.0, load_nm=6.0)
    assert abs(v) < 1e-3 and abs(p) > 0.01  # settled, displaced by the load: a spring, not a lock
    assert torque == pytest.approx(-20.0 * p, rel=0.05)  # kp (p_des - p), p_des = 0, at rest
    p_stiff, _, _ = _mit_hold(kp=40.0, load_nm=6.0)
    assert p_stiff == pytest.approx(p / 2.0, rel=0.1)  # twice the kp, half the give under the same load
