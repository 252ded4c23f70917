"""The motor's own position sees the gearbox backlash: the AK60-6's encoder is on the rotor, before the planetary
(PROTOCOLS.md B.3 ``pid_pos_now``), so across a reversal the position it reports moves through the free play while
the output (the ankle encoder's shaft) does not."""

from __future__ import annotations

import math

import pytest

from hal.virtual.devices.ak60 import Ak60
from hal.virtual.devices.world import World
from hal.virtual.plant import Plant, load_plant_params
from hal.virtual.plant.fixtures import Fixture, FixtureKind
from hal.virtual.uart import VirtualUart
from protocol import vesc

P = load_plant_params()
GAP = math.radians(0.55)  # the maker's backlash at the actuator (gearbox) output
HALF_ROTOR = 0.5 * GAP * P.gearbox_ratio  # half the free play at the rotor
# the foot's weight held by a hand at the ankle: with +-0.2 A (0.37 N m at the ankle, under the 0.93 N m static
# friction) the output stays put while the rotor turns through the gap on its own inertia (13 ms)
HELD = Fixture(FixtureKind.SUSPENDED, torque_nm=P.gravity_moment_nm)
I_A = 0.2


def _gap(plant: Plant, t: float) -> tuple[float, float, float]:
    """(rotor angle minus N x the output's, rotor speed minus N x the output's, output angle) at t."""
    s = plant.state_at(t)
    return (s.motor_angle_rad - P.total_ratio * s.output_angle_rad, s.motor_velocity_rad_s
            - P.total_ratio * s.output_velocity_rad_s, s.output_angle_rad)


def test_the_rotor_angle_crosses_the_gap_at_a_reversal_while_the_output_does_not():
    plant = Plant(P, HELD, backlash_rad=GAP)
    assert _gap(plant, 0.0)[0] == 0.0  # before any command: no side known
    plant.set_current_command(I_A, 0.0)
    before, _, out_before = _gap(plant, 0.0099)
    assert before == pytest.approx(HALF_ROTOR, abs=1e-12)  # the teeth rest on the command's side
    trace = []
    for k in range(20):  # reversed, every millisecond: the rotor turns through the gap on its own inertia
        t = 0.01 + k * 1e-3
        plant.set_current_command(-I_A, t)
        trace += [_gap(plant, t + f * 1e-3) for f in (0.25, 0.5, 0.75, 0.999)]
    phis = [g[0] for g in trace]
    after, w_after, out_after = trace[-1]
    assert after == pytest.approx(-HALF_ROTOR, abs=1e-12) and w_after == 0.0  # in contact on the other side
    assert all(b <= a + 1e-12 for a, b in zip(phis, phis[1:], strict=False))  # it moves one way, then rests
    inside = [g for g in trace if abs(g[0]) < HALF_ROTOR - 1e-9]
    assert 30 <= len(inside) <= 70 and all(g[1] < 0.0 for g in inside)  # crossing, backwards, for 13 ms
    # the reported rotor angle moved by the whole gap; the output not at all (held by static friction)
    assert before - after == pytest.approx(2 * HALF_ROTOR)
    assert out_after == out_before
    assert plant.gap_crossings == 1


def test_without_backlash_the_rotor_is_n_times_the_output():
    plant = Plant(P, HELD)
    plant.set_current_command(I_A, 0.0)
    plant.set_current_command(-I_A, 0.01)
    assert _gap(plant, 0.0125)[:2] == pytest.approx((0.0, 0.0), abs=1e-9)


def test_the_motors_reported_position_shows_the_backlash():
    """Over the UART: GET_VALUES' pid_pos (the planetary's output angle, rotor / 6) minus the belt ratio times the
    output angle is +- half the backlash, on the side the last command pushed."""
    f = 168_000_000
    now = [0]
    plant = Plant(P, HELD, backlash_rad=GAP)
    world = World(plant, f)
    motor = Ak60(world)
    uart = VirtualUart(lambda: now[0], f, 921_600, rx_buffer_size=4096, tx_queue_size=4096)
    uart.connect(motor)
    motor.connect(uart)
    decoder = vesc.Decoder("from-motor")

    def step(t_s: float, current_a: float) -> tuple[float, float]:
        """Command current_a at t_s with a GET_VALUES request; (its reply's pid_pos - belt x output [deg], output
        [deg]) at the request's arrival."""
        now[0] = round(t_s * f)
        frame = vesc.SetCurrent(current_a).encode() + vesc.GetValues().encode()
        assert uart.write(frame) == len(frame)
        end = uart.tx_line_busy_until
        now[0] = round((t_s + 1.9e-3) * f)  # the 78-byte reply is in
        world.advance_to(now[0])
        (values,) = [m for m in decoder.feed(uart.read()) if isinstance(m, vesc.Values)]
        output = math.degrees(plant.output_angle_rad(end / f))
        return math.degrees(values.pid_pos_rad) - P.belt_ratio * output, output

    pushing = [step(0.01 + k * 2e-3, I_A) for k in range(5)]
    pulling = [step(0.02 + k * 2e-3, -I_A) for k in range(15)]
    half_deg = 0.5 * math.degrees(GAP)
    assert pushing[-1][0] == pytest.approx(half_deg, abs=2e-6)  # pid_pos is in 1e-6 deg
    assert pulling[-1][0] == pytest.approx(-half_deg, abs=2e-6)
    assert any(abs(g) < half_deg - 0.01 for g, _ in pulling)  # caught mid-crossing
    assert pulling[-1][1] == pushing[0][1]  # the output did not move
