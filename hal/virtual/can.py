"""The virtual bxCAN of the STM32: 3 transmit mailboxes, 2 receive FIFOs of 3 with overrun, ID filters.

A node of a :class:`~hal.virtual.can_bus.VirtualCanBus`. ``send`` at cycle t first brings the world up
to t (freeing the mailboxes whose frames have ended), then takes a free mailbox or refuses (counted);
a taken mailbox is offered to the bus at t and is free again at the end of its frame. Frames ending on
the bus are kept with their end times and moved into the FIFOs only when the MCU looks (``receive``),
in arrival order, so that a FIFO's state at each read is exact: a frame is checked against the filter
banks (first match decides its FIFO; frames no bank accepts are dropped, counted in ``filtered``;
with no bank set, every frame goes to FIFO 0), and a fourth frame into a full FIFO is an overrun
(RM0090 "FIFO overrun": FOVR set; with ``fifo_lock`` off, the default, the last stored frame is
overwritten by the new one; with it on, the new frame is discarded). ``receive`` reads FIFO 0 first.
"""

from __future__ import annotations

from collections import deque
from collections.abc import Callable

from hal.can import CanFrame, CanPort
from hal.virtual.can_bus import VirtualCanBus
from hal.virtual.irq import EventTimesInterrupt

__all__ = ["FIFO_DEPTH", "TX_MAILBOXES", "FilterBank", "VirtualBxCan"]

TX_MAILBOXES = 3
FIFO_DEPTH = 3


class FilterBank:
    """Accept a frame when ``(id & mask) == (ident & mask)`` and its ID kind matches; into ``fifo`` (0 or 1)."""

    def __init__(self, ident: int, mask: int, extended: bool, fifo: int = 0) -> None:
        """A bank in identifier-mask mode."""
        if fifo not in (0, 1):
            raise ValueError(f"filter fifo {fifo!r} out of range: 0 or 1")
        self.ident = ident
        self.mask = mask
        self.extended = extended
        self.fifo = fifo

    def accepts(self, frame: CanFrame) -> bool:
        """Whether frame passes this bank."""
        return frame.extended == self.extended and (frame.arbitration_id & self.mask) == (self.ident & self.mask)


class VirtualBxCan(CanPort):
    """The MCU's CAN controller on the cycle clock ``now``, attached to bus."""

    def __init__(self, now: Callable[[], int], bus: VirtualCanBus, name: str = "can", fifo_lock: bool = False,
                 max_banks: int = 14) -> None:
        """Empty mailboxes and FIFOs, no filter bank (everything to FIFO 0); max_banks: 14 (F1) or 28 (F4)."""
        super().__init__(bus.bitrate, name)
        self._now = now
        self.bus = bus
        self.fifo_lock = fifo_lock
        self.max_banks = max_banks
        self.banks: list[FilterBank] = []
        self._mailboxes: list[CanFrame] = []
        self._arrivals: deque[tuple[int, CanFrame]] = deque()
        self._fifos: tuple[deque[CanFrame], deque[CanFrame]] = (deque(), deque())
        self.fifo_overruns = [0, 0]
        self.filtered = 0
        self.tx_frames = 0
        self.rx_frames = 0
        self._irq_sources: list[EventTimesInterrupt] = []
        bus.attach(self)

    # configuration -------------------------------------------------------------------------
    def set_filters(self, banks: list[FilterBank]) -> None:
        """Replace the filter banks (at most max_banks)."""
        if len(banks) > self.max_banks:
            raise ValueError(f"{len(banks)} filter banks: this bxCAN has {self.max_banks}")
        self.banks = list(banks)

    def rx_interrupt(self, cost_cycles: object, name: str | None = None) -> EventTimesInterrupt:
        """An interrupt source firing once per frame received into a FIFO region (at its end)."""
        source = EventTimesInterrupt(name or f"{self.name}_rx", cost_cycles, self._advance)
        self._irq_sources.append(source)
        return source

    # bus side -------------------------------------------------------------------------------
    def on_frame(self, frame: CanFrame, t: int) -> None:
        """A frame from another node ended at t: kept until the MCU looks."""
        self._arrivals.append((t, frame))
        for source in self._irq_sources:
            source.add_times((t,))

    def tx_done(self, frame: CanFrame, t: int) -> None:
        """Our frame left: its mailbox is free."""
        self._mailboxes.remove(frame)
        self.tx_frames += 1

    # time ------------------------------------------------------------------------------------
    def _advance(self, t: int) -> None:
        self.bus.world.advance_to(t)

    def _sync(self) -> None:
        t = self._now()
        self._advance(t)
        arrivals = self._arrivals
        while arrivals and arrivals[0][0] <= t:
            self._store(arrivals.popleft()[1])

    def _store(self, frame: CanFrame) -> None:
        fifo = 0
        if self.banks:
            for bank in self.banks:
                if bank.accepts(frame):
                    fifo = bank.fifo
                    break
            else:
                self.filtered += 1
                return
        queue = self._fifos[fifo]
        if len(queue) >= FIFO_DEPTH:
            self.fifo_overruns[fifo] += 1
            self.errors.overruns += 1
            if not self.fifo_lock:
                queue[-1] = frame
            return
        queue.append(frame)
        self.rx_frames += 1

    def fifo_level(self, fifo: int) -> int:
        """Frames waiting in FIFO 0 or 1 now."""
        self._sync()
        return len(self._fifos[fifo])

    # CanPort hooks -------------------------------------------------------------------------
    def _send(self, frame: CanFrame) -> bool:
        t = self._now()
        self._advance(t)
        if len(self._mailboxes) >= TX_MAILBOXES:
            return False
        self._mailboxes.append(frame)
        self.bus.offer(self, frame, t)
        return True

    def _receive(self) -> CanFrame | None:
        self._sync()
        for queue in self._fifos:
            if queue:
                return queue.popleft()
        return None

    def _tx_pending(self) -> int:
        self._advance(self._now())
        return len(self._mailboxes)

    def _drain(self, timeout_s: float) -> bool:
        # virtual time does not pass inside a call: the mailboxes are empty only if they already are
        return self._tx_pending() == 0

    def _close(self) -> None:
        self.bus.withdraw(self)
        self._mailboxes.clear()
        self._arrivals.clear()
