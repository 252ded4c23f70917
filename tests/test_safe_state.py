"""The firmware's safe-state policy (firmware/safe_state.py): [safety] safe_state chosen in the profile, carried by
each motor link as its drive's own behaviour, refused before the run where the link lacks it, and on the wire
after a fault on the virtual bench."""

from __future__ import annotations

import dataclasses
import logging

import pytest

from firmware.app import Firmware
from firmware.config import load_firmware_config
from firmware.safe_state import SAFE_STATES, SafeCommand, SafePolicy, check_offered
from firmware.safety_limits import SafetyLimits
from hal.virtual.bench import VirtualBench
from hal.virtual.devices.ak60 import DriveMode
from hal.virtual.devices.ak60_loops import LoopMode
from hal.virtual.faults import make_injector
from hal.virtual.faults.observer import Observer
from host_tools.runner import RunConfig, run_virtual
from host_tools.serial_mode.host_watchdog import stop_frames
from protocol import can_mit, can_servo
from protocol.vesc import SetCurrent, SetCurrentBrake, SetDuty, SetHandbrake

UART = ("release", "brake", "short", "handbrake", "hold")
SERVO = ("release", "brake", "short", "hold")
MIT = ("release", "brake", "damping", "hold")  # CanMitDriver.SAFE_BEHAVIOURS


def _policy(state: str, offered: tuple[str, ...] = UART) -> SafePolicy:
    return SafePolicy(state, offered, "test", brake_current_a=2.0, brake_delay_s=0.01, damping_kd=1.5)


def test_fixed_safe_states_and_the_brakes_delay() -> None:
    p = _policy("brake")
    assert p.command(1.005, 1.0, loaded=True, drive_fault=False) == SafeCommand("release")
    assert p.command(1.01, 1.0, loaded=True, drive_fault=False) == SafeCommand("brake", 2.0)
    assert _policy("short").command(1.0, 1.0, loaded=False, drive_fault=True) == SafeCommand("short")
    assert _policy("handbrake").command(1.0, 1.0, loaded=False, drive_fault=False) == SafeCommand("handbrake", 2.0)
    assert _policy("damping", MIT).command(1.0, 1.0, loaded=False, drive_fault=False) == SafeCommand("damping", kd=1.5)
    assert _policy("release").stop_command() == SafeCommand("release")


@pytest.mark.parametrize(("offered", "stance", "swing"), [
    (UART, SafeCommand("hold", position_rad=0.3), SafeCommand("short")),
    (SERVO, SafeCommand("hold", position_rad=0.3), SafeCommand("short")),
    (MIT, SafeCommand("damping", kd=1.5), SafeCommand("damping", kd=1.5 * 0.25)),
])
def test_graded_holds_while_loaded_keeps_that_hold_in_swing_lets_a_swing_foot_go_and_releases_on_a_drive_fault(
        offered: tuple[str, ...], stance: SafeCommand, swing: SafeCommand) -> None:
    p = _policy("graded", offered)
    damper = SafeCommand("short") if "short" in offered else stance
    assert p.stop_command() == damper  # before any: the damper
    # the short first for brake_delay_s (the current a fault wound up decays), then the hold
    assert p.command(1.0, 1.0, loaded=True, drive_fault=False, position_rad=0.2) == damper
    assert p.command(1.01, 1.0, loaded=True, drive_fault=False, position_rad=0.3) == stance
    assert p.stop_command() == stance
    # a hold taken in stance stays through swing, at its target (a wound parallel spring would throw the foot); a
    # stance damper gives way to the swing's
    assert p.command(1.1, 1.0, loaded=False, drive_fault=False, position_rad=0.4) == \
        (stance if stance.behaviour == "hold" else swing)
    assert p.command(1.2, 1.0, loaded=True, drive_fault=True, position_rad=0.4) == SafeCommand("release")
    assert p.stop_command() == SafeCommand("release")
    q = _policy("graded", offered)  # met in swing: let go gently, before and after the brake's delay
    assert q.command(1.0, 1.0, loaded=False, drive_fault=False, position_rad=0.2) == swing
    assert q.command(1.05, 1.0, loaded=False, drive_fault=False, position_rad=0.2) == swing


def _hold(position_rad: float) -> SafeCommand:
    return SafeCommand("hold", position_rad=position_rad)


def test_the_hold_keeps_the_target_it_began_with_through_swing_and_the_next_stance() -> None:
    p = _policy("graded")
    assert p.command(1.01, 1.0, loaded=True, drive_fault=False, position_rad=0.1) == _hold(0.1)
    assert p.command(1.1, 1.0, loaded=True, drive_fault=False, position_rad=0.2) == _hold(0.1)
    assert p.command(1.2, 1.0, loaded=False, drive_fault=False, position_rad=0.2) == _hold(0.1)
    assert p.command(1.3, 1.0, loaded=True, drive_fault=False, position_rad=0.25) == _hold(0.1)
    p = _policy("graded")  # met in swing: the short, then a hold from the first stance on, where the foot is then
    assert p.command(1.01, 1.0, loaded=False, drive_fault=False, position_rad=0.1) == SafeCommand("short")
    assert p.command(1.2, 1.0, loaded=True, drive_fault=False, position_rad=0.25) == _hold(0.25)


def test_without_a_fresh_position_the_short_stands_in_for_the_hold() -> None:
    for state in ("graded", "hold"):
        p = _policy(state)
        assert p.command(1.05, 1.0, loaded=True, drive_fault=False, position_rad=None) == SafeCommand("short")
        assert p.command(1.1, 1.0, loaded=True, drive_fault=False, position_rad=0.2) == _hold(0.2)
    p = _policy("hold", SERVO)  # the fixed hold holds in swing too; a faulted drive's target is taken afresh
    assert p.command(1.0, 1.0, loaded=False, drive_fault=False, position_rad=0.05) == SafeCommand("short")
    assert p.command(1.01, 1.0, loaded=False, drive_fault=False, position_rad=0.1) == _hold(0.1)
    assert p.command(1.1, 1.0, loaded=False, drive_fault=True, position_rad=0.5) == SafeCommand("short")
    assert p.command(1.2, 1.0, loaded=False, drive_fault=False, position_rad=0.5) == _hold(0.5)


@pytest.mark.parametrize(("state", "offered", "link"), [
    ("handbrake", SERVO, "can-servo"), ("damping", UART, "uart"), ("short", MIT, "can-mit"),
    ("handbrake", MIT, "can-mit"), ("hold", ("release", "hold"), "test")])  # the hold needs a damper to stand in
def test_a_safe_state_the_link_lacks_is_refused_naming_it(state: str, offered: tuple[str, ...], link: str) -> None:
    with pytest.raises(ValueError, match=f"safe_state = '{state}' is not offered by the {link} link: it offers"):
        check_offered(state, offered, link)


def test_every_link_offers_release_and_graded() -> None:
    for offered in (UART, SERVO, MIT):
        for state in ("release", "graded"):
            check_offered(state, offered, "x")


def test_the_profile_value_is_checked_with_its_allowed_values() -> None:
    with pytest.raises(ValueError, match="safe_state = 'coast' is not allowed: one of release, brake, short"):
        SafetyLimits(safe_state="coast")
    with pytest.raises(ValueError, match="damping_kd"):
        SafetyLimits(damping_kd=6.0)  # beyond MIT mode's kd range
    assert set(SAFE_STATES) == {"release", "brake", "short", "handbrake", "damping", "hold", "graded"}


def _cfg(link: str, state: str):
    cfg = load_firmware_config()
    return cfg.with_changes(motor_link=link, safety=dataclasses.replace(cfg.safety, safe_state=state))


def test_the_firmware_refuses_before_the_run_a_safe_state_its_link_lacks() -> None:
    bench = VirtualBench(lambda: 0, 168_000_000, motor_link="can-servo")
    with pytest.raises(ValueError, match="'handbrake' is not offered by the can-servo link"):
        Firmware(bench.board, _cfg("can-servo", "handbrake"))


@pytest.mark.parametrize(("state", "expected"), [
    ("short", SetCurrent(0.0).encode() + SetDuty(0.0).encode()),
    ("handbrake", SetCurrent(0.0).encode() + SetHandbrake(2.0).encode()),
    ("hold", SetCurrent(0.0).encode() + SetDuty(0.0).encode()),  # no position yet: the short stands in
    ("release", SetCurrent(0.0).encode()),
    ("brake", SetCurrent(0.0).encode() + SetCurrentBrake(2.0).encode()),
])
def test_the_stop_path_ends_with_the_safe_behaviour_uart(state: str, expected: bytes) -> None:
    data, _ = stop_frames(VirtualBench(lambda: 0, 168_000_000).board, _cfg("uart", state))
    assert data == expected


def test_the_stop_path_ends_with_the_safe_behaviour_can() -> None:
    P = can_servo.PacketId
    _, frames = stop_frames(VirtualBench(lambda: 0, 168_000_000, motor_link="can-servo").board,
                            _cfg("can-servo", "short"))
    # alone: the bxCAN sends by identifier, so a zero current (0x101) queued beside it would go out last
    assert [(f.arbitration_id, f.data) for f in frames] == [(0x001, can_servo.encode_command(P.SET_DUTY, 0.0))]
    _, frames = stop_frames(VirtualBench(lambda: 0, 168_000_000, motor_link="can-servo").board,
                            _cfg("can-servo", "brake"))
    assert [(f.arbitration_id, f.data) for f in frames] == [
        (0x101, can_servo.encode_command(P.SET_CURRENT, 0.0)),
        (0x201, can_servo.encode_command(P.SET_CURRENT_BRAKE, 2.0))]
    _, frames = stop_frames(VirtualBench(lambda: 0, 168_000_000, motor_link="can-mit").board,
                            _cfg("can-mit", "damping"))
    assert [f.data for f in frames] == [can_mit.encode_command(can_mit.MitCommand(kd=1.0))]


@pytest.mark.parametrize(("link", "state", "mode"), [
    ("uart", "short", DriveMode.DUTY), ("uart", "handbrake", DriveMode.HANDBRAKE), ("uart", "brake", DriveMode.BRAKE),
    ("uart", "hold", DriveMode.LOOP), ("can-servo", "short", DriveMode.DUTY), ("can-servo", "hold", DriveMode.LOOP),
    ("can-mit", "damping", DriveMode.CURRENT)])
def test_after_a_fault_the_drive_does_the_safe_behaviour(link: str, state: str, mode: DriveMode) -> None:
    logging.getLogger("firmware.safety").setLevel(logging.ERROR)
    fault, obs = make_injector("imu_silent", 1.6, 0.2, seed=3), Observer()
    r = run_virtual(RunConfig(strides=1, trace_capacity=0, firmware=_cfg(link, state), faults=(obs, fault),
                              duration_s=1.9))
    sup = r.firmware.supervisor
    assert sup.reason.name == "IMU_TIMEOUT"
    dev = r.bench.motor_device
    core = getattr(dev, "core", dev)
    assert core.mode is mode
    if state == "hold":  # the drive's position loop, at the position the drive reported when the hold began
        assert core.loops.mode is LoopMode.POSITION
        assert abs(core.position_error_deg()) < 10.0  # pid_pos degrees (2 deg at the ankle): a unit slip would be far
    if link == "can-mit":
        assert dev.mit_command is not None and dev.mit_command.kd == pytest.approx(1.0, abs=0.01)
        assert dev.mit_command.kp == 0.0
    safe_s = obs.safe_on_wire_s(sup.tripped_at_s)
    assert safe_s is not None and safe_s - 1.6 < 0.06
