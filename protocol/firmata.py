"""Firmata (the MIDI-framed protocol of StandardFirmata boards): the messages an analog acquisition board uses.

Wire format (Firmata protocol 2.x, github.com/firmata/protocol, protocol.md):

* analog I/O message, board -> host: ``0xE0 | pin`` (pins 0..15), value bits 0-6, value bits 7-13;
* report analog pin, host -> board: ``0xC0 | pin``, 1 (enable) or 0 (disable);
* protocol version: ``0xF9``, major, minor (the board sends it at start-up and on request);
* sysex: ``0xF0``, command, 7-bit data..., ``0xF7``; SAMPLING_INTERVAL is command ``0x7A`` with the
  interval in ms as two 7-bit bytes (LSB first); REPORT_FIRMWARE is ``0x79``.

Data bytes have bit 7 clear; a byte with bit 7 set starts a message. The decoder never raises: it
counts what it drops (a data byte outside a message, a message cut short by a new command byte, an
unknown command) and resynchronises on the next command byte. Stdlib only.

>>> analog_message(2, 1234).hex()
'e25209'
>>> d = FirmataDecoder(); d.feed(b"\\x00" + analog_message(2, 1234)); (d.analog, d.stats.dropped)
({2: 1234}, 1)
"""

from __future__ import annotations

from dataclasses import dataclass, field

__all__ = ["ANALOG", "FirmataDecoder", "FirmataStats", "REPORT_ANALOG", "SAMPLING_INTERVAL", "SYSEX_END",
           "SYSEX_START", "VERSION", "analog_message", "report_analog", "sampling_interval", "version_message"]

ANALOG = 0xE0
REPORT_ANALOG = 0xC0
VERSION = 0xF9
SYSEX_START = 0xF0
SYSEX_END = 0xF7
SAMPLING_INTERVAL = 0x7A
MAX_VALUE = (1 << 14) - 1
_MAX_SYSEX = 64  # longer sysex bodies are dropped (none of the messages used here comes near)


def _check(name: str, value: int, hi: int) -> None:
    if isinstance(value, bool) or not isinstance(value, int) or not 0 <= value <= hi:
        raise ValueError(f"{name} {value!r} out of range: an int in 0..{hi}")


def analog_message(pin: int, value: int) -> bytes:
    """The board's report of an analog pin (0..15) with a value of up to 14 bits."""
    _check("analog pin", pin, 15)
    _check("analog value", value, MAX_VALUE)
    return bytes((ANALOG | pin, value & 0x7F, value >> 7))


def report_analog(pin: int, enable: bool = True) -> bytes:
    """Ask the board to start (or stop) reporting an analog pin."""
    _check("analog pin", pin, 15)
    return bytes((REPORT_ANALOG | pin, 1 if enable else 0))


def sampling_interval(ms: int) -> bytes:
    """Set the board's analog sampling interval in ms (StandardFirmata allows 1..16383)."""
    _check("sampling interval ms", ms, MAX_VALUE)
    return bytes((SYSEX_START, SAMPLING_INTERVAL, ms & 0x7F, ms >> 7, SYSEX_END))


def version_message(major: int = 2, minor: int = 5) -> bytes:
    """The protocol version report."""
    _check("major", major, 127)
    _check("minor", minor, 127)
    return bytes((VERSION, major, minor))


@dataclass
class FirmataStats:
    """What the decoder has seen: messages by kind, bytes dropped."""

    bytes_in: int = 0
    analog: int = 0
    report_analog: int = 0
    sysex: int = 0
    version: int = 0
    dropped: int = 0
    unknown: dict[int, int] = field(default_factory=dict)


class FirmataDecoder:
    """Decodes a byte stream from either side; keeps the latest analog values and the host's requests.

    ``analog``: pin -> last value (board side); ``reporting``: pin -> enabled (host requests);
    ``interval_ms``: the last sampling interval asked for; ``version``: the last version reported.
    """

    def __init__(self) -> None:
        """Empty: no message seen."""
        self.stats = FirmataStats()
        self.analog: dict[int, int] = {}
        self.reporting: dict[int, bool] = {}
        self.interval_ms: int | None = None
        self.version: tuple[int, int] | None = None
        self._cmd = -1
        self._data: list[int] = []

    def _need(self, cmd: int) -> int:
        kind = cmd & 0xF0
        if kind in (ANALOG, 0x90) or cmd == VERSION:  # 0x90: digital message (2 bytes), decoded and ignored
            return 2
        if kind in (REPORT_ANALOG, 0xD0) or cmd == 0xF4:  # report digital, set pin mode take 1 and 2
            return 1 if cmd != 0xF4 else 2
        return -1

    def feed(self, data: bytes) -> None:
        """Take bytes; complete messages update the state."""
        stats = self.stats
        stats.bytes_in += len(data)
        for b in data:
            if b & 0x80:
                if b == SYSEX_END and self._cmd == SYSEX_START:
                    self._sysex(self._data)
                    self._cmd, self._data = -1, []
                    continue
                if self._cmd != -1:
                    stats.dropped += 1 + len(self._data)  # a message cut short
                if b == SYSEX_START or self._need(b) > 0:
                    self._cmd, self._data = b, []
                else:
                    stats.unknown[b] = stats.unknown.get(b, 0) + 1
                    stats.dropped += 1
                    self._cmd, self._data = -1, []
                continue
            if self._cmd == -1:
                stats.dropped += 1
                continue
            self._data.append(b)
            if self._cmd == SYSEX_START:
                if len(self._data) > _MAX_SYSEX:
                    stats.dropped += 1 + len(self._data)
                    self._cmd, self._data = -1, []
                continue
            if len(self._data) == self._need(self._cmd):
                self._message(self._cmd, self._data)
                self._cmd, self._data = -1, []

    def _message(self, cmd: int, data: list[int]) -> None:
        kind = cmd & 0xF0
        if kind == ANALOG:
            self.analog[cmd & 0x0F] = data[0] | data[1] << 7
            self.stats.analog += 1
        elif kind == REPORT_ANALOG:
            self.reporting[cmd & 0x0F] = data[0] != 0
            self.stats.report_analog += 1
        elif cmd == VERSION:
            self.version = (data[0], data[1])
            self.stats.version += 1

    def _sysex(self, data: list[int]) -> None:
        self.stats.sysex += 1
        if len(data) == 3 and data[0] == SAMPLING_INTERVAL:
            self.interval_ms = data[1] | data[2] << 7
