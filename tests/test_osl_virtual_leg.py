"""The virtual Open Source Leg (host_tools/osl): opensourceleg's interfaces on pafp's bench, and the example
impedance state machine, written against the OSL API only, walking 80 kg (issue 37). Skipped without opensourceleg
(the osl extra; `make test` installs it)."""

from __future__ import annotations

import math
import time
from pathlib import Path

import pytest

pytest.importorskip("opensourceleg", reason="the osl extra is not installed (make test installs it)")

from opensourceleg.actuators.base import CONTROL_MODES, ActuatorBase  # noqa: E402
from opensourceleg.sensors.base import EncoderBase, IMUBase, LoadcellBase  # noqa: E402

from host_tools.osl.virtual_leg import (  # noqa: E402
    VirtualActuator,
    VirtualEncoder,
    VirtualIMU,
    VirtualLeg,
    VirtualLoadcell,
)
from host_tools.osl.walk_osl import walk_osl  # noqa: E402


def test_the_classes_are_opensourcelegs_interfaces() -> None:
    leg = VirtualLeg()
    parts = (VirtualActuator(leg), VirtualEncoder(leg), VirtualLoadcell(leg), VirtualIMU(leg))
    for part, base in zip(parts, (ActuatorBase, EncoderBase, LoadcellBase, IMUBase), strict=True):
        assert isinstance(part, base)
    assert parts[0].gear_ratio == pytest.approx(leg.params.gearbox_ratio * leg.params.belt_ratio)


def test_output_torque_reaches_the_plant_through_kt_and_the_ratios() -> None:
    """CURRENT mode: 20 N m at the joint -> q current 20 / (Kt N); the drive's reply reports it back."""
    leg = VirtualLeg()
    act = VirtualActuator(leg)
    with act:
        act.set_control_mode(CONTROL_MODES.CURRENT)
        act.set_output_torque(20.0)
        for _ in range(40):
            act.update()
    amps = 20.0 / (leg.params.kt_nm_per_a * leg.params.total_ratio)
    assert leg.drive.core.meter.current_a == pytest.approx(amps, rel=0.02)
    assert act.motor_current == pytest.approx(amps, rel=0.02)  # through the MIT reply's 12-bit torque
    assert act.motor_torque * act.gear_ratio == pytest.approx(20.0, rel=0.02)


def test_the_example_walks_ten_strides_at_80_kg(tmp_path: Path) -> None:
    s = walk_osl(tmp_path / "a", strides=10, seed=0)
    assert s["faults"] == {"drive_fault": 0, "drive_faults_raised": 0, "command_timeouts": 0}
    assert s["phase_transitions"] == 40  # four phases a stride, every stride
    assert s["current_a"]["max_abs"] < s["current_a"]["peak_a"]
    enc = s["tracking"]["encoder"]
    assert enc["rms_deg"] < 10.0 and enc["max_deg"] < 25.0, enc  # pafp's own impedance controller: 3.2 / 10.1
    assert s["thermal"]["winding_max_c"] < 60.0


def test_same_seed_same_telemetry_bytes(tmp_path: Path) -> None:
    for name in ("a", "b"):
        walk_osl(tmp_path / name, strides=3, seed=5)
    assert (tmp_path / "a" / "telemetry.csv").read_bytes() == (tmp_path / "b" / "telemetry.csv").read_bytes()


def test_wall_clock_follows_the_wall() -> None:
    leg = VirtualLeg(clock="wall")
    act = VirtualActuator(leg)
    t0 = time.perf_counter()
    with act:
        while time.perf_counter() - t0 < 0.3:
            act.update()
            time.sleep(0.005)
    assert leg.t_s == pytest.approx(time.perf_counter() - leg._wall0, abs=0.05)
    assert math.isfinite(act.motor_position)
