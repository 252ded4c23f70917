"""The Firmata codec, the acquisition board model behind sim://ground-sensors and the serial-mode ADC backend."""

from __future__ import annotations

import time

import pytest
from hypothesis import given
from hypothesis import strategies as st

from hal.serial.firmata_adc import FirmataAdc
from hal.serial.sim_port import WallDevices, parse_sim_url
from hal.virtual.ground_sensors import ADC_CHANNELS
from protocol.firmata import FirmataDecoder, analog_message, report_analog, sampling_interval, version_message


def test_messages_have_the_protocols_bytes():
    assert analog_message(0, 4095) == bytes((0xE0, 0x7F, 0x1F))
    assert report_analog(3) == bytes((0xC3, 1)) and report_analog(3, False) == bytes((0xC3, 0))
    assert sampling_interval(2) == bytes((0xF0, 0x7A, 2, 0, 0xF7))
    assert version_message() == bytes((0xF9, 2, 5))
    with pytest.raises(ValueError, match="analog pin 16 out of range"):
        analog_message(16, 0)


def test_decoder_keeps_requests_and_values_and_counts_junk():
    d = FirmataDecoder()
    d.feed(sampling_interval(7) + report_analog(1) + version_message(2, 6) + b"\x05\x06" + analog_message(1, 300)
           + bytes((0xE2, 0x10)) + analog_message(2, 5) + bytes((0xA5,)))
    assert d.interval_ms == 7 and d.reporting == {1: True} and d.version == (2, 6)
    assert d.analog == {1: 300, 2: 5}  # the message cut short by the next command byte is dropped
    assert d.stats.dropped == 2 + 2 + 1 and d.stats.unknown == {0xA5: 1}


@given(st.lists(st.tuples(st.integers(0, 15), st.integers(0, 16383)), max_size=20), st.binary(max_size=40))
def test_decoder_never_raises_and_resynchronises_on_the_next_command_byte(messages, junk):
    d = FirmataDecoder()
    d.feed(junk)
    analog_before = dict(d.analog)
    d.feed(b"".join(analog_message(p, v) for p, v in messages))
    assert d.analog == {**analog_before, **dict(messages)}  # every message after the junk decoded, last wins


def test_sim_ground_sensors_stream_the_unloaded_sensors_to_the_firmata_backend():
    url = parse_sim_url("sim://ground-sensors")
    assert url.role == "ground"
    devices = WallDevices(["ground"])
    try:
        adc = FirmataAdc(devices.uarts["ground"], ADC_CHANNELS)
        deadline = time.monotonic() + 2.0
        while time.monotonic() < deadline and adc.decoder.stats.analog < 40:
            time.sleep(0.005)
            codes = adc.read()
        assert adc.decoder.version == (2, 5) and adc.decoder.interval_ms is None  # the host side saw no request echo
        assert devices.ground.decoder.interval_ms == 2 and devices.ground.enabled() == [0, 1, 2, 3]
        assert adc.decoder.stats.analog >= 40 and adc.decoder.stats.dropped == 0
        volts = dict(zip(ADC_CHANNELS, (adc.volts(c) for c in codes), strict=True))
        assert volts["fsr_heel"] < 0.02 and volts["fsr_toe"] < 0.02  # no ground on sim://: unloaded
        assert abs(volts["load_force"] - 0.3) < 0.05 and abs(volts["load_moment"] - 1.65) < 0.05
    finally:
        devices.close()


def test_serial_mode_reads_the_ground_sensors_from_the_firmata_board(tmp_path):
    from host_tools.serial_mode.realtime import RealtimeSettings
    from host_tools.serial_mode.serial_run import SerialRunConfig, run_serial

    cfg = SerialRunConfig(motor="sim://ak60-6", imu="sim://bno08x", ground="sim://ground-sensors", encoder="sim",
                          duration_s=1.0, realtime=RealtimeSettings.none())
    r = run_serial(cfg, tmp_path)
    ev = r.firmware.ground_events
    assert ev is not None and ev.driver.tared and ev.healthy  # the unloaded sensors, read over Firmata
    assert ev.driver.adc.decoder.stats.analog > 100 and ev.heel_strike_s == []
    assert abs(ev.driver.force_n) < 10.0
    assert ev.driver.moment_v == pytest.approx(1.65, abs=0.05)  # the moment channel at its REF


def test_emulate_serves_the_ground_sensors_on_a_pty():
    import signal
    import subprocess
    import sys
    from pathlib import Path

    import serial

    from protocol.firmata import FirmataDecoder

    proc = subprocess.Popen([sys.executable, "-m", "host_tools", "emulate", "ground", "--pty"],
                            cwd=Path(__file__).resolve().parents[1], stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                            text=True)
    try:
        role, path = proc.stdout.readline().strip().split(": ", 1)  # type: ignore[union-attr]
        assert role == "ground"
        port = serial.Serial(path, 115_200, timeout=0.5)
        port.write(sampling_interval(2) + report_analog(0) + report_analog(2))
        time.sleep(0.3)
        d = FirmataDecoder()
        d.feed(port.read(port.in_waiting or 1))
        assert set(d.analog) == {0, 2} and d.stats.analog >= 20  # only the pins asked for
        port.close()
    finally:
        proc.send_signal(signal.SIGTERM)
        out, err = proc.communicate(timeout=10)
    assert proc.returncode == 0, err
    assert "ground: frames_in=3 frames_out=" in out.strip().splitlines()[-1]
