"""Telemetry logger: one framed record per call on the telemetry UART, never blocking the loop.

If the transmit queue cannot take a whole record, the record is dropped and counted; its sequence
number is still consumed, so the host sees the loss as a sequence gap.
"""

from __future__ import annotations

from hal.errors import HalError
from hal.interfaces import Uart
from protocol.telemetry import RECORD_FRAMER, record_framer
from protocol.telemetry_frame import RecordFramer

__all__ = ["TelemetryLogger"]


class TelemetryLogger:
    """Writes `TelemetryRecord`s to `uart`; counts records sent and dropped."""

    def __init__(self, uart: Uart) -> None:
        """Bind the telemetry UART; the first record gets sequence number 0."""
        self.uart = uart
        self._framer: RecordFramer = RECORD_FRAMER
        self.seq = 0
        self.sent = 0
        self.dropped = 0

    def extra_fields(self, count: int) -> None:
        """Records carry `count` float32 fields after the base ones from now on (a controller's published values)."""
        self._framer = record_framer(count)

    def log_values(self, time_cycles: int, *values: float | int) -> int:
        """Frame and queue one record, every field after time_cycles given positionally in RECORD_FIELDS order.

        Return bytes written (0 if dropped for lack of room).
        """
        return self._queue(self._framer.frame(self.seq & 0xFFFFFFFF, time_cycles, values))  # encode_record_values

    def _queue(self, frame: bytes) -> int:
        """Queue one encoded record (its sequence number is consumed even if dropped); return bytes written."""
        self.seq += 1
        try:
            if self.uart.tx_free() < len(frame):
                self.dropped += 1
                return 0
            self.uart.write(frame)
        except HalError:  # the telemetry port failed: the record is dropped, control goes on
            self.dropped += 1
            return 0
        self.sent += 1
        return len(frame)
