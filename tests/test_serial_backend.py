"""pyserial backend: loop://, a real pty pair, socket:// on loopback, spy://, vanished ports, refusals."""

from __future__ import annotations

import os
import socket
import time
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import Any

import pytest
import serial

from hal.errors import HalError, PortLostError
from hal.interfaces import Uart
from hal.serial.backend import SerialUart, url_scheme
from hal.serial.icount import IcountSnapshot, read_icount

DEADLINE_S = 2.0


def read_until(uart: Uart, n: int) -> bytes:
    """Poll the non-blocking read until n bytes came (ptys deliver asynchronously) or the deadline."""
    got = b""
    end = time.monotonic() + DEADLINE_S
    while len(got) < n and time.monotonic() < end:
        got += uart.read()
        if len(got) < n:
            time.sleep(0.001)
    return got


def read_fd(fd: int, n: int) -> bytes:
    os.set_blocking(fd, False)
    got = b""
    end = time.monotonic() + DEADLINE_S
    while len(got) < n and time.monotonic() < end:
        try:
            got += os.read(fd, n - len(got))
        except BlockingIOError:
            time.sleep(0.001)
    return got


@pytest.fixture
def pty_pair() -> Iterator[tuple[int, str]]:
    master, slave = os.openpty()
    path = os.ttyname(slave)
    os.close(slave)
    yield master, path
    try:
        os.close(master)
    except OSError:
        pass


def test_loop_url_echoes_and_refuses_beyond_the_tx_queue() -> None:
    with SerialUart("loop://", 115_200, tx_queue_size=16) as uart:
        assert uart.write(b"ping") == 4
        assert uart.in_waiting() == 4
        assert uart.read() == b"ping"
        assert uart.write(bytes(range(20))) == 16
        assert uart.errors.tx_dropped == 4
        assert uart.tx_free() == 0
        assert uart.read(10) == bytes(range(10))
        assert uart.tx_free() == 10
        assert uart.read() == bytes(range(10, 16))


def test_pty_pair_both_directions(pty_pair: tuple[int, str]) -> None:
    master, path = pty_pair
    with SerialUart(path, 921_600) as uart:
        assert uart.baud == 921_600 and uart.name == path
        assert uart.read() == b""
        payload = bytes(range(256)) * 4
        os.write(master, payload)
        assert read_until(uart, len(payload)) == payload
        assert uart.write(b"\x02\x01\x04\x40\x84\x03") == 6
        assert read_fd(master, 6) == b"\x02\x01\x04\x40\x84\x03"
        assert uart.errors.total() == 0


def test_vanished_pty_raises_port_lost_every_time(pty_pair: tuple[int, str]) -> None:
    master, path = pty_pair
    uart = SerialUart(path, 115_200)
    os.close(master)
    for call in (uart.read, uart.in_waiting, lambda: uart.write(b"x"), uart.tx_free):
        with pytest.raises(PortLostError, match=path) as info:
            call()
        assert isinstance(info.value, HalError)
    assert uart.lost
    uart.close()
    with pytest.raises(HalError, match="closed"):
        uart.read()


def test_spy_url_wraps_a_pty_and_logs_the_traffic(pty_pair: tuple[int, str], tmp_path: Path) -> None:
    master, path = pty_pair
    log_file = tmp_path / "spy.txt"
    with SerialUart(f"spy://{path}?file={log_file}", 115_200) as uart:
        os.write(master, b"hi")
        assert read_until(uart, 2) == b"hi"
        assert uart.write(b"yo") == 2
        assert read_fd(master, 2) == b"yo"
    text = log_file.read_text()
    assert "RX" in text and "TX" in text


def test_socket_url_on_loopback_and_disconnect() -> None:
    with socket.create_server(("127.0.0.1", 0)) as server:
        port = server.getsockname()[1]
        uart = SerialUart(f"socket://127.0.0.1:{port}", 921_600)
        conn, _ = server.accept()
        with conn:
            assert uart.write(b"abc") == 3
            conn.settimeout(DEADLINE_S)
            assert conn.recv(3) == b"abc"
            conn.sendall(b"x" * 5000)
            assert read_until(uart, 5000) == b"x" * 5000
        with pytest.raises(PortLostError, match="disconnected"):
            end = time.monotonic() + DEADLINE_S
            while time.monotonic() < end:
                uart.read()
        uart.close()


def test_missing_device_and_unknown_protocol() -> None:
    with pytest.raises(PortLostError, match="/dev/ttyPAFP_NOPE"):
        SerialUart("/dev/ttyPAFP_NOPE", 115_200)
    with pytest.raises(ValueError, match="nosuchproto"):
        SerialUart("nosuchproto://x", 115_200)
    with pytest.raises(ValueError, match="tx_queue_size 0"):
        SerialUart("loop://", 115_200, tx_queue_size=0)
    assert url_scheme("LOOP://") == "loop" and url_scheme("COM3") == ""


class FakePort:
    """A pyserial-like port whose behaviour each test scripts."""

    def __init__(self, write: Callable[[bytes], Any], out_waiting: int = 0) -> None:
        self._write = write
        self.out_waiting = out_waiting
        self.in_waiting = 0
        self.closed = False

    def write(self, data: bytes) -> Any:
        return self._write(data)

    def read(self, size: int) -> bytes:
        return b""

    def close(self) -> None:
        self.closed = True
        raise serial.SerialException("close failed")


def fake(write: Callable[[bytes], Any], **kw: Any) -> tuple[SerialUart, list[dict[str, Any]]]:
    seen: list[dict[str, Any]] = []

    def factory(url: str, **options: Any) -> FakePort:
        seen.append({"url": url, **options})
        return FakePort(write, **kw)

    return SerialUart("/dev/ttyFAKE", 57_600, port_factory=factory, tx_queue_size=100), seen


def test_opened_non_blocking_and_partial_writes_are_counted() -> None:
    uart, seen = fake(lambda data: len(data) - 3, out_waiting=90)
    assert seen[0] == {"url": "/dev/ttyFAKE", "baudrate": 57_600, "timeout": 0, "write_timeout": 0}
    assert uart.tx_free() == 10
    assert uart.write(bytes(25)) == 7  # 10 fit the queue, the OS took 3 fewer
    assert uart.errors.tx_dropped == 18
    uart.close()  # a failing close is logged, not raised


def test_write_timeout_is_a_refusal_not_a_crash() -> None:
    def timeout(data: bytes) -> int:
        raise serial.SerialTimeoutException("Write timeout")

    uart, _ = fake(timeout)
    assert uart.write(b"abc") == 0
    assert uart.errors.tx_dropped == 3
    assert not uart.lost


def test_os_error_in_write_becomes_port_lost() -> None:
    def unplugged(data: bytes) -> int:
        raise OSError(5, "Input/output error")

    uart, _ = fake(unplugged)
    with pytest.raises(PortLostError, match="Input/output error"):
        uart.write(b"abc")
    with pytest.raises(PortLostError, match="ttyFAKE"):
        uart.in_waiting()


def test_icount_is_none_where_unsupported(tmp_path: Path, pty_pair: tuple[int, str]) -> None:
    with open(tmp_path / "f", "wb") as f:
        assert read_icount(f.fileno()) is None
    assert read_icount(pty_pair[0]) is None
    uart, _ = fake(len)
    uart._apply_icount(IcountSnapshot(1, 2, 0, 0, 3), IcountSnapshot(4, 6, 0, 0, 4))
    assert (uart.errors.framing, uart.errors.overrun, uart.errors.rx_lost) == (3, 5, 5)
