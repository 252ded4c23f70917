"""The shared logic of the HAL base classes, exercised through a minimal backend and the null peripherals."""

from __future__ import annotations

import pytest

from hal.errors import HalError, PortLostError
from hal.interfaces import Board, EncoderTimer, Uart, UartErrors
from hal.virtual.gpio import VirtualWatchdog
from hal.virtual.null import NullDigitalIn, NullDigitalOut, NullEncoderTimer, NullUart


class HalfUart(Uart):
    """Accepts half of every write; receives a fixed script."""

    def __init__(self, accept_override: int | None = None) -> None:
        super().__init__(9600, "half")
        self.sent = b""
        self.inbox = bytearray(b"hello")
        self.override = accept_override
        self.closed_hook = 0

    def _send(self, data: bytes) -> int:
        n = len(data) // 2 if self.override is None else self.override
        self.sent += data[:n]
        return n

    def _receive(self, max_bytes: int) -> bytes:
        n = len(self.inbox) if max_bytes < 0 else max_bytes
        out = bytes(self.inbox[:n])
        del self.inbox[:n]
        return out

    def _rx_count(self) -> int:
        return len(self.inbox)

    def _tx_space(self) -> int:
        return 7

    def _close(self) -> None:
        self.closed_hook += 1


def test_base_counts_refused_bytes_and_accepts_bytes_like() -> None:
    u = HalfUart()
    assert u.write(bytearray(b"abcd")) == 2
    assert u.write(memoryview(b"xyz")) == 1
    assert u.write(b"") == 0
    assert u.sent == b"abx"
    assert u.errors == UartErrors(tx_dropped=4)
    assert u.tx_free() == 7
    assert u.in_waiting() == 5
    assert u.read(2) == b"he" and u.read() == b"llo"


def test_errors_is_a_snapshot() -> None:
    u = HalfUart()
    snap = u.errors
    snap.overrun = 99
    assert u.errors.overrun == 0
    assert UartErrors(1, 2, 3, 4, 5).total() == 15


def test_backend_misreporting_is_a_hal_error() -> None:
    with pytest.raises(HalError, match="accepted 9 of 2"):
        HalfUart(accept_override=9).write(b"ab")


def test_close_is_idempotent_and_with_block_closes() -> None:
    with HalfUart() as u:
        assert not u.closed
    assert u.closed and u.closed_hook == 1
    u.close()
    assert u.closed_hook == 1
    with pytest.raises(HalError, match="half: UART is closed"):
        u.read()


@pytest.mark.parametrize("baud", [0, -5, 1.5, True, 30_000_000])
def test_bad_baud_is_named(baud: object) -> None:
    with pytest.raises(ValueError, match=f"baud {baud!r}"):
        NullUart(baud)  # type: ignore[arg-type]


def test_port_lost_error_names_the_port() -> None:
    err = PortLostError("/dev/ttyUSB3", "unplugged")
    assert isinstance(err, HalError)
    assert "/dev/ttyUSB3" in str(err) and err.port == "/dev/ttyUSB3" and err.reason == "unplugged"


def test_encoder_base_validation_and_null_encoder() -> None:
    enc = NullEncoderTimer(bits=32)
    assert (enc.bits, enc.arr, enc.cnt(), enc.counting_down()) == (32, 2**32 - 1, 0, False)
    enc.set_cnt(123)
    assert enc.cnt() == 123
    with pytest.raises(ValueError, match="CNT value -1"):
        enc.set_cnt(-1)
    assert isinstance(enc, EncoderTimer)


def test_null_pins_and_board_validation() -> None:
    led = NullDigitalOut()
    led.write(True)
    assert led.level is True
    assert NullDigitalIn(True).read() is True
    parts = (NullUart(9600), NullUart(9600), NullUart(9600), NullEncoderTimer(), NullDigitalIn(), led)
    dog = VirtualWatchdog(lambda: None)
    with pytest.raises(ValueError, match="f_cpu_hz 0"):
        Board(*parts, dog, lambda: 0, 0)
    board = Board(*parts, dog, lambda: 72_000_123, 72_000_000)
    assert board.ticks_ms() == 1000
