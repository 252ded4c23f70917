"""What the CAN bus faults share: they act on the frames between the MCU and the motor on the virtual bus."""

from __future__ import annotations

from hal.can import CanFrame
from hal.virtual.faults.base import FaultRig, Injector
from hal.virtual.faults.taps import can_tap

__all__ = ["CanFault"]


class CanFault(Injector):
    """A fault of the bus: ``fate`` of each frame in the window (None: destroyed; else the delay in seconds)."""

    WHERE = "CAN bus (frames between the MCU and the motor)"
    LINKS = ("can-servo", "can-mit")

    def arm(self, rig: FaultRig) -> None:
        """Act on the frames both ways."""
        self.bitrate = rig.bench.can_bitrate
        tap = can_tap(rig)
        tap.rx_faults.append(self)
        tap.tx_faults.append(self)

    def on_frame(self, frame: CanFrame, t_s: float) -> float | None:
        """The frame's fate, noted when it is not delivered on time."""
        if not self.active(t_s):
            return 0.0
        fate = self.fate(frame, t_s)
        if fate != 0.0:
            self.note(t_s, f"frame {frame.arbitration_id:#x} " + ("destroyed" if fate is None else
                                                                f"delayed {fate * 1e6:.0f} us"))
        return fate

    def fate(self, frame: CanFrame, t_s: float) -> float | None:
        """What happens to a frame in the window (subclasses)."""
        raise NotImplementedError
