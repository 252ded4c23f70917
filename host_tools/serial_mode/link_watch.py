"""Serial mode's watch on the motor and IMU ports: a lost one is recorded, then the run stops or reopens it.

The drivers latch a port failure themselves (``link_lost``) and the supervisor trips LINK_LOST; this bench
instrument, stepped by the serial probe, names the port that failed first, asks the run to stop
``STOP_AFTER_LOSS_S`` later (the safe commands go out meanwhile), or with ``--reconnect`` reopens the port
every ``RECONNECT_EVERY_S`` and carries on latched in SAFE.
"""

from __future__ import annotations

import logging
from dataclasses import dataclass
from typing import Protocol

from firmware.app import Firmware
from hal.binding import open_uart
from hal.errors import HalError
from host_tools.wire_capture import WireCapture

__all__ = ["RECONNECT_EVERY_S", "STOP_AFTER_LOSS_S", "LinkEvent", "LinkPorts", "LinkWatch"]

log = logging.getLogger(__name__)

STOP_AFTER_LOSS_S = 0.030  # after a lost link: the safe state on the ports still open, then stop
RECONNECT_EVERY_S = 0.2


class LinkPorts(Protocol):
    """What the watch reads of the run's configuration (serial_run.SerialRunConfig has these)."""

    motor: str
    imu: str
    baud: int
    imu_baud: int
    reconnect: bool


@dataclass
class LinkEvent:
    """A lost port: which role, its name, why, when the driver saw it and when the supervisor tripped."""

    role: str
    port: str
    reason: str
    lost_at_s: float | None
    detected_at_s: float | None
    reconnects: int = 0


class LinkWatch:
    """Watches for LINK_LOST: records the event; stops shortly after, or reopens the port with reconnect."""

    def __init__(self, cfg: LinkPorts, fw: Firmware, wire: WireCapture | None = None) -> None:
        """Nothing lost yet; `cfg` names the ports and whether to reconnect."""
        self.cfg, self.fw, self.wire = cfg, fw, wire
        self.event: LinkEvent | None = None
        self.stop_at: float | None = None
        self.next_try = 0.0

    def step(self, t: float) -> bool:
        """Called every probe tick at time t (s); True when the run should stop."""
        fw = self.fw
        if self.event is None and fw.link_lost_seen_s is not None:
            # the port that failed first is the one named (both go when a whole adapter or emulator dies)
            lost = [(d.lost_at_s, role, d) for role, d in (("motor", fw.motor), ("imu", fw.imu)) if d.link_lost]
            lost_at, role, drv = min(lost, key=lambda x: (x[0] if x[0] is not None else float("inf"), x[1]))
            # detection: from the first failed read or write to the supervisor's first look at it (>= 0)
            self.event = LinkEvent(role, getattr(self.cfg, role), drv.lost_reason, lost_at, fw.link_lost_seen_s)
            log.warning("%s port %s lost at %.4f s: %s", role, self.event.port, t, drv.lost_reason)
            if not self.cfg.reconnect:
                self.stop_at = t + STOP_AFTER_LOSS_S
            self.next_try = t + RECONNECT_EVERY_S
        if self.stop_at is not None:
            return t >= self.stop_at
        if self.event is not None and self.cfg.reconnect and t >= self.next_try:
            self.next_try = t + RECONNECT_EVERY_S
            self._try_reopen()
        return False

    def _try_reopen(self) -> None:
        """Reopen every lost port that is back; the supervisor stays latched in SAFE."""
        cfg = self.cfg
        for role, drv, baud in (("motor", self.fw.motor, cfg.baud), ("imu", self.fw.imu, cfg.imu_baud)):
            if not drv.link_lost:
                continue
            try:
                uart = open_uart(getattr(cfg, role), baud, role=role)
            except (HalError, ValueError) as exc:
                log.debug("%s port not back yet: %s", role, exc)
                continue
            drv.uart.close()
            drv.relink(self.wire.tap(role, uart) if self.wire is not None else uart)
            assert self.event is not None
            self.event.reconnects += 1
            log.warning("%s port %s reopened; staying in the safe state", role, getattr(cfg, role))
