"""Efficiency by power direction: the planetary's backdriven efficiency and the plant's gain by direction."""

from __future__ import annotations

import dataclasses
import math

import pytest

from hal.virtual.plant import Plant, load_plant_params
from hal.virtual.plant.design import Design, plant_params_for
from hal.virtual.plant.params import plant_params_from_mapping
from hal.virtual.plant.transmission import planetary_backdriven_efficiency, planetary_stages

P = load_plant_params()


def torque_balance_backdriven(eta0: float, ratio: float) -> float:
    """One stage by its torques (ring fixed): carrier torque in, sun torque out, ring torque z_r/z_s T_sun / eta0."""
    k = ratio - 1.0  # z_ring / z_sun
    t_sun = 1.0
    t_ring = k * t_sun / eta0  # the meshes pass power ring -> sun in the carrier's frame: loss on the way in
    t_carrier = t_sun + t_ring
    return (t_sun * ratio) / t_carrier  # power out / power in, the sun turning ratio times the carrier's speed


@pytest.mark.parametrize("ratio", [3.0, 6.0, 9.0, 10.0])
@pytest.mark.parametrize("eta_fwd", [0.80, 0.90, 0.97, 1.0])
def test_the_planetary_backdriven_efficiency_is_the_torque_balance_of_its_meshes(eta_fwd: float, ratio: float) -> None:
    eta0 = (ratio * eta_fwd - 1.0) / (ratio - 1.0)
    eta_back = planetary_backdriven_efficiency(eta_fwd, ratio)
    assert eta_back == pytest.approx(torque_balance_backdriven(eta0, ratio), rel=1e-12)
    # never above the forward figure, and equal to it to first order in the loss
    loss = 1.0 - eta_fwd
    assert eta_back <= eta_fwd + 1e-15
    assert eta_fwd - eta_back <= 2.0 * loss * loss + 1e-15


def test_a_large_ratio_is_two_stages_and_a_hopeless_efficiency_is_refused() -> None:
    assert [planetary_stages(r) for r in (1.0, 6.0, 10.0, 10.5, 64.0)] == [1, 1, 1, 2, 2]
    assert planetary_backdriven_efficiency(0.81, 64.0) == pytest.approx(
        planetary_backdriven_efficiency(0.9, 8.0) ** 2)
    with pytest.raises(ValueError, match=r"gearbox efficiency 0\.15 is too low for a 6:1 planetary"):
        planetary_backdriven_efficiency(0.15, 6.0)


def test_the_shipped_plant_keeps_one_gain_and_a_profile_may_set_the_backdriven_efficiency() -> None:
    assert P.efficiency_backdriven is None
    assert P.backdriven_torque_per_amp_nm == P.output_torque_per_amp_nm
    assert P.output_torque_nm(-2.0, 1) == P.output_torque_nm(-2.0, -1) == -2.0 * P.output_torque_per_amp_nm
    import tomllib

    from hal.virtual.plant import default_profile_path

    data = tomllib.loads(default_profile_path().read_text(encoding="utf-8"))
    data["transmission"]["efficiency_backdriven"] = 0.85
    q = plant_params_from_mapping(data)
    assert q.backdriven_torque_per_amp_nm == pytest.approx(q.kt_nm_per_a * q.total_ratio / 0.85)
    data["transmission"]["efficiency_backdriven"] = 1.2
    with pytest.raises(ValueError, match=r"transmission\.efficiency_backdriven = 1\.2 is outside the allowed range"):
        plant_params_from_mapping(data)


def test_a_design_plant_is_backdriven_through_the_planetary_and_the_belt() -> None:
    q = plant_params_for(Design("ak70_10", 24, 144, 2.0), P)
    assert q.efficiency_backdriven == pytest.approx(planetary_backdriven_efficiency(0.90, 10.0) * 0.95)
    # the torque gain ratio backdriven / driving is 1 / (eta_fwd eta_back): the 1.37
    assert q.backdriven_torque_per_amp_nm / q.output_torque_per_amp_nm == pytest.approx(1.37, abs=0.01)


@pytest.mark.parametrize("direction", [1.0, -1.0])
def test_the_motor_receives_eta_back_of_the_ankle_power_and_gives_eta_fwd_of_its_own(direction: float) -> None:
    q = dataclasses.replace(P, efficiency_backdriven=0.8)
    plant = Plant(q, initial_velocity_rad_s=direction * 2.0)
    plant.set_current_command(-direction * 3.0, 0.0)  # against the motion: the ankle drives the rotor
    s = plant.state_at(0.01)
    assert s.output_velocity_rad_s * direction > 0 and s.current_q_a * direction < 0
    ankle_power = -s.output_torque_nm * s.output_velocity_rad_s  # into the transmission
    motor_power = -s.motor_torque_nm * s.motor_velocity_rad_s  # absorbed by the rotor
    assert motor_power == pytest.approx(0.8 * ankle_power, rel=1e-9)
    plant = Plant(q, initial_velocity_rad_s=direction * 2.0)
    plant.set_current_command(direction * 3.0, 0.0)  # along the motion: the motor drives the ankle
    s = plant.state_at(0.01)
    assert s.output_torque_nm * s.output_velocity_rad_s == pytest.approx(
        q.efficiency * s.motor_torque_nm * s.motor_velocity_rad_s, rel=1e-9)


def test_the_integrator_brakes_with_the_backdriven_gain() -> None:
    """Two plants alike but for eta_back: the one whose backdriven gain is larger slows the ankle faster, by it."""
    one = dataclasses.replace(P, coulomb_friction_nm=0.0, actuator_backdrive_torque_nm=0.0)
    two = dataclasses.replace(one, efficiency_backdriven=0.5)
    dv = []
    for q in (one, two):
        plant = Plant(q, initial_velocity_rad_s=3.0, initial_current_a=-4.0)
        plant.set_current_command(-4.0, 0.0)  # held: the current stays at -4 A
        a0 = plant.output_accel_rad_s2(0.0)
        dv.append((plant.output_velocity_rad_s(0.0005) - 3.0, a0))
    (dv_one, a_one), (dv_two, a_two) = dv
    extra = (two.backdriven_torque_per_amp_nm - one.output_torque_per_amp_nm) * -4.0 / two.output_inertia_kg_m2
    assert a_two - a_one == pytest.approx(extra, rel=1e-9)
    assert dv_two - dv_one == pytest.approx(extra * 0.0005, rel=0.01)


def test_a_designs_belt_is_its_pitchs_widest_unless_it_names_a_stock_width() -> None:
    from hal.virtual.plant.design import design_from_mapping

    table = {"motor": "ak70_10", "belt_driver_teeth": 18, "belt_driven_teeth": 62, "belt_pitch_mm": 5.0}
    d = design_from_mapping(dict(table), "t")
    per_mm = 712.0 / 25.4  # SDP/SI Table 3: 712 N per inch of a 5 mm GT belt
    assert d.width_mm == 25.0 and d.rated_tension_n == pytest.approx(25.0 * per_mm, rel=1e-12)
    assert design_from_mapping({**table, "belt_width_mm": 15}, "t").rated_tension_n == pytest.approx(15.0 * per_mm,
                                                                                                     rel=1e-12)
    with pytest.raises(ValueError, match=r"^t: \[design\] belt width 12.0 mm is not allowed for the 5 mm pitch: "
                                         r"one of 9, 15, 25$"):
        design_from_mapping({**table, "belt_width_mm": 12}, "t")
    with pytest.raises(ValueError, match=r"belt_width_mm = 'wide' is outside the allowed range \[1, 100\] mm"):
        design_from_mapping({**table, "belt_width_mm": "wide"}, "t")


def test_the_belt_ratings_agree_with_the_handbooks_rated_torque() -> None:
    """SDP/SI's rated torque of a 20-groove 2 mm GT pulley with a 6 mm belt, about 0.18 N m at 10 rpm, against the
    working tension of its Table 3 on that pulley's pitch radius (20 x 2 mm / 2 pi): within 10 %."""
    from hal.virtual.plant.transmission import BELT_RATED_N_PER_INCH, rated_belt_tension_n

    assert BELT_RATED_N_PER_INCH == {2.0: 111.0, 3.0: 507.0, 5.0: 712.0, 8.0: 1690.0}
    torque = rated_belt_tension_n(2.0, 6.0) * 20 * 2e-3 / (2.0 * math.pi)
    assert torque == pytest.approx(0.18, rel=0.10)
    assert torque == pytest.approx(111.0 * 6.0 / 25.4 * 6.366e-3, rel=1e-3)
