"""The parallel spring at the ankle: its moment in the plant, its keys, and the controllers taking it into account."""

from __future__ import annotations

import dataclasses
import math
from pathlib import Path

import pytest

from firmware.control.cascade import Cascade
from firmware.control.gains import FeedforwardParams, PidGains
from firmware.control.gait_events import LoadDetector
from firmware.control.impedance import Impedance, ImpedanceParams
from firmware.control.observation import Observation
from firmware.control.pid import Feedforward, parallel_spring_torque_nm
from hal.virtual.plant import Plant, load_plant_params
from hal.virtual.plant.params import plant_params_from_mapping
from profiles import profile_path, read_toml

K, ENGAGE = 200.0, 0.25  # N m/rad, rad: values whose products are exact in binary


def _plant(two_sided: bool, k: float = K):
    return dataclasses.replace(load_plant_params(), parallel_stiffness_nm_per_rad=k, parallel_engage_rad=ENGAGE,
                               parallel_two_sided=two_sided)


@pytest.mark.parametrize(("angle", "one", "two"), [
    (0.75, -100.0, -100.0),  # dorsiflexed 0.5 rad beyond the engagement: -k x 0.5 either way
    (0.5, -50.0, -50.0),
    (0.25, 0.0, 0.0),  # at the engagement angle
    (0.0, 0.0, 50.0),  # the plantarflexion side: only the two-sided spring pushes back
    (-0.25, 0.0, 100.0),
])
def test_the_spring_moment_at_a_few_angles_on_both_sides(angle: float, one: float, two: float) -> None:
    assert _plant(False).parallel_spring_torque_nm(angle) == one
    assert _plant(True).parallel_spring_torque_nm(angle) == two
    assert parallel_spring_torque_nm(K, ENGAGE, False, angle) == one  # the firmware's model says the same
    assert parallel_spring_torque_nm(K, ENGAGE, True, angle) == two
    assert load_plant_params().parallel_spring_torque_nm(angle) == 0.0  # the packaged plant has none


@pytest.mark.parametrize("two_sided", [False, True])
@pytest.mark.parametrize("angle", [0.45, 0.05])
def test_the_plant_feels_the_spring(angle: float, two_sided: bool) -> None:
    """The ankle's acceleration changes by exactly the spring's moment over the inertia; its energy by 1/2 k d^2."""
    base = Plant(load_plant_params(), initial_angle_rad=angle, initial_velocity_rad_s=0.5)
    sprung = Plant(_plant(two_sided), initial_angle_rad=angle, initial_velocity_rad_s=0.5)
    moment = _plant(two_sided).parallel_spring_torque_nm(angle)
    assert sprung.output_accel_rad_s2(0.0) - base.output_accel_rad_s2(0.0) == pytest.approx(
        moment / base.output_inertia_kg_m2, rel=1e-9, abs=1e-9)
    engaged = moment != 0.0
    assert engaged == (angle > ENGAGE or two_sided)
    assert sprung.energy_j(0.0) - base.energy_j(0.0) == pytest.approx(
        0.5 * K * (angle - ENGAGE) ** 2 if engaged else 0.0, abs=1e-12)
    # integrated: the sprung foot is pushed back towards the engagement angle
    later = 0.05
    if engaged:
        direction = 1.0 if angle < ENGAGE else -1.0
        assert direction * (sprung.output_angle_rad(later) - base.output_angle_rad(later)) > 0.0
    else:
        assert sprung.output_angle_rad(later) == base.output_angle_rad(later)


def test_the_spring_keys_load_from_a_plant_profile_and_default_to_none(tmp_path: Path) -> None:
    data = read_toml(profile_path("plant_ak60_6.toml"), "plant profile")
    assert plant_params_from_mapping(data).parallel_stiffness_nm_per_rad == 0.0
    spring = {"parallel_stiffness_nm_per_rad": 150.0, "parallel_engage_rad": -0.05, "parallel_two_sided": True}
    p = plant_params_from_mapping({**data, "spring": spring})
    assert (p.parallel_stiffness_nm_per_rad, p.parallel_engage_rad, p.parallel_two_sided) == (150.0, -0.05, True)
    with pytest.raises(ValueError, match=r"spring.parallel_stiffness_nm_per_rad = 5000.0 is outside the allowed "
                                         r"range \[0.0, 2000.0\]"):
        plant_params_from_mapping({**data, "spring": {**spring, "parallel_stiffness_nm_per_rad": 5000.0}})
    with pytest.raises(ValueError, match="spring.parallel_two_sided = 1 must be true or false"):
        plant_params_from_mapping({**data, "spring": {**spring, "parallel_two_sided": 1}})


FF = FeedforwardParams(0.05, 1.176, 0.15, 0.095, 72.0, 0.855)
FF_SPRING = dataclasses.replace(FF, parallel_stiffness_nm_per_rad=K, parallel_engage_deg=math.degrees(ENGAGE))


def test_the_feedforward_takes_the_spring_off_what_it_asks_of_the_motor() -> None:
    plain, sprung = Feedforward(FF), Feedforward(FF_SPRING)
    nm_per_a = 0.095 * 72.0 * 0.855
    assert plain.spring_current_a(0.75) == 0.0
    assert sprung.spring_current_a(0.75) == pytest.approx(-100.0 / nm_per_a, rel=1e-12)
    assert sprung.spring_current_a(0.0) == 0.0  # one-sided: nothing on the plantarflexion side
    gains = PidGains(8.0, 2.0, 0.02, 0.004), PidGains(0.2, 3.0)
    obs = Observation()
    obs.reference_rad = obs.angle_rad = 0.75
    a = Cascade(*gains, 0.001, 50.0, 8.0, plain, math.pi / 2).update(obs)
    b = Cascade(*gains, 0.001, 50.0, 8.0, sprung, math.pi / 2).update(obs)
    assert b - a == pytest.approx(100.0 / nm_per_a, rel=1e-9)  # the spring resists dorsiflexion: the motor less so
    with pytest.raises(ValueError, match="parallel_engage_deg = 45"):
        dataclasses.replace(FF, parallel_engage_deg=45.0)


def test_the_impedance_controller_and_the_load_detector_account_for_the_spring() -> None:
    nm_per_a = 0.095 * 72.0 * 0.855
    args = ({}, nm_per_a, 1.176 * 9.8 * 0.15, math.pi / 2, 0.05)
    plain = Impedance(ImpedanceParams(*args))
    sprung = Impedance(ImpedanceParams(*args, spring=(K, ENGAGE, True)))
    obs = Observation()
    obs.stance, obs.angle_rad = True, -0.25  # stance: the phase's spring-damper law
    a, b = plain.update(obs), sprung.update(obs)
    assert plain.published["torque_nm"] == sprung.published["torque_nm"]  # the law's moment is the same
    assert b - a == pytest.approx(-100.0 / nm_per_a, rel=1e-9)  # two-sided: it pushes dorsiflexion, the motor less
    det_plain = LoadDetector(0.001, nm_per_a, 0.05, 1.176 * 9.8 * 0.15, math.pi / 2, cutoff_hz=499.0)
    det_sprung = LoadDetector(0.001, nm_per_a, 0.05, 1.176 * 9.8 * 0.15, math.pi / 2, cutoff_hz=499.0,
                              feedforward=Feedforward(FF_SPRING))
    for det in (det_plain, det_sprung):
        det.update(0.0, 0.0, 0.75, 0.0)
    alpha = det_plain.alpha
    assert det_sprung.load_torque_nm - det_plain.load_torque_nm == pytest.approx(alpha * 100.0, rel=1e-9)


def test_a_walk_with_a_spring_needs_less_current(tmp_path: Path) -> None:
    """80 kg at free speed on the AK10-9 with a 5:1 belt, with and without a one-sided 300 N m/rad spring from
    2 deg: the motor's reported current (a bench figure) is lower with the spring, and neither run faults."""
    import csv
    import json

    from hal.virtual.plant.design import Design, DesignSpring
    from host_tools.cli import main
    from host_tools.design_profile import design_profile_text

    rms = {}
    for name, spring in (("plain", None), ("spring", DesignSpring(300.0, 2.0, "one"))):
        profile = tmp_path / f"{name}.toml"
        profile.write_text(design_profile_text(Design("ak10_9", 20, 100, 2.0, spring=spring)))
        out = tmp_path / name
        assert main(["run", "--quiet", "--no-plot", "--no-trace", "--scenario", "walk", "--body-mass", "80",
                     "--speed", "free", "--controller", "impedance", "--strides", "2", "--profile", str(profile),
                     "--out", str(out)]) == 0
        assert not json.loads((out / "summary.json").read_text())["faults"]
        with (out / "telemetry.csv").open() as fh:
            current = [float(r["current_meas_a"]) for r in csv.DictReader(fh) if r["supervisor_state_name"] == "RUN"]
        rms[name] = math.sqrt(sum(c * c for c in current) / len(current))
    assert rms["spring"] < 0.8 * rms["plain"], rms


def test_the_swing_law_does_not_push_the_foot_into_a_one_sided_spring() -> None:
    """In swing, with the reference beyond a one-sided spring's engagement, the impedance law's equilibrium is the
    engagement (the motor neither loads the spring nor takes its energy back); below it, and with a two-sided spring,
    the reference."""
    def swing(sided_two: bool, ref_deg: float) -> tuple[float, float]:
        law = Impedance(ImpedanceParams({}, 10.0, 0.0, 0.0, 0.05, (400.0, math.radians(2.0), sided_two)))
        obs = Observation()
        obs.reference_rad = math.radians(ref_deg)
        obs.reference_velocity_rad_s, obs.reference_acceleration_rad_s2 = 1.0, 5.0
        law.update(obs)
        return law.published["equilibrium_deg"], law.published["torque_nm"]

    eq, torque = swing(False, 8.0)
    assert eq == pytest.approx(2.0) and torque == pytest.approx(100.0 * math.radians(2.0))  # no reference motion
    assert swing(False, -5.0)[0] == pytest.approx(-5.0)
    assert swing(True, 8.0)[0] == pytest.approx(8.0)


def test_the_load_detector_counts_a_braking_current_by_the_backdriven_gain() -> None:
    """With [feedforward] efficiency_backdriven, a current against the motion delivers 1 / (eta_fwd eta_back) of the
    driving moment per ampere, and the detector's external moment says so; along the motion, the driving gain."""
    ff = Feedforward(FeedforwardParams(0.05, 1.176, 0.15, 0.095, 31.0, 0.855, efficiency_backdriven=0.85))
    share = ff.backdriven_share

    def external(velocity: float) -> float:
        det = LoadDetector(0.001, ff.nm_per_a, 0.0, 0.0, math.pi / 2, cutoff_hz=499.0, feedforward=ff)
        for k in range(50):
            det.update(k * 0.001, -2.0, 0.0, 0.0, velocity)
        return det.load_torque_nm

    assert external(0.5) == pytest.approx(2.0 * ff.nm_per_a / share, rel=1e-6)  # braking: more moment per ampere
    assert external(-0.5) == pytest.approx(2.0 * ff.nm_per_a, rel=1e-6)
