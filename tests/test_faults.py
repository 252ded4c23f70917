"""The fault injectors (hal/virtual/faults): each fires, records when and what, and has its effect on the bench."""

from __future__ import annotations

import dataclasses
import logging
import math

import pytest

from firmware.config import load_firmware_config
from hal.virtual.faults import INJECTORS, injector_class, make_injector
from hal.virtual.faults.observer import Observer
from hal.virtual.faults.rvc_frames import rewrite_frames
from hal.virtual.faults.wire_faults import flip_bits
from host_tools.runner import RunConfig, run_virtual
from protocol.rvc import RvcFrame

ONSET_S, DURATION_S, RUN_S = 1.6, 0.2, 2.0

# the supervisor's reason each fault must trip on the UART link (None: no check catches it in this window)
EXPECTED = {
    "imu_frozen": "IMU_FROZEN", "imu_silent": "IMU_TIMEOUT", "imu_bias_step": "SENSOR_DISAGREEMENT",
    "imu_corrupt": "IMU_TIMEOUT", "encoder_glitch": "MOTOR_ENCODER_DISAGREEMENT",
    "encoder_stuck": "MOTOR_ENCODER_DISAGREEMENT", "encoder_reversed": "MOTOR_ENCODER_DISAGREEMENT",
    "motor_replies_lost": "MOTOR_TIMEOUT", "motor_frames_corrupt": "MOTOR_TIMEOUT", "motor_over_temp": "MOTOR_FAULT",
    "motor_fault_code": "MOTOR_FAULT", "motor_stall": None, "supply_sag": "MOTOR_FAULT",
    "task_overrun": "DEADLINE_MISSES", "controller_raise": "CONTROLLER_ERROR", "controller_nan": "CONTROLLER_ERROR",
    "can_bus_off": "MOTOR_TIMEOUT", "can_error_passive": None,
}


def _run(name: str, link: str = "uart", **params: object):
    logging.getLogger("firmware.safety").setLevel(logging.ERROR)
    fw = load_firmware_config()
    if link != "uart":
        fw = dataclasses.replace(fw, motor_link=link)
    fault, obs = make_injector(name, ONSET_S, DURATION_S, seed=3, **params), Observer()
    r = run_virtual(RunConfig(strides=1, trace_capacity=0, firmware=fw, faults=(obs, fault), duration_s=RUN_S))
    return r, fault, obs


def test_the_table_names_every_injector_and_each_loads():
    assert set(INJECTORS) == set(EXPECTED)
    for name in INJECTORS:
        cls = injector_class(name)
        assert cls.NAME == name and cls.HAZARD and cls.WHERE


@pytest.mark.parametrize("name", sorted(EXPECTED))
def test_each_injector_fires_in_its_window_and_has_its_effect(name):
    link = "can-servo" if name.startswith("can_") else "uart"
    r, fault, obs = _run(name, link)
    rec = fault.record
    assert rec.fired and rec.count >= 1 and rec.what
    assert ONSET_S <= rec.first_s < ONSET_S + 0.01  # fired at its onset (within a control period)
    assert rec.last_s < ONSET_S + DURATION_S or name == "encoder_glitch" or name.startswith("encoder_")
    sup = r.firmware.supervisor
    expected = EXPECTED[name]
    if expected is None:
        assert sup.reason.name == "NONE" or sup.tripped_at_s > ONSET_S  # not caught at once
    else:
        assert sup.reason.name == expected and ONSET_S <= sup.tripped_at_s < ONSET_S + DURATION_S
        safe = obs.safe_on_wire_s(sup.tripped_at_s)
        if name == "can_bus_off":  # nothing crosses the bus until it recovers: the safe command neither
            assert safe is not None and safe >= ONSET_S + DURATION_S
        else:
            assert safe is not None and sup.tripped_at_s < safe < sup.tripped_at_s + 0.005


def test_a_fault_outside_the_run_never_fires():
    fault, obs = make_injector("motor_replies_lost", 5.0, 0.1), Observer()
    r = run_virtual(RunConfig(strides=1, trace_capacity=0, faults=(obs, fault), duration_s=1.0))
    assert not fault.record.fired and r.firmware.supervisor.reason.name == "NONE"


def test_the_observer_changes_nothing_before_the_onset():
    """The paired fault-free run and the faulted one agree exactly until the fault acts."""
    fw = load_firmware_config()
    runs = []
    for faults in ((Observer(),), (Observer(), make_injector("encoder_glitch", 1.2, 0.1))):
        run_virtual(RunConfig(strides=1, trace_capacity=0, firmware=fw, faults=faults, duration_s=1.5))
        runs.append(faults[0].arrays())
    a, b = runs
    before = a["t_s"] < 1.2
    assert before.sum() > 1000
    assert (a["angle_rad"][before] == b["angle_rad"][before]).all()
    assert not (a["angle_rad"][~before] == b["angle_rad"][~before]).all()


def test_the_encoder_faults_change_the_count_as_described():
    r, fault, _ = _run("encoder_reversed")
    assert "counted" in fault.record.what
    r, fault, _ = _run("encoder_glitch", counts=-100)
    # the count is 100 counts (9 deg) off from the onset: the firmware's encoder angle jumps by that
    assert fault.record.fired


def test_bad_parameters_are_refused_naming_the_value():
    with pytest.raises(ValueError, match="bit_error_rate = 2"):
        make_injector("imu_corrupt", 1.0, 0.1, bit_error_rate=2)
    with pytest.raises(ValueError, match="task = 'cpu' unknown"):
        make_injector("task_overrun", 1.0, 0.1, task="cpu")
    with pytest.raises(ValueError, match="onset_s = -1"):
        make_injector("imu_silent", -1, 0.1)
    with pytest.raises(ValueError, match="duration_s = 0"):
        make_injector("imu_silent", 1, 0)
    with pytest.raises(ValueError, match="'nope' unknown"):
        make_injector("nope", 1, 1)
    with pytest.raises(ValueError, match="parameter 'volts' unknown"):
        make_injector("supply_sag", 1, 1, volts=3)


def test_flip_bits_is_seeded_and_always_flips():
    import random

    data = bytes(19)
    a = flip_bits(data, 1e-6, random.Random(1))
    assert a != data and a == flip_bits(data, 1e-6, random.Random(1))
    assert sum(bin(x).count("1") for x in a) == 1


def test_rewrite_frames_touches_whole_frames_only():
    f = RvcFrame(7, 0.0, 0.1, 0.0, 0.0, 0.0, 9.8).encode()
    out = rewrite_frames(f + f, lambda fr: RvcFrame(fr.index, 0.0, 0.5, 0.0, 0.0, 0.0, 9.8))
    assert RvcFrame.from_bytes(out[:19]).pitch_rad == pytest.approx(0.5, abs=1e-3)
    assert rewrite_frames(b"banner\r\n", lambda fr: fr) == b"banner\r\n"
    assert rewrite_frames(f[:10], lambda fr: fr) == f[:10]
    assert not math.isnan(RvcFrame.from_bytes(out[19:]).pitch_rad)


@pytest.mark.parametrize("battery", ["molicel_p42a_6s1p"])  # the 12S pack trips the 24 V AK60-6's over-voltage
def test_supply_sag_acts_on_a_fitted_battery(battery):
    """With a battery the sag caps the pack's EMF in its window: the driver's input falls below its 8 V
    under-voltage trip as on the fixed supply, the supervisor latches MOTOR_FAULT and the safe command leaves
    the wire; after the window the pack is itself again."""
    logging.getLogger("firmware.safety").setLevel(logging.ERROR)
    fault, obs = make_injector("supply_sag", ONSET_S, DURATION_S, seed=3), Observer()
    r = run_virtual(RunConfig(strides=1, trace_capacity=0, faults=(obs, fault), duration_s=RUN_S, battery=battery))
    pack = r.heat["battery"]
    assert pack is not None and pack.emf_limit_v is None  # recovered at the window's end (1.8 s < RUN_S)
    sup = r.firmware.supervisor
    assert fault.record.fired and fault.record.what
    assert sup.reason.name == "MOTOR_FAULT" and ONSET_S <= sup.tripped_at_s < ONSET_S + DURATION_S
    safe = obs.safe_on_wire_s(sup.tripped_at_s)
    assert safe is not None and sup.tripped_at_s < safe < sup.tripped_at_s + 0.005
