"""hal.registry: names -> lazily imported references, errors listing the choices, entry-point groups; and a
second IMU model added from files outside the package, run on the virtual bench and behind sim://."""

from __future__ import annotations

import json
import os
import re
import subprocess
import sys
import textwrap
from pathlib import Path

import pytest

from firmware.control.registry import CONTROLLERS
from firmware.drivers.motor_links import MOTOR_LINKS
from hal.registry import Registry, resolve
from hal.virtual.bench import FIXTURES
from hal.virtual.devices.registry import DEVICES, DeviceModel, device_model
from hal.virtual.wiring import MOTOR_WIRING
from host_tools.benchtests import TESTS
from host_tools.build_info import ROOT
from host_tools.cli import COMMANDS


def _dist(folder: Path, name: str, entry_points: str) -> None:
    """An installed-looking distribution in folder (what pip leaves in site-packages): metadata + entry points."""
    info = folder / f"{name}-0.1.dist-info"
    info.mkdir()
    (info / "METADATA").write_text(f"Metadata-Version: 2.1\nName: {name}\nVersion: 0.1\n")
    (info / "entry_points.txt").write_text(textwrap.dedent(entry_points))


def _run_with_device(folder: Path, module: str, source: str, name: str, script: str) -> dict:
    """script's last line of JSON, run in a fresh Python with module (source, entry point pafp.devices name =
    module:MODEL) in folder as a separate package would install it."""
    (folder / f"{module}.py").write_text(source)
    _dist(folder, module, f"""
        [pafp.devices]
        {name} = {module}:MODEL
    """)
    env = {**os.environ, "PYTHONPATH": os.pathsep.join([str(folder), str(ROOT)])}
    done = subprocess.run([sys.executable, "-c", script], env=env, cwd=folder, capture_output=True, text=True,
                          timeout=600)
    assert done.returncode == 0, done.stderr[-3000:]
    return json.loads(done.stdout.splitlines()[-1])


def test_names_are_listed_without_importing_and_loaded_on_first_use(tmp_path, monkeypatch):
    (tmp_path / "lazy_thing.py").write_text("VALUE = 42\n")
    monkeypatch.syspath_prepend(str(tmp_path))
    things = Registry("thing", {"answer": "lazy_thing:VALUE", "module": "lazy_thing", "inline": 7})
    assert things.names() == ["answer", "module", "inline"] and "answer" in things and len(things) == 3
    assert "lazy_thing" not in sys.modules
    assert things.load("answer") == 42 and things.load("module").VALUE == 42 and things.load("inline") == 7
    assert things.reference("answer") == "lazy_thing:VALUE"
    assert things.spoken() == "answer, module or inline" and things.spoken("and") == "answer, module and inline"


def test_a_bad_name_or_reference_is_one_line_naming_the_value_and_the_choices():
    things = Registry("thing", {"b": "math:pi", "a": "math:e", "gone": "math:no_such_thing",
                                "absent": "no_such_module_of_pafp:x"})
    with pytest.raises(ValueError, match=r"^--thing 'c' unknown: one of \['a', 'absent', 'b', 'gone'\]$"):
        things.load("c", "--thing")
    with pytest.raises(ValueError, match=r"^thing 3 unknown"):
        things.check(3)
    with pytest.raises(ValueError, match=r"^thing 'gone': 'math:no_such_thing' cannot be loaded: AttributeError"):
        things.load("gone")
    with pytest.raises(ValueError, match=r"^thing 'absent': .* cannot be loaded: ModuleNotFoundError"):
        things.load("absent")
    for ref in ("math:", "not a ref", "a:b:c"):
        with pytest.raises(ValueError, match="is not 'module:attribute' or 'module'"):
            Registry("thing", {"x": ref})
    with pytest.raises(ValueError, match="already registered; pass replace=True"):
        things.register("a", "math:tau")
    things.register("a", "math:tau", replace=True)
    assert things.load("a") == resolve("math:tau")
    things.unregister("a")
    with pytest.raises(ValueError, match=r"thing 'a' not registered: one of \['absent', 'b', 'gone'\]"):
        things.unregister("a")


def test_an_entry_point_group_adds_names_and_never_replaces_a_shipped_one(tmp_path, monkeypatch):
    (tmp_path / "plugin_things.py").write_text("EXTRA = 'from a package'\nFAKE = 'impostor'\n")
    _dist(tmp_path, "plugin_things", """
        [pafp.test_things]
        extra = plugin_things:EXTRA
        shipped = plugin_things:FAKE
        [other.group]
        ignored = plugin_things:EXTRA
    """)
    things = Registry("thing", {"shipped": "math:pi"}, group="pafp.test_things")
    assert things.names() == ["shipped"]  # not on sys.path yet
    monkeypatch.syspath_prepend(str(tmp_path))
    things.refresh()
    assert things.names() == ["shipped", "extra"] and things.shadowed == ["shipped"]
    assert things.load("extra") == "from a package" and things.load("shipped") == resolve("math:pi")
    monkeypatch.undo()
    things.refresh()
    assert things.names() == ["shipped"]


def test_every_table_is_a_registry_with_its_group_and_its_entries_load():
    tables = {MOTOR_LINKS: "pafp.motor_links", MOTOR_WIRING: "pafp.motor_wiring", DEVICES: "pafp.devices",
              CONTROLLERS: "pafp.controllers", COMMANDS: "pafp.commands", TESTS: "pafp.benchtests",
              FIXTURES: "pafp.fixtures"}
    for table, group in tables.items():
        assert isinstance(table, Registry) and table.group == group
        for name in table:
            assert table.load(name) is not None, (table, name)
    doc = (ROOT / "docs" / "registries.md").read_text()
    rows = re.findall(r"^\| `(\w+)` \| `([\w/.]+)` \| .* \| `([\w.]+)` \|$", doc, re.MULTILINE)
    assert sorted((name, group) for name, _, group in rows) == sorted(
        (next(k for k, v in globals().items() if v is table), group) for table, group in tables.items())
    assert MOTOR_LINKS.names() == MOTOR_WIRING.names() == ["uart", "can-servo", "can-mit"]
    assert all(isinstance(device_model(n), DeviceModel) for n in DEVICES)
    assert device_model("imu") is device_model("bno08x") and device_model("motor") is device_model("ak60-6")


def test_no_module_of_hal_names_the_firmware():
    """hal/ is below the firmware: not an import, not a "module:attribute" string, not a dotted name."""
    offenders = []
    for path in sorted((ROOT / "hal").rglob("*.py")):
        for k, line in enumerate(path.read_text().splitlines(), 1):
            if re.search(r"\bfirmware\.(?!toml\b)[a-z_]", line) or re.search(r"^\s*(from|import) firmware\b", line):
                offenders.append(f"{path.relative_to(ROOT)}:{k}: {line.strip()}")
    assert offenders == []


def test_a_device_model_checks_its_fields():
    with pytest.raises(ValueError, match=r"role 'foot' unknown on the UART: one of \['motor', 'imu', 'ground'\]"):
        DeviceModel("foot", "uart", 115_200, print)
    with pytest.raises(ValueError, match=r"kind 'spi' unknown: one of \['uart', 'adc'\]"):
        DeviceModel("imu", "spi", 115_200, print)
    with pytest.raises(ValueError, match="baud 0 out of range 1..20000000 on the UART"):
        DeviceModel("imu", "uart", 0, print)
    with pytest.raises(ValueError, match=r"role 'imu' unknown on the ADC: one of \['sensor'\]"):
        DeviceModel("imu", "adc", 0, print)
    with pytest.raises(ValueError, match="baud 9600 out of range 0..0 on the ADC"):
        DeviceModel("sensor", "adc", 9600, print)
    with pytest.raises(ValueError, match=r"imu_model 'ak60-6' is a motor device, not an IMU"):
        from hal.virtual.bench import VirtualBench

        VirtualBench(lambda: 0, 168_000_000, imu_model="ak60-6")
    from hal.serial.sim_port import parse_sim_url

    with pytest.raises(ValueError, match=r"^sim:// device 'load-cell' is a sensor on the adc: sim://ground-sensors"):
        parse_sim_url("sim://load-cell")


_ACME = '''
"""An RVC-speaking IMU that is not the BNO08x: 50 Hz frames and four times its pitch noise (a test's own
device, outside pafp: one file plus one entry point)."""
import dataclasses, math

from hal.virtual.devices.bno08x import Bno08x
from hal.virtual.devices.bno08x_config import Bno08xConfig
from hal.virtual.devices.registry import DeviceModel

NOISE_RAD = math.radians(0.2)


def build(world, link, *, seed=0, config=None):
    base = config if config is not None else Bno08xConfig()
    return Bno08x(world, dataclasses.replace(base, rate_hz=50.0, pitch_noise_rad=NOISE_RAD), seed=seed, link=link)


MODEL = DeviceModel("imu", "uart", 115_200, build, "ACME RVC IMU: 50 Hz, 0.2 deg noise")
'''

_SCRIPT = '''
import json, time
import serial
from hal.serial.protocol_sim import register_sim_handler
from hal.virtual.devices.registry import DEVICES
from host_tools.runner import RunConfig, run_virtual
from protocol.rvc import RvcDecoder

out = {"registered": "acme-imu" in DEVICES.names()}
for model in ("bno08x", "acme-imu"):
    r = run_virtual(RunConfig(strides=1, trace_capacity=0, bench_options={"imu_model": model}))
    out[model] = {"sent": r.bench.imu.frames_sent, "read": r.firmware.imu.frames, "sim_s": r.sim_time_s,
                  "rate_hz": r.bench.imu.config.rate_hz, "noise": r.bench.imu.config.pitch_noise_rad}
register_sim_handler()
port = serial.serial_for_url("sim://acme-imu", timeout=0.4)
t0 = time.perf_counter()
data = port.read(1 << 20)
elapsed = time.perf_counter() - t0
port.close()
decoder = RvcDecoder()
out["sim"] = {"frames": len(decoder.feed(data)), "elapsed": elapsed, "banner": decoder.stats.banner_bytes,
              "lost": decoder.stats.lost_frames}
print(json.dumps(out))
'''


def test_a_second_imu_from_outside_the_package_runs_on_the_bench_and_behind_sim(tmp_path):
    """The acme-imu lives in a folder of its own with an entry point; pafp's files are not touched."""
    out = _run_with_device(tmp_path, "acme_imu", _ACME, "acme-imu", _SCRIPT)
    assert out["registered"]
    bno, acme = out["bno08x"], out["acme-imu"]
    assert bno["rate_hz"] == 100.0 and acme["rate_hz"] == 50.0 and acme["noise"] == pytest.approx(4 * bno["noise"])
    assert bno["sim_s"] == acme["sim_s"]
    for imu, hz in ((bno, 100), (acme, 50)):  # one frame per period from boot, all read by the firmware
        assert abs(imu["sent"] - hz * imu["sim_s"]) <= 3, imu
        assert imu["sent"] - 2 <= imu["read"] <= imu["sent"], imu
    sim = out["sim"]
    assert sim["banner"] == 81 and sim["lost"] == 0
    assert abs(sim["frames"] - 50 * sim["elapsed"]) <= 3, sim


_THERMISTOR = '''
"""A toy NTC thermistor on a spare ADC channel, warming 2 K a second from 25 C (a test's own sensor,
outside pafp: one file plus one entry point). 10 kohm at 25 C, B = 3950 K, on the low side of a divider
with a 10 kohm pull-up to 3.3 V."""
import math

from hal.virtual.devices.registry import DeviceModel

R25, B, T25, R_PULL, SUPPLY = 10_000.0, 3950.0, 298.15, 10_000.0, 3.3


def celsius(t_s):
    return 25.0 + 2.0 * t_s


def volts_at(c):
    r = R25 * math.exp(B * (1.0 / (c + 273.15) - 1.0 / T25))
    return SUPPLY * r / (r + R_PULL)


class Thermistor:
    def __init__(self, f_hz):
        self.f_hz = f_hz

    def volts(self, t):
        return volts_at(celsius(t / self.f_hz))

    def outputs(self):
        return {"thermistor": self.volts}

    def set_fault(self, mode):
        raise ValueError(f"thermistor fault {mode!r} unknown")


def build(ground, f_hz, *, seed=0, config=None):
    return Thermistor(f_hz)


MODEL = DeviceModel("sensor", "adc", 0, build, "toy NTC thermistor, 10 kohm B3950 under a 10 kohm pull-up")
'''

_ADC_SCRIPT = '''
import hashlib, json, time
from hal.serial.backend import SerialUart
from hal.serial.firmata_adc import FirmataAdc
from hal.serial.protocol_sim import register_sim_handler
from hal.virtual.devices.registry import adc_sensor_models
from hal.virtual.ground_sensors import ADC_CHANNELS
from host_tools.runner import RunConfig, run_virtual

out = {"sensors": [name for name, _ in adc_sensor_models()]}
r = run_virtual(RunConfig(strides=1, trace_capacity=0, ground_sensors=True))
adc = r.bench.ground_sensors.adc
out["run"] = {"channels": list(adc.channels), "codes": adc.read(), "t_s": adc.now() / adc.f_cpu_hz,
              "lsb": adc.vref_v / 2 ** adc.bits, "telemetry": hashlib.sha256(r.telemetry).hexdigest()}
register_sim_handler()
uart = SerialUart("sim://ground-sensors", 115_200)
board = FirmataAdc(uart, ADC_CHANNELS + ("thermistor",))
t0 = time.perf_counter()
codes = board.read()
while time.perf_counter() - t0 < 2.0 and board.decoder.stats.analog < 100:
    time.sleep(0.005)
    codes = board.read()
out["sim"] = {"codes": codes, "analog": board.decoder.stats.analog, "dropped": board.decoder.stats.dropped,
              "elapsed": time.perf_counter() - t0}
uart.serial.close()
print(json.dumps(out))
'''


def test_a_toy_adc_sensor_from_outside_the_package_runs_on_the_bench_and_behind_sim(tmp_path):
    """A thermistor in a folder of its own with an entry point reaches a fifth ADC channel, after the shipped
    sensors' four, on the virtual bench and on sim://ground-sensors; pafp's files are not touched."""
    import hashlib
    import importlib.util

    from hal.virtual.ground_sensors import ADC_CHANNELS
    from host_tools.runner import RunConfig, run_virtual

    out = _run_with_device(tmp_path, "toy_thermistor", _THERMISTOR, "toy-thermistor", _ADC_SCRIPT)
    assert out["sensors"] == ["load-cell", "fsr-heel", "fsr-toe", "toy-thermistor"]
    spec = importlib.util.spec_from_file_location("toy_thermistor_here", tmp_path / "toy_thermistor.py")
    toy = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(toy)
    run = out["run"]
    assert run["channels"] == [*ADC_CHANNELS, "thermistor"]
    expected = toy.volts_at(toy.celsius(run["t_s"])) / run["lsb"]  # the last conversion is < 1 ms old: 0.002 K
    assert run["t_s"] > 1.0 and abs(run["codes"][4] - expected) <= 5, (run, expected)
    # the shipped sensors read exactly what they read without the toy, and the firmware sends the same bytes
    alone = run_virtual(RunConfig(strides=1, trace_capacity=0, ground_sensors=True))
    assert list(alone.bench.ground_sensors.adc.channels) == list(ADC_CHANNELS)
    assert alone.bench.ground_sensors.adc.read() == run["codes"][:4]
    assert hashlib.sha256(alone.telemetry).hexdigest() == run["telemetry"]
    sim = out["sim"]
    assert sim["analog"] >= 100 and sim["dropped"] == 0, sim
    lsb = run["lsb"]
    hot, cold = toy.volts_at(toy.celsius(sim["elapsed"] + 0.5)) / lsb, toy.volts_at(25.0) / lsb
    assert hot - 5 <= sim["codes"][4] <= cold + 5, (sim, hot, cold)  # warmed from 25 C since the port opened
    assert abs(sim["codes"][3] * lsb) < 0.02  # and the shipped sensors still stream beside it, unloaded
