"""Board binding: strings map to the right backend, bad strings are named, the registry, bind_board."""

from __future__ import annotations

import os
from collections.abc import Iterator
from typing import Any

import pytest

from hal import binding
from hal.binding import (
    ALLOWED_FORMS,
    PYSERIAL,
    VIRTUAL_BENCH,
    PeripheralSpec,
    bind_board,
    open_peripheral,
    open_uart,
    parse_spec,
    register_backend,
    unregister_backend,
)
from hal.interfaces import Board, Uart
from hal.serial.backend import SerialUart
from hal.virtual.gpio import VirtualDigitalIn, VirtualDigitalOut, VirtualWatchdog
from hal.virtual.mcu import VirtualMcu
from hal.virtual.null import NullDigitalIn, NullEncoderTimer, NullUart
from hal.virtual.timer import VirtualEncoderTimer
from hal.virtual.uart import VirtualUart


class Bench:
    """A minimal virtual bench: the sim:// context, recording what was asked of it."""

    def __init__(self) -> None:
        self.mcu = VirtualMcu(lambda: 0, 168_000_000)
        self.asked: list[tuple[Any, ...]] = []

    def virtual_uart(self, role: str, model: str, baud: int) -> VirtualUart:
        self.asked.append(("uart", role, model, baud))
        return self.mcu.uart(role, baud)

    def virtual_encoder(self, role: str, model: str) -> VirtualEncoderTimer:
        self.asked.append(("encoder", role, model))
        return self.mcu.encoder_timer(lambda t: 0.0)

    def virtual_digital_in(self, role: str, model: str) -> VirtualDigitalIn:
        self.asked.append(("in", role, model))
        return self.mcu.digital_in(role)

    def virtual_digital_out(self, role: str, model: str) -> VirtualDigitalOut:
        self.asked.append(("out", role, model))
        return self.mcu.digital_out(role)


BAUDS = {"motor": 921_600, "imu": 115_200, "telemetry": 921_600}


@pytest.fixture
def restore_registry() -> Iterator[None]:
    saved = dict(binding._BACKENDS)
    yield
    binding._BACKENDS.clear()
    binding._BACKENDS.update(saved)


@pytest.mark.parametrize(
    ("role", "url", "scheme", "target"),
    [
        ("motor", "sim://ak60-6", "sim", "ak60-6"),
        ("telemetry", "sim://", "sim", ""),
        ("encoder", "SIM://", "sim", ""),
        ("led", "null://", "null", ""),
        ("imu", "/dev/ttyUSB1", PYSERIAL, "/dev/ttyUSB1"),
        ("imu", "COM3", PYSERIAL, "COM3"),
        ("motor", "loop://", PYSERIAL, "loop://"),
        ("motor", "socket://127.0.0.1:7777", PYSERIAL, "socket://127.0.0.1:7777"),
        ("telemetry", "spy:///dev/ttyUSB0?file=x.txt", PYSERIAL, "spy:///dev/ttyUSB0?file=x.txt"),
        ("motor", "rfc2217://host:2217", PYSERIAL, "rfc2217://host:2217"),
    ],
)
def test_strings_map_to_backends(role: str, url: str, scheme: str, target: str) -> None:
    spec = parse_spec(role, url)
    assert spec == PeripheralSpec(role, binding.ROLE_KINDS[role], url, scheme, target)


@pytest.mark.parametrize(
    ("role", "url", "needle"),
    [
        ("motor", "", "''"),
        ("motor", "ak60-6", "'ak60-6' is neither"),
        ("motor", "bogus://x", "scheme 'bogus' unknown"),
        ("motor", " /dev/ttyUSB0", "' /dev/ttyUSB0' invalid"),
        ("motor", "/dev/tty USB0", "neither"),
        ("motor", "pyserial://x", "scheme 'pyserial' unknown"),
        ("encoder", "/dev/ttyUSB2", "cannot serve peripheral kind 'encoder'"),
        ("estop", "loop://", "cannot serve peripheral kind 'digital_in'"),
        ("elbow", "sim://", "role 'elbow' unknown"),
    ],
)
def test_bad_strings_are_named_with_the_allowed_forms(role: str, url: str, needle: str) -> None:
    with pytest.raises(ValueError, match=needle.replace("(", r"\(")) as info:
        parse_spec(role, url)
    if role != "elbow":
        assert url in str(info.value) or not url
        assert "sim://" in str(info.value)


def test_sim_goes_through_the_context() -> None:
    bench = Bench()
    uart = open_uart("sim://ak60-6", 921_600, role="motor", context=bench)
    assert isinstance(uart, VirtualUart) and uart.baud == 921_600
    assert bench.asked == [("uart", "motor", "ak60-6", 921_600)]
    with pytest.raises(ValueError, match="needs a context"):
        open_uart("sim://", 115_200, role="imu")


def test_null_and_pyserial_backends_open_the_right_types() -> None:
    assert isinstance(open_uart("null://", 9_600), NullUart)
    assert isinstance(open_peripheral("encoder", "null://"), NullEncoderTimer)
    assert isinstance(open_peripheral("estop", "null://"), NullDigitalIn)
    with pytest.raises(ValueError, match="no target"):
        open_peripheral("led", "null://x")
    with open_uart("loop://", 115_200, role="telemetry") as uart:
        assert isinstance(uart, SerialUart)
        uart.write(b"ok")
        assert uart.read() == b"ok"
    with pytest.raises(ValueError, match="needs a baud"):
        open_peripheral("motor", "loop://")
    with pytest.raises(ValueError, match="not a UART role"):
        open_uart("null://", 9_600, role="led")


def test_pty_path_binds_to_the_serial_backend() -> None:
    master, slave = os.openpty()
    try:
        uart = open_uart(os.ttyname(slave), 115_200, role="imu")
        assert isinstance(uart, SerialUart) and uart.url == os.ttyname(slave)
        uart.close()
    finally:
        os.close(master)
        os.close(slave)


def test_registry_add_replace_remove(restore_registry: None) -> None:
    made: list[PeripheralSpec] = []

    def factory(spec: PeripheralSpec, baud: int | None, context: Any) -> Uart:
        made.append(spec)
        return NullUart(baud or 1)

    register_backend("hil", factory, kinds=["uart"])
    assert "hil" in binding.backends()
    uart = open_uart("hil://bench-3", 230_400, role="imu")
    assert isinstance(uart, NullUart) and made[0].target == "bench-3"
    with pytest.raises(ValueError, match="cannot serve peripheral kind 'encoder'"):
        parse_spec("encoder", "hil://x")
    with pytest.raises(ValueError, match="already registered"):
        register_backend("hil", factory)
    register_backend("hil", lambda spec, baud, ctx: object(), replace=True)
    with pytest.raises(TypeError, match="returned object, not a Uart"):
        open_uart("hil://", 9_600)
    unregister_backend("hil")
    with pytest.raises(ValueError, match="'hil' unknown"):
        parse_spec("motor", "hil://x")
    for bad in ("Bad", "no space", ""):
        with pytest.raises(ValueError, match="invalid"):
            register_backend(bad, factory)
    with pytest.raises(ValueError, match="kinds"):
        register_backend("ok", factory, kinds=["uart", "adc"])
    with pytest.raises(ValueError, match="not registered"):
        unregister_backend("hil")


def test_bind_board_on_the_virtual_bench() -> None:
    bench = Bench()
    board = bind_board(
        VIRTUAL_BENCH,
        bauds=BAUDS,
        watchdog=VirtualWatchdog(lambda: None),
        now_cycles=bench.mcu.now,
        f_cpu_hz=168_000_000,
        context=bench,
    )
    assert isinstance(board, Board)
    assert board.imu_uart.baud == 115_200
    assert [a[:3] for a in bench.asked] == [
        ("uart", "motor", "ak60-6"),
        ("uart", "imu", "bno08x"),
        ("uart", "telemetry", ""),
        ("encoder", "encoder", ""),
        ("in", "estop", ""),
        ("out", "led", ""),
    ]


def test_bind_board_mixed_and_its_errors() -> None:
    mixed = {**VIRTUAL_BENCH, "motor": "loop://", "telemetry": "null://"}
    dog = VirtualWatchdog(lambda: None)
    board = bind_board(
        mixed, bauds=BAUDS, watchdog=dog, now_cycles=lambda: 0, f_cpu_hz=72_000_000, context=Bench()
    )
    assert isinstance(board.motor_uart, SerialUart) and isinstance(board.telemetry_uart, NullUart)
    board.motor_uart.close()
    with pytest.raises(ValueError, match=r"missing \['led'\]"):
        bind_board(
            {k: v for k, v in VIRTUAL_BENCH.items() if k != "led"},
            bauds=BAUDS, watchdog=dog, now_cycles=lambda: 0, f_cpu_hz=1,
        )
    with pytest.raises(ValueError, match=r"bauds lacks \['imu'\]"):
        bind_board(
            VIRTUAL_BENCH, bauds={"motor": 1, "telemetry": 1}, watchdog=dog, now_cycles=lambda: 0, f_cpu_hz=1
        )
    # a failure part-way closes the ports already opened
    bad = {**VIRTUAL_BENCH, "motor": "loop://", "imu": "/dev/ttyPAFP_NOPE"}
    opened: list[Uart] = []
    real_open = binding._BACKENDS[PYSERIAL]

    def spy_factory(spec: PeripheralSpec, baud: int | None, context: Any) -> object:
        uart = real_open[0](spec, baud, context)
        opened.append(uart)  # type: ignore[arg-type]
        return uart

    binding._BACKENDS[PYSERIAL] = (spy_factory, real_open[1])
    try:
        with pytest.raises(Exception, match="ttyPAFP_NOPE"):
            bind_board(bad, bauds=BAUDS, watchdog=dog, now_cycles=lambda: 0, f_cpu_hz=1, context=Bench())
    finally:
        binding._BACKENDS[PYSERIAL] = real_open
    assert len(opened) == 1 and opened[0].closed
    assert "pyserial URL" in ALLOWED_FORMS
