"""The pyserial sim:// URL handler: plain pyserial programs talk to the virtual devices in wall-clock time."""

from __future__ import annotations

import time

import pytest
import serial
from serial.serialutil import PortNotOpenError, SerialException

from hal.serial.backend import SerialUart
from hal.serial.protocol_sim import Serial, register_sim_handler
from hal.serial.sim_port import arrival_end_times, parse_sim_url
from hal.virtual.plant import FixtureKind
from protocol.rvc import RvcDecoder
from protocol.vesc import Decoder, GetValues, SetCurrent, Values


@pytest.fixture(autouse=True)
def _handler() -> None:
    register_sim_handler()


def test_register_is_idempotent() -> None:
    register_sim_handler()
    assert serial.protocol_handler_packages.count("hal.serial") == 1


def test_motor_get_values_round_trip() -> None:
    port = serial.serial_for_url("sim://ak60-6?baud=921600", timeout=0.5)
    assert isinstance(port, Serial) and port.devices is not None
    request = SetCurrent(1.0).encode() + GetValues().encode()
    t0 = time.perf_counter()
    port.write(request)
    raw = port.read(78)
    elapsed = time.perf_counter() - t0
    port.close()
    assert len(raw) == 78
    (values,) = Decoder("from-motor").feed(raw)
    assert isinstance(values, Values) and values.controller_id == 0x7E and values.v_in_v > 20
    # request (16 B) + 50 us latency + reply (78 B) at 921600 baud: the bytes cannot come sooner
    assert elapsed >= (16 + 78) * 10 / 921_600 + 50e-6


def test_imu_frames_arrive_at_about_100_hz() -> None:
    port = serial.serial_for_url("sim://bno08x", timeout=0.3)
    t0 = time.perf_counter()
    data = port.read(1 << 20)  # waits the whole timeout
    elapsed = time.perf_counter() - t0
    port.close()
    decoder = RvcDecoder()
    frames = decoder.feed(data)
    assert 0.3 <= elapsed < 1.0
    assert decoder.stats.banner_bytes == 81 and decoder.stats.lost_frames == 0
    assert abs(len(frames) - 100 * elapsed) <= 3


def test_timeout_semantics() -> None:
    port = serial.serial_for_url("sim://ak60-6", timeout=0)
    t0 = time.perf_counter()
    assert port.read(10) == b""
    assert time.perf_counter() - t0 < 0.02
    port.timeout = 0.05
    t0 = time.perf_counter()
    assert port.read(10) == b""
    assert 0.05 <= time.perf_counter() - t0 < 0.5
    port.timeout = None
    port.write(GetValues().encode())
    assert len(port.read(78)) == 78  # blocks until all 78 bytes are there
    assert port.in_waiting == 0 and port.out_waiting == 0
    port.close()
    with pytest.raises(PortNotOpenError):
        port.read(1)


def test_url_options_and_errors() -> None:
    assert serial.serial_for_url("sim://ak60-6").devices.uarts["motor"].baud == 921_600
    assert serial.serial_for_url("sim://motor", baudrate=460_800).devices.uarts["motor"].baud == 460_800
    assert serial.serial_for_url("sim://bno08x").devices.uarts["imu"].baud == 115_200
    spring = serial.serial_for_url("sim://ak60-6?fixture=spring_bench&seed=4")
    assert spring.devices.world.plant.fixture.kind is FixtureKind.SPRING_BENCH
    for url, words in (("sim://nothing", "unknown"), ("sim://ak60-6?speed=3", "speed"),
                       ("sim://ak60-6?baud=fast", "integer"), ("sim://imu?fixture=moon", "moon")):
        with pytest.raises(SerialException, match=words):
            serial.serial_for_url(url)
    assert parse_sim_url("sim://IMU?seed=9").seed == 9


def test_the_hal_serial_backend_opens_sim_urls() -> None:
    uart = SerialUart("sim://ak60-6", 921_600)
    assert uart.write(GetValues().encode()) == 6
    time.sleep(0.01)
    assert len(uart.read()) == 78
    uart.close()


def test_arrival_end_times_are_back_to_back_and_increasing() -> None:
    ends = arrival_end_times(4, 10_000, 1000.0, 0)
    assert ends == [7000, 8000, 9000, 10_000]
    assert arrival_end_times(3, 10_000, 1000.0, 9500) == [9501, 9502, 10_000]
