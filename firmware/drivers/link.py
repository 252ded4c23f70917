"""The latched "link lost" state shared by the drivers of the serial links (motor, IMU)."""

from __future__ import annotations

from mypy_extensions import mypyc_attr

from hal.errors import HalError

__all__ = ["LinkState"]


@mypyc_attr(allow_interpreted_subclasses=True)  # as MotorLink (motor_link.py): drivers and doubles in Python
class LinkState:
    """Mixin: `link_lost` latches the first port failure with its cause and time; a relink clears it."""

    link_lost: bool = False
    lost_reason: str = ""
    lost_at_s: float | None = None

    def _lose(self, exc: HalError, now_s: float) -> None:
        """The port failed (unplugged, peer gone): latch link_lost with the cause and the time."""
        if not self.link_lost:
            self.link_lost, self.lost_reason, self.lost_at_s = True, str(exc), now_s

    def _relinked(self) -> None:
        """A reopened port is in use: the link is up again (the supervisor's latched fault stays)."""
        self.link_lost, self.lost_reason = False, ""
