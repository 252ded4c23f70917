"""The ground sensors: load cell (calibration, saturation, drift), FSRs (curve, hysteresis, divider, faults),
the ground reaction of the walking scenario, and the firmware's driver reading them through the ADC."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

from firmware.config import load_firmware_config
from firmware.drivers.ground_sensor_config import GroundSensorConfig
from firmware.drivers.ground_sensors import GroundSensorDriver
from hal.virtual.devices.fsr import Fsr, FsrParams
from hal.virtual.devices.load_cell import LoadCell, LoadCellParams
from hal.virtual.ground_sensors import ADC_CHANNELS, AdcSettings, load_ground_profile, wire_ground_sensors
from hal.virtual.plant.ground import NoGround
from host_tools.walk import ground_reaction, walking_load
from profiles import profile_path

F = 168_000_000


class Load:
    """A settable ground: vertical force, fore-aft force, CoP."""

    def __init__(self) -> None:
        self.value = (0.0, 0.0, 0.0)

    def at(self, t_s):
        return self.value


def _bench(ground, seed=0, noise=0.0):
    t = [0]
    gs = wire_ground_sensors(lambda: t[0], F, ground, AdcSettings(noise_lsb_rms=noise), seed=seed)
    return t, gs


def test_firmware_calibration_is_the_inverse_of_the_cells_sensitivity_and_gains():
    cell, _, _ = load_ground_profile()
    expected = np.linalg.inv(np.diag([cell.force_gain, cell.moment_gain]) @ np.array(cell.sensitivity()))
    fw = np.array(load_firmware_config().ground_sensors.calibration)
    assert fw == pytest.approx(expected, rel=1e-5)
    assert cell.force_gain == pytest.approx(1 + 100e3 / 229)  # INA333: G = 1 + 100 kOhm / RG


def test_a_designs_ground_sensors_are_the_packaged_ones_but_its_load_cell_and_its_calibration_follows() -> None:
    """profiles/ground_sensors/pylon_300nm.toml (the adult design's) changes only the cell's moment rating; the
    design profile's calibration is the inverse of that cell's sensitivity and gains, not the packaged cell's."""
    from hal.virtual.plant.design import load_design

    base_cell, base_fsr, base_foot = load_ground_profile()
    profile = profile_path("designs/adult_80kg.toml")
    path = load_design(profile).ground_profile
    cell, fsr, foot = load_ground_profile(path)
    assert (fsr, foot) == (base_fsr, base_foot)
    assert cell.rated_moment_nm == 300.0 and cell == replace(base_cell, rated_moment_nm=300.0)
    expected = np.linalg.inv(np.diag([cell.force_gain, cell.moment_gain]) @ np.array(cell.sensitivity()))
    fw = np.array(load_firmware_config(profile).ground_sensors.calibration)
    assert fw == pytest.approx(expected, rel=1e-5)
    assert fw[1][1] == pytest.approx(3 * np.array(load_firmware_config().ground_sensors.calibration)[1][1], rel=1e-5)


@pytest.mark.parametrize("force_n, moment_nm", [(0.0, 0.0), (200.0, 10.0), (800.0, -25.0), (1500.0, 60.0)])
def test_the_driver_recovers_applied_loads_through_the_adc(force_n, moment_nm):
    ground = Load()
    cfg = load_firmware_config().ground_sensors
    t, gs = _bench(ground, seed=3)
    drv = GroundSensorDriver(gs.adc, cfg, 0.001)
    for k in range(1, 400):  # unloaded while taring
        t[0] = k * F // 1000
        drv.sample(k / 1000)
    assert drv.tared
    cell = gs.load_cell
    h = cell.params.height_m
    ground.value = (force_n, -moment_nm / h if force_n == 0 else 0.0, moment_nm / force_n if force_n else 0.0)
    t[0] += 2 * F // 1000
    drv.sample(0.5)
    fz, my = cell.loads(0.5)
    lsb_n = cfg.calibration[0][0] * 3.3 / 4096  # one force LSB in N
    assert drv.force_n == pytest.approx(fz, abs=3 * lsb_n)
    assert drv.moment_nm == pytest.approx(my, abs=0.3)


def test_the_load_cell_saturates_at_the_amplifier_rails_and_the_driver_says_so():
    ground = Load()
    t, gs = _bench(ground)
    p = gs.load_cell.params
    ground.value = (10 * p.rated_force_n, 0.0, 0.0)
    assert gs.load_cell.force_volts(F) == pytest.approx(p.supply_v - p.swing_v)
    ground.value = (100.0, 0.0, -5.0 * p.rated_moment_nm / 100.0)
    assert gs.load_cell.moment_volts(F) == pytest.approx(p.swing_v)
    drv = GroundSensorDriver(gs.adc, GroundSensorConfig(), 0.001)
    ground.value = (10 * p.rated_force_n, 0.0, 0.0)
    t[0] = F
    drv.sample(1.0)
    assert drv.at_rail
    with pytest.raises(ValueError, match=r"LoadCellParams.crosstalk = 0.9 is outside the allowed range"):
        LoadCellParams(crosstalk=0.9)


def test_offsets_are_drawn_from_the_seed_and_drift_with_time():
    a, b, c = (LoadCell(LoadCellParams(), NoGround(), F, seed=s) for s in (1, 1, 2))
    assert a.offset_v == b.offset_v != c.offset_v
    assert a.force_volts(60 * F) - a.force_volts(0) == pytest.approx(
        a.params.force_gain * a.params.drift_per_min * 2e-3 * 3.3, rel=1e-6)


def test_fsr_curve_divider_hysteresis_and_faults():
    p = FsrParams()
    assert p.resistance_ohm(0.1) == p.open_ohm  # below the actuation force: open
    assert p.resistance_ohm(1.0) == pytest.approx(8e3)
    assert p.resistance_ohm(50.0) == p.resistance_ohm(20.0)  # saturated
    assert p.resistance_ohm(5.0, falling=True) == pytest.approx(0.9 * p.resistance_ohm(5.0))  # +10 % hysteresis
    assert p.volts(10e3) == pytest.approx(1.65) and p.volts(p.open_ohm) < 0.004
    force = [0.0]
    fsr = Fsr(p, lambda t_s: force[0] if t_s >= 1.0 else 0.0, F)
    force[0] = 100.0  # 5 N on the sensor (load share 5 %)
    rising, steady = fsr.volts(F), fsr.volts(2 * F)
    assert rising == pytest.approx(steady)
    fsr.set_fault("open")
    assert fsr.volts(2 * F) == 0.0
    fsr.set_fault("short")
    assert fsr.volts(2 * F) == p.supply_v
    with pytest.raises(ValueError, match="FSR fault 'cut' unknown"):
        fsr.set_fault("cut")


def test_ground_reaction_follows_the_normative_force_and_the_cop_rolls_heel_to_toe():
    load = walking_load(60.0, 1.1)
    ground = ground_reaction(load)
    assert ground.at(5.0) == (0.0, 0.0, 0.0)  # no gait yet
    load.bind(lambda: 1.0)
    fz, _, _ = ground.at(1.0 + 0.10 * 1.1)
    assert fz == pytest.approx(0.9891 * 60 * 9.81, rel=0.02)  # Schwartz 2008 free speed, 10 %: 0.99 BW
    cops = [ground.at(1.0 + pct / 100 * 1.1)[2] for pct in (1, 10, 30, 50)]
    assert cops == sorted(cops) and cops[0] < 0 < cops[-1]  # behind the ankle at heel strike, ahead at push-off
    assert ground.at(1.0 + 0.595 * 1.1) == (0.0, 0.0, 0.0)  # toe off at 59 %
    strikes, offs = ground.true_events(3.3)
    assert strikes == pytest.approx([1.0, 2.1, 3.2]) and offs == pytest.approx([1.649, 2.749])


def test_suspended_leaves_every_sensor_unloaded():
    t, gs = _bench(NoGround(), noise=1.0)
    t[0] = 3 * F
    codes = dict(zip(ADC_CHANNELS, gs.adc.read(), strict=True))
    assert codes["fsr_heel"] < 10 and codes["fsr_toe"] < 10  # divider at 0 V, a few LSB of noise
    p = gs.load_cell.params
    assert abs(gs.adc.volts(codes["load_force"]) - p.force_ref_v) < 0.05  # at REF (+ the zero offset)
    assert abs(gs.adc.volts(codes["load_moment"]) - p.moment_ref_v) < 0.05


def test_firmware_profile_checks_its_ground_sensor_table():
    with pytest.raises(ValueError, match="fsr_on_v = 0.5 is not allowed"):
        GroundSensorConfig(fsr_on_v=0.5)
    with pytest.raises(ValueError, match="singular"):
        GroundSensorConfig(calibration=((1.0, 2.0), (2.0, 4.0)))
    with pytest.raises(ValueError, match="has no key 'gain'"):
        GroundSensorConfig.from_table({"gain": 1})
