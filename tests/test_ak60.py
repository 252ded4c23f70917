"""AK60-6 driver model, protocol side: PROTOCOLS.md vectors, reply timing, averages, timeout, streaming."""

from __future__ import annotations

import dataclasses
import math
import struct

from doubles import SpyLink
from hypothesis import given, settings
from hypothesis import strategies as st

from hal.virtual.devices.ak60 import Ak60, DriveMode
from hal.virtual.devices.ak60_config import Ak60Config
from hal.virtual.devices.world import World
from hal.virtual.line import ceil_div
from hal.virtual.plant import Plant
from hal.virtual.uart import VirtualUart
from protocol.vesc import (
    Decoder,
    FwVersion,
    RotorPosition,
    SetCurrent,
    SetDetect,
    Values,
    ValuesSelective,
    encode_frame,
)

F = 168_000_000
BAUD = 921_600
GET_VALUES = bytes.fromhex("02 01 04 40 84 03")
FW_VERSION = bytes.fromhex("02 01 00 00 00 03")
SET_CURRENT_2A5 = bytes.fromhex("02 05 06 00 00 09 C4 EE D5 03")
ALIVE = bytes.fromhex("02 01 1E F3 FF 03")
SELECTIVE_ERPM_FAULT_POS = bytes.fromhex("02 05 32 00 01 80 80 F5 4D 03")
SET_DETECT_4 = bytes.fromhex("02 02 0B 04 9C 7E 03")


class Rig:
    """A world with the AK60-6 on a VirtualUart at 921600 baud; the test moves the MCU clock ``t``."""

    def __init__(self, config: Ak60Config | None = None, initial_angle_rad: float = 0.0) -> None:
        self.t = 0
        self.plant = Plant(initial_angle_rad=initial_angle_rad)
        self.world = World(self.plant, F)
        self.motor = Ak60(self.world, config)
        self.uart = VirtualUart(lambda: self.t, F, BAUD, rx_buffer_size=4096, tx_queue_size=4096)
        self.uart.connect(self.motor)
        self.motor.connect(self.uart)
        self.decoder = Decoder("from-motor")

    def at(self, t_s: float) -> None:
        self.t = max(self.t, round(t_s * F))

    def send(self, frame: bytes) -> int:
        """Write at the present tick; return the stop-bit end of the last byte."""
        assert self.uart.write(frame) == len(frame)
        return self.uart.tx_line_busy_until

    def replies(self) -> list:
        return self.decoder.feed(self.uart.read())

    def plant_at(self, t: int) -> tuple[float, float]:
        """(rotor angle, rotor speed) at tick t, after the device events up to t."""
        self.world.advance_to(t)
        t_s = t / F
        return self.plant.motor_angle_rad(t_s), self.plant.motor_velocity_rad_s(t_s)


def byte_ticks(k: int) -> int:
    return ceil_div(k * 10 * F, BAUD)


def test_get_values_reply_reflects_the_plant_byte_exact() -> None:
    rig = Rig(initial_angle_rad=0.4)  # the suspended foot falls: speed and position are non-zero
    rig.at(0.05)
    end = rig.send(GET_VALUES)
    angle, speed = rig.plant_at(end)
    rig.at(0.06)
    raw = rig.uart.read()
    assert raw[:3] == bytes.fromhex("02 49 04") and len(raw) == 78  # 73-byte payload, like manual p.41
    (values,) = Decoder("from-motor").feed(raw)
    assert isinstance(values, Values)
    assert Values(**{f.name: getattr(values, f.name) for f in dataclasses.fields(values)}).encode() == raw
    assert values.erpm == int(speed * 60 / math.tau * 14) and values.erpm < -100
    pid_pos_raw = struct.unpack(">i", raw[2 + 54 : 2 + 58])[0]
    assert abs(pid_pos_raw - math.degrees(angle / 6) * 1e6) <= 1
    assert values.tachometer == math.floor(angle * 14 * 6 / math.tau) - math.floor(0.4 * 28 * 14 * 6 / math.tau)
    assert values.controller_id == 0x7E and values.fault == 0
    assert values.temp_fet_c == values.temp_motor_c == 25.0
    assert 23.9 <= values.v_in_v <= 24.0


def test_selective_vector_echoes_the_mask_and_carries_the_fields() -> None:
    rig = Rig(initial_angle_rad=0.3)
    rig.at(0.02)
    end = rig.send(SELECTIVE_ERPM_FAULT_POS)
    angle, speed = rig.plant_at(end)
    rig.at(0.03)
    raw = rig.uart.read()
    payload = raw[2:-3]
    assert payload[:5] == bytes.fromhex("32 00 01 80 80") and len(payload) == 14
    erpm, fault, pid_raw = struct.unpack(">iBi", payload[5:])
    assert erpm == int(speed * 60 / math.tau * 14) and fault == 0
    expected = {"erpm": erpm, "fault": 0, "pid_pos_rad": math.radians(math.degrees(angle / 6))}
    assert abs(pid_raw - math.degrees(angle / 6) * 1e6) <= 1
    assert ValuesSelective(0x00018080, expected).encode() == raw


def test_selective_without_mask_echo() -> None:
    rig = Rig(Ak60Config(selective_mask_echo=False))
    rig.send(SELECTIVE_ERPM_FAULT_POS)
    rig.at(0.005)
    raw = rig.uart.read()
    assert raw[2] == 0x32 and raw[1] == 10  # id + int32 + uint8 + int32, no mask
    (msg,) = Decoder("from-motor", selective_mask_echo=False, selective_mask=0x00018080).feed(raw)
    assert set(msg.values) == {"erpm", "fault", "pid_pos_rad"}


def test_reply_starts_after_request_end_plus_latency() -> None:
    rig = Rig()
    rig.at(1000 / F)
    end = rig.send(GET_VALUES)
    assert end == 1000 + byte_ticks(6)
    start = end + round(50e-6 * F)
    rig.t = start + byte_ticks(1) - 1
    assert rig.uart.in_waiting() == 0
    rig.t += 1
    assert rig.uart.in_waiting() == 1
    rig.t = start + byte_ticks(78) - 1
    assert rig.uart.in_waiting() == 77
    rig.t += 1
    assert rig.uart.in_waiting() == 78


@settings(max_examples=25)
@given(cuts=st.lists(st.integers(1, 5), max_size=4, unique=True),
       gaps=st.lists(st.integers(0, 50_000), min_size=5, max_size=5))
def test_request_in_pieces_is_answered_only_after_its_last_byte(cuts: list[int], gaps: list[int]) -> None:
    rig = Rig()
    pieces = [FW_VERSION[a:b] for a, b in zip([0, *sorted(cuts)], [*sorted(cuts), 6], strict=True)]
    for piece, gap in zip(pieces, gaps, strict=False):
        rig.t += gap
        end = rig.send(piece)
        assert rig.replies() == []
    first = end + round(50e-6 * F) + byte_ticks(1)
    rig.t = max(rig.t, first - 1)
    assert rig.uart.in_waiting() == 0
    rig.t = first + byte_ticks(40)
    (reply,) = rig.replies()
    assert reply == FwVersion(3, 65, "AK60-6", b"pafp-ak60-6\x00")


def test_set_current_vector_drives_the_plant_from_its_end_time() -> None:
    rig = Rig()
    end = rig.send(SET_CURRENT_2A5)
    rig.world.advance_to(end - 1)
    assert rig.motor.mode is DriveMode.RELEASED
    rig.world.advance_to(end)
    assert rig.motor.mode is DriveMode.CURRENT
    tau = 0.00114
    t = end + round(tau * F)
    rig.world.advance_to(t)
    assert math.isclose(rig.plant.current_q_a(t / F), 2.5 * (1 - math.exp(-1)), rel_tol=1e-3)


def _lag_integral(i_target: float, t0: float, ta: float, tb: float, tau: float = 0.00114) -> float:
    """Integral over [ta, tb] of i_target (1 - e^(-(t - t0)/tau)) for t > t0 (zero before t0)."""
    ta, tb = max(ta, t0), max(tb, t0)
    return i_target * ((tb - ta) + tau * (math.exp(-(tb - t0) / tau) - math.exp(-(ta - t0) / tau)))


def test_averages_are_read_and_reset_per_request() -> None:
    rig = Rig()
    e_cmd = rig.send(SET_CURRENT_2A5)
    e1 = rig.send(GET_VALUES)
    rig.at(0.005)
    e2 = rig.send(GET_VALUES)
    e3 = rig.send(GET_VALUES)
    rig.at(0.02)
    v1, v2, v3 = rig.replies()
    s = [e / F for e in (0, e_cmd, e1, e2, e3)]
    expect1 = _lag_integral(2.5, s[1], s[0], s[2]) / (s[2] - s[0])
    expect2 = _lag_integral(2.5, s[1], s[2], s[3]) / (s[3] - s[2])
    expect3 = _lag_integral(2.5, s[1], s[3], s[4]) / (s[4] - s[3])
    for v, expect in ((v1, expect1), (v2, expect2), (v3, expect3)):
        assert abs(v.avg_iq_a - expect) <= 0.0101 and abs(v.avg_motor_current_a - expect) <= 0.0101
    assert v1.avg_iq_a < 0.5 < v2.avg_iq_a < v3.avg_iq_a  # each window starts where the previous ended


def test_each_average_resets_on_its_own() -> None:
    rig = Rig()
    e_cmd = rig.send(SET_CURRENT_2A5)
    rig.at(0.010)
    e_sel = rig.send(encode_frame(struct.pack(">BI", 50, 1 << 5)))  # avg_iq only
    e_full = rig.send(GET_VALUES)
    rig.at(0.02)
    sel, full = rig.replies()
    s_cmd, s_sel, s_full = e_cmd / F, e_sel / F, e_full / F
    assert abs(sel.values["avg_iq_a"] - _lag_integral(2.5, s_cmd, 0, s_sel) / s_sel) <= 0.0101
    assert abs(full.avg_iq_a - 2.5) <= 0.0101  # since the selective read: settled at 2.5 A
    assert abs(full.avg_motor_current_a - _lag_integral(2.5, s_cmd, 0, s_full) / s_full) <= 0.0101
    assert full.avg_motor_current_a < full.avg_iq_a


def test_command_timeout_releases_after_one_second() -> None:
    rig = Rig()
    end = rig.send(SetCurrent(1.0).encode())
    rig.world.advance_to(end + F - 1)
    assert rig.motor.mode is DriveMode.CURRENT and not rig.motor.timed_out
    assert rig.plant.state_at((end + F - 1) / F).current_command_a == 1.0
    rig.world.advance_to(end + F)
    assert rig.motor.mode is DriveMode.RELEASED and rig.motor.timed_out
    assert rig.plant.state_at((end + F) / F).current_command_a == 0.0
    rig.t = end + F + 1
    rig.send(encode_frame(struct.pack(">BI", 50, 1 << 21)))
    rig.at(rig.t / F + 0.001)
    (status,) = rig.replies()
    assert status.values == {"status": 1} and rig.motor.stats.timeouts == 1


def test_alive_postpones_the_timeout() -> None:
    rig = Rig()
    rig.send(SetCurrent(1.0).encode())
    rig.at(0.5)
    end_alive = rig.send(ALIVE)
    rig.world.advance_to(end_alive + F - 1)
    assert rig.motor.mode is DriveMode.CURRENT
    rig.world.advance_to(end_alive + F)
    assert rig.motor.mode is DriveMode.RELEASED


def test_set_detect_4_streams_the_position_every_10_ms_at_scale_1e4() -> None:
    rig = Rig(initial_angle_rad=0.5)
    spy = SpyLink()
    rig.motor.connect(spy)
    end = rig.send(SET_DETECT_4)
    period = round(0.010 * F)
    decoder = Decoder("from-motor", rotor_position_scale=1e4)
    for k in range(1, 11):
        t_k = end + k * period
        angle, _ = rig.plant_at(t_k)
        data, start = spy.sent[-1]
        assert start == t_k and len(spy.sent) == k
        (msg,) = decoder.feed(data)
        assert isinstance(msg, RotorPosition)
        raw = struct.unpack(">i", data[3:7])[0]
        assert abs(raw - math.degrees(angle / 6) * 1e4) <= 1
    rig.t = end + 10 * period + 1
    end_off = rig.send(SetDetect(0).encode())
    rig.world.advance_to(end_off + 5 * period)
    assert rig.motor.stats.stream_frames == 10


def test_garbage_and_unknown_ids_are_counted_and_ignored() -> None:
    rig = Rig()
    rig.send(b"\x00\x55\xaa\x10" + encode_frame(bytes([200, 1, 2])) + GET_VALUES)
    rig.at(0.005)
    (reply,) = rig.replies()
    assert isinstance(reply, Values)
    stats = rig.motor.decoder.stats
    assert stats.dropped_bytes == 4 and stats.unknown_ids == 1 and stats.frames == 2
    assert rig.motor.stats.commands == 0 and rig.motor.stats.requests == 1


def test_fw_version_reply() -> None:
    rig = Rig(Ak60Config(fw_major=5, fw_minor=2, hw_name="X"))
    rig.send(FW_VERSION)
    rig.at(0.002)
    assert rig.replies() == [FwVersion(5, 2, "X", b"pafp-ak60-6\x00")]
