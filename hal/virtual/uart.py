"""A byte-timed virtual UART on the cycle clock: lazy, exact, with overrun and fault injection.

Nothing happens per byte. A write at cycle t schedules the bytes on the TX wire back to back
(10 bit-times each, 8N1) and hands them at once to the connected peer (a device model) with
their stop-bit end times. The peer pushes its replies with `VirtualUart.transmit_to_mcu`, which
schedules them on the RX wire. A read at cycle t first lets the peer catch up to t, then moves
every byte whose stop bit has ended by t into the receive buffer, in arrival order, counting
overruns when the buffer is full, and returns from the buffer.
"""

from __future__ import annotations

import logging
from collections import deque
from collections.abc import Callable, Sequence
from typing import Literal, Protocol

from hal.interfaces import Uart
from hal.virtual.checks import check_int
from hal.virtual.events import Horizon
from hal.virtual.irq import EventTimesInterrupt
from hal.virtual.line import ByteLine

__all__ = ["UartPeer", "VirtualUart"]

log = logging.getLogger(__name__)

_DATA, _NOISE, _FRAMING = 0, 1, 2


class UartPeer(Protocol):
    """The far end of a virtual UART (a device model)."""

    def on_bytes(self, data: bytes, end_times_cycles: Sequence[int]) -> None:
        """Receive bytes the MCU sent, each with its stop-bit end; act on none before its end."""
        ...

    def advance_to(self, t_cycles: int) -> None:
        """Catch up to t_cycles: transmit every reply byte that starts by then (transmit_to_mcu)."""
        ...


class _Chunk:
    """Bytes scheduled on the RX wire by one call, with their end times; ``pos`` of them have arrived."""

    def __init__(self, ends: list[int], data: bytes, kind: int) -> None:
        """A chunk of which nothing has arrived yet."""
        self.ends = ends
        self.data = data
        self.kind = kind
        self.pos = 0


class VirtualUart(Uart):
    """A UART of the virtual MCU at a configured baud on the integer cycle clock ``now``.

    rx_buffer_size models the firmware's receive ring buffer (filled by the RX interrupt):
    when it is full, newly arriving bytes are lost, the oldest are kept. tx_queue_size models the
    transmit ring buffer: a byte occupies it until its stop bit has ended.
    """

    def __init__(
        self,
        now: Callable[[], int],
        f_cpu_hz: object,
        baud: object,
        rx_buffer_size: object = 256,
        tx_queue_size: object = 256,
        name: str = "uart",
    ) -> None:
        """Create an idle UART with empty buffers and no peer (sizes and clock: ints >= 1)."""
        super().__init__(baud, name)
        self._now = now
        self.f_cpu_hz = check_int("f_cpu_hz", f_cpu_hz, 1)
        self.rx_buffer_size = check_int("rx_buffer_size", rx_buffer_size, 1)
        self.tx_queue_size = check_int("tx_queue_size", tx_queue_size, 1)
        self._tx_line = ByteLine(f_cpu_hz, baud)
        self._rx_line = ByteLine(f_cpu_hz, baud)
        self._pending: deque[_Chunk] = deque()
        self._buffer = bytearray()
        self._synced = 0
        self._peer: UartPeer | None = None
        self._peer_time = -1
        self._in_overrun = False
        self._irq_sources: list[EventTimesInterrupt] = []
        self._drop_rx = 0
        self._drop_tx = 0
        self.dropped_rx = 0
        self.dropped_tx = 0
        self.tx_bytes = 0

    # Wiring ---------------------------------------------------------------------------------
    @property
    def peer(self) -> UartPeer | None:
        """The connected device model, if any."""
        return self._peer

    def connect(self, peer: UartPeer | None) -> None:
        """Connect a device model to this UART (None disconnects)."""
        if peer is not None and not (callable(getattr(peer, "on_bytes", None))
                                     and callable(getattr(peer, "advance_to", None))):
            raise TypeError(f"peer {peer!r} lacks on_bytes(data, end_times) and advance_to(t)")
        self._peer = peer
        for source in self._irq_sources:
            source.horizon = self._horizon()

    def _horizon(self) -> Horizon | None:
        """The peer if it is a :class:`Horizon` (announces ``next_event``): it sends nothing ending by that tick.

        A ``Horizon`` peer promises that every byte it has not yet transmitted ends after its
        ``next_event`` (bytes are sent from events at that tick or later), so an RX interrupt window
        ending by then needs no catch-up of the peer. Any other peer is caught up for every window.
        """
        peer: object = self._peer
        if isinstance(peer, Horizon):
            return peer
        return None

    @property
    def byte_cycles(self) -> float:
        """Duration of one 8N1 byte in cycles."""
        return self._tx_line.byte_cycles

    @property
    def rx_line_busy_until(self) -> int:
        """Cycle at which the last byte scheduled towards the MCU ends."""
        return self._rx_line.busy_until

    @property
    def tx_line_busy_until(self) -> int:
        """Cycle at which the last byte the MCU queued ends."""
        return self._tx_line.busy_until

    def rx_interrupt(self, cost_cycles: object, name: str | None = None) -> EventTimesInterrupt:
        """An interrupt source firing once per byte arriving on the RX wire, at its stop-bit end."""
        source = EventTimesInterrupt(name or f"{self.name}_rx", cost_cycles, self._advance_peer)
        source.horizon = self._horizon()
        self._irq_sources.append(source)
        return source

    # Device side ----------------------------------------------------------------------------
    def transmit_to_mcu(self, data: bytes, start_cycles: int) -> list[int]:
        """The peer sends data from start_cycles (or when its line frees up); return the end cycles."""
        return self._schedule_rx(bytes(data), start_cycles, _DATA)

    def inject_garbage(self, data: bytes, start_cycles: int) -> list[int]:
        """Put arbitrary bytes on the RX wire (received as ordinary data); return their end cycles."""
        return self.transmit_to_mcu(data, start_cycles)

    def inject_noise(self, data: bytes, start_cycles: int) -> list[int]:
        """Put bytes on the RX wire that arrive with the noise flag set (kept, counted as noise)."""
        return self._schedule_rx(bytes(data), start_cycles, _NOISE)

    def inject_framing_error(self, start_cycles: int, count: int = 1) -> list[int]:
        """Put count characters with a bad stop bit on the RX wire (counted as framing errors, not stored)."""
        if count < 1:
            raise ValueError(f"count {count!r} out of range: >= 1")
        return self._schedule_rx(b"\x00" * count, start_cycles, _FRAMING)

    def drop_next(self, n: object, direction: Literal["rx", "tx"] = "rx") -> None:
        """Lose the next n bytes (an int >= 0) on a wire: they take line time but never arrive.

        ``direction`` "rx": towards the MCU; "tx": towards the peer.
        """
        count = check_int("n", n, 0)
        if direction == "rx":
            self._drop_rx += count
        elif direction == "tx":
            self._drop_tx += count
        else:
            raise ValueError(f"direction {direction!r} invalid: 'rx' or 'tx'")

    def _schedule_rx(self, data: bytes, start_cycles: int, kind: int) -> list[int]:
        if start_cycles < self._synced:
            raise ValueError(
                f"{self.name}: start_cycles {start_cycles} is before cycle {self._synced}, "
                "which the MCU has already read up to (a peer must not transmit into the past)"
            )
        ends = self._rx_line.schedule(len(data), start_cycles)
        drop = min(self._drop_rx, len(data))
        if drop:
            self._drop_rx -= drop
            self.dropped_rx += drop
            data, ends_kept = data[drop:], ends[drop:]
        else:
            ends_kept = ends
        if data:
            self._pending.append(_Chunk(ends_kept, data, kind))
            for source in self._irq_sources:
                source.add_times(ends_kept)
        return ends

    # Time -----------------------------------------------------------------------------------
    def _advance_peer(self, t_cycles: int) -> None:
        if self._peer is not None and t_cycles > self._peer_time:
            self._peer_time = t_cycles
            self._peer.advance_to(t_cycles)

    def _sync(self) -> None:
        t = self._now()
        self._advance_peer(t)
        if t < self._synced:
            return
        self._synced = t
        pending = self._pending
        while pending:
            chunk = pending[0]
            ends, pos = chunk.ends, chunk.pos
            n = len(ends)
            stop = pos
            while stop < n and ends[stop] <= t:  # each byte is passed once: cheaper than a bisect call
                stop += 1
            if stop > pos:
                self._arrive(chunk.data[pos:stop], chunk.kind)
                chunk.pos = stop
            if stop < n:
                break
            pending.popleft()

    def _arrive(self, data: bytes, kind: int) -> None:
        if kind == _FRAMING:
            self._errors.framing += len(data)
            return
        if kind == _NOISE:
            self._errors.noise += len(data)
        room = self.rx_buffer_size - len(self._buffer)
        kept = data[: max(room, 0)]
        lost = len(data) - len(kept)
        if kept:
            self._buffer += kept
            self._in_overrun = False
        if lost:
            if not self._in_overrun:
                self._errors.overrun += 1
                log.debug("%s: overrun, %d bytes lost", self.name, lost)
            self._in_overrun = True
            self._errors.rx_lost += lost

    # Uart hooks -----------------------------------------------------------------------------
    def _send(self, data: bytes) -> int:
        t = self._now()
        self._advance_peer(t)
        n = min(len(data), self.tx_queue_size - self._tx_line.pending(t))
        if n <= 0:
            return 0
        ends = self._tx_line.schedule(n, t)
        self.tx_bytes += n
        drop = min(self._drop_tx, n)
        self._drop_tx -= drop
        self.dropped_tx += drop
        if self._peer is not None and n > drop:
            self._peer.on_bytes(data[drop:n], ends[drop:] if drop else ends)
        return n

    def _tx_space(self) -> int:
        return self.tx_queue_size - self._tx_line.pending(self._now())

    def _receive(self, max_bytes: int) -> bytes:
        self._sync()
        buffer = self._buffer
        if max_bytes < 0 or max_bytes >= len(buffer):  # everything (the usual case): no slices
            out = bytes(buffer)
            buffer.clear()
            return out
        out = bytes(buffer[:max_bytes])
        del buffer[:max_bytes]
        return out

    def _rx_count(self) -> int:
        self._sync()
        return len(self._buffer)

    def _refresh_errors(self) -> None:
        self._sync()

    def _close(self) -> None:
        self._peer = None
        self._pending.clear()
        self._buffer.clear()
