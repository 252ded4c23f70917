"""The replaying peripherals: the UARTs, encoder timer, pins, watchdog and CAN port of a `ReplayBoard`.

Each call takes the next recorded result of its kind on its port from the board (`ReplayBoard.take`); what
the firmware writes is kept on the board for the comparison (`ReplayBoard.put`), never sent anywhere. The
module is compiled (setup.py's COMPILED): these are the calls the firmware makes.
"""

from __future__ import annotations

from typing import TYPE_CHECKING, Final

from hal.can import CanFrame, CanPort
from hal.errors import HalError
from hal.interfaces import DigitalIn, DigitalOut, EncoderTimer, Uart, UartErrors, Watchdog
from hal.record.format import Kind
from hal.record.recorder import PORTS

if TYPE_CHECKING:
    from hal.record.replay import ReplayBoard

__all__ = ["ReplayCan", "ReplayEncoder", "ReplayLed", "ReplayPin", "ReplayUart", "ReplayWatchdog"]

_ENC_CNT_KEY: Final = Kind.ENC_CNT << 2
_ENC_DIR_KEY: Final = Kind.ENC_DIR << 2
_ENC_SET_KEY: Final = Kind.ENC_SET << 2
_ESTOP_KEY: Final = Kind.ESTOP << 2
_LED_KEY: Final = Kind.LED << 2
_KICK_KEY: Final = Kind.KICK << 2


class ReplayUart(Uart):
    """A UART that answers from the record and keeps what is written."""

    def __init__(self, replay: ReplayBoard, port: int, baud: int, name: str) -> None:
        """The recorded port's baud and name."""
        super().__init__(baud, name)
        self.replay, self.port = replay, port
        self._write_key, self._read_key = Kind.WRITE << 2 | port, Kind.READ << 2 | port
        self._rx_key, self._tx_key = Kind.IN_WAITING << 2 | port, Kind.TX_FREE << 2 | port
        self._flush_key, self._errors_key = Kind.FLUSH << 2 | port, Kind.ERRORS << 2 | port

    def _send(self, data: bytes) -> int:
        key = self._write_key
        replay = self.replay
        s = replay.section
        i = s.find(key)
        if i >= 0 and isinstance(s.values[i], HalError):  # the recorded write raised
            s.keys[i] = -1
            raise HalError(str(s.values[i]))
        accepted = replay.expected_accept(key, data)
        replay.put(key, (accepted, data))
        return accepted

    def _receive(self, max_bytes: int) -> bytes:
        data: bytes = self.replay.take(self._read_key, b"")
        self.replay.last.pop(self._read_key, None)  # a starved read returns nothing, not the last bytes
        return data

    def _rx_count(self) -> int:
        return int(self.replay.take(self._rx_key, 0))

    def _tx_space(self) -> int:
        return int(self.replay.take(self._tx_key, 1 << 12))

    def _drain(self, timeout_s: float) -> bool:
        return bool(self.replay.take(self._flush_key, True))

    def _refresh_errors(self) -> None:
        e = self.replay.take(self._errors_key, (0, 0, 0, 0, 0))
        self._errors = UartErrors(*e)


class ReplayEncoder(EncoderTimer):
    """The encoder timer: recorded CNT and DIR readings; CNT writes kept."""

    def __init__(self, replay: ReplayBoard, bits: int, arr: int) -> None:
        """The recorded timer's width and auto-reload."""
        super().__init__(bits, arr)
        self.replay = replay

    def cnt(self) -> int:
        """The recorded CNT."""
        return int(self.replay.take(_ENC_CNT_KEY, 0))

    def counting_down(self) -> bool:
        """The recorded DIR bit."""
        return bool(self.replay.take(_ENC_DIR_KEY, False))

    def _write_cnt(self, value: int) -> None:
        self.replay.put(_ENC_SET_KEY, value)


class ReplayPin(DigitalIn):
    """The e-stop input: the recorded levels."""

    def __init__(self, replay: ReplayBoard) -> None:
        """Read from `replay`."""
        self.replay = replay

    def read(self) -> bool:
        """The recorded level."""
        return bool(self.replay.take(_ESTOP_KEY, False))


class ReplayLed(DigitalOut):
    """The status LED: levels kept for the comparison."""

    def __init__(self, replay: ReplayBoard, initial: bool) -> None:
        """Start at the recorded initial level."""
        super().__init__(initial)
        self.replay = replay

    def _drive(self, level: bool) -> None:
        self.replay.put(_LED_KEY, int(level))


class ReplayWatchdog(Watchdog):
    """The watchdog: kicks kept for the comparison."""

    def __init__(self, replay: ReplayBoard) -> None:
        """Kicks go to `replay`."""
        self.replay = replay

    def kick(self) -> None:
        """Keep the kick."""
        self.replay.put(_KICK_KEY, None)


class ReplayCan(CanPort):
    """The CAN port: recorded received frames; sent frames kept."""

    def __init__(self, replay: ReplayBoard, bitrate: int) -> None:
        """The recorded bus's bit rate."""
        super().__init__(bitrate, "can (replay)")
        self.replay = replay
        port = PORTS["can"]
        self._tx_key, self._rx_key = Kind.CAN_TX << 2 | port, Kind.CAN_RX << 2 | port
        self._pending_key, self._flush_key = Kind.CAN_PENDING << 2 | port, Kind.CAN_FLUSH << 2 | port

    def _send(self, frame: CanFrame) -> bool:
        key = self._tx_key
        recorded = self.replay.section.outputs.get(key, [])
        done = self.replay.produced.get(key)
        i = 0 if done is None else len(done)
        ok = bool(recorded[i][0]) if i < len(recorded) else True
        self.replay.put(key, (int(ok), frame))
        return ok

    def _receive(self) -> CanFrame | None:
        frame: CanFrame | None = self.replay.take(self._rx_key, None)
        self.replay.last.pop(self._rx_key, None)
        return frame

    def _tx_pending(self) -> int:
        return int(self.replay.take(self._pending_key, 0))

    def _drain(self, timeout_s: float) -> bool:
        return bool(self.replay.take(self._flush_key, True))
