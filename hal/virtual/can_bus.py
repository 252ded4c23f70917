"""A virtual CAN bus on the world's clock: frame times with exact stuffing, priority arbitration, bus load.

The bus is a :class:`~hal.virtual.events.EventDevice` of the device :class:`~hal.virtual.devices.world.World`.
Nodes (the MCU's bxCAN, device models) ``offer`` a frame from a tick on; whenever the wire is idle the
bus picks, among the frames offered by then, the one whose arbitration field is lowest (a dominant 0
wins: lower ID first; a standard frame beats an extended one with the same 11-bit base ID), puts it on
the wire for :func:`~hal.virtual.can_bits.frame_bits` bit times (intermission included) and at its end
hands it to every other node (``on_frame``) and tells the sender (``tx_done``). One node offers its
mailboxes in ID order too (bxCAN's default transmit priority). Frames lose nothing on the wire: error
frames and retransmission are not modelled.
"""

from __future__ import annotations

from typing import Protocol

from hal.can import CanFrame
from hal.virtual.can_bits import frame_bits
from hal.virtual.devices.world import World
from hal.virtual.events import NEVER, EventDevice

__all__ = ["CanNode", "VirtualCanBus", "arbitration_key"]


class CanNode(Protocol):
    """A node on the virtual bus."""

    def on_frame(self, frame: CanFrame, t: int) -> None:
        """A frame sent by another node ended at tick t."""
        ...

    def tx_done(self, frame: CanFrame, t: int) -> None:
        """This node's frame ended at tick t (acknowledged)."""
        ...


def arbitration_key(frame: CanFrame) -> int:
    """Lower wins arbitration: the arbitration field read as a number (base ID, SRR/IDE, extension)."""
    if frame.extended:
        return ((frame.arbitration_id >> 18) << 20) | (3 << 18) | (frame.arbitration_id & 0x3FFFF)
    return frame.arbitration_id << 20


class _Offer:
    def __init__(self, key: int, seq: int, node: CanNode, frame: CanFrame, ready: int) -> None:
        self.key = key
        self.seq = seq
        self.node = node
        self.frame = frame
        self.ready = ready


class VirtualCanBus(EventDevice):
    """The wire shared by the nodes at ``bitrate`` bit/s; ticks are the world's."""

    def __init__(self, world: World, bitrate: int = 1_000_000) -> None:
        """An idle bus with no nodes, added to world."""
        super().__init__()
        if isinstance(bitrate, bool) or not isinstance(bitrate, int) or not 10_000 <= bitrate <= 1_000_000:
            raise ValueError(f"CAN bitrate {bitrate!r} out of range: an int in 10000..1000000 bit/s")
        self.world = world
        self.bitrate = bitrate
        self.bit_ticks = world.f_hz / bitrate
        self._nodes: list[CanNode] = []
        self._offers: list[_Offer] = []
        self._wire: _Offer | None = None
        self._wire_end = NEVER
        self._idle_from = 0
        self._seq = 0
        self.frames = 0
        self.bits = 0
        self.busy_ticks = 0
        self.arbitration_losses = 0
        self.late_offers = 0
        world.add(self)

    def attach(self, node: CanNode) -> None:
        """Connect a node: it receives every frame it did not send."""
        self._nodes.append(node)

    def frame_ticks(self, frame: CanFrame) -> int:
        """Ticks frame takes on this wire (exact stuffing, intermission included)."""
        return int(round(frame_bits(frame.arbitration_id, frame.data, frame.extended) * self.bit_ticks))

    def offer(self, node: CanNode, frame: CanFrame, ready: int) -> None:
        """node wants frame on the wire from tick ready on (not before the world's present)."""
        now = self.world.now
        if ready < now:  # the world was brought past ready by a look-ahead: the frame competes from now on
            self.late_offers += 1
            ready = now
        self._seq += 1
        self._offers.append(_Offer(arbitration_key(frame), self._seq, node, frame, ready))
        self._update_next()

    def withdraw(self, node: CanNode) -> int:
        """Drop node's frames that have not started (a mailbox abort); return how many."""
        keep = [o for o in self._offers if o.node is not node]
        n = len(self._offers) - len(keep)
        self._offers = keep
        self._update_next()
        return n

    def load(self, span_ticks: int) -> float:
        """Fraction of span_ticks the wire was busy (frames started so far)."""
        return self.busy_ticks / span_ticks if span_ticks > 0 else 0.0

    def _update_next(self) -> None:
        if self._wire is not None:
            self.next_event = self._wire_end
            return
        nxt = NEVER
        for o in self._offers:
            if o.ready < nxt:
                nxt = o.ready
        self.next_event = max(nxt, self._idle_from) if nxt != NEVER else NEVER

    def run_event(self) -> None:
        """End the frame on the wire at its end, or arbitrate among the frames offered by the present tick."""
        t = self.next_event
        wire = self._wire
        if wire is not None and self._wire_end <= t:
            self._wire, self._wire_end, self._idle_from = None, NEVER, t
            frame = wire.frame
            for node in self._nodes:
                if node is not wire.node:
                    node.on_frame(frame, t)
            wire.node.tx_done(frame, t)
        if self._wire is None:
            best: _Offer | None = None
            contenders = 0
            for o in self._offers:
                if o.ready <= t:
                    contenders += 1
                    if best is None or o.key < best.key or (o.key == best.key and o.seq < best.seq):
                        best = o
            if best is not None:
                self.arbitration_losses += contenders - 1
                self._offers.remove(best)
                ticks = self.frame_ticks(best.frame)
                self._wire, self._wire_end = best, t + ticks
                self.frames += 1
                self.busy_ticks += ticks
        self._update_next()
