"""The firmware's clock for host instruments: a ``fault://`` port (hal/serial/protocol_fault.py) counts its window
on it and places a gait-phase onset on its gait clock. Serial mode hands both to every such port it opened."""

from __future__ import annotations

from collections.abc import Callable, Iterable

from firmware.app import Firmware

__all__ = ["FirmwareClock", "follow_firmware"]


class FirmwareClock:
    """The firmware's time in seconds for host instruments (``fault://`` ports): None until its scheduler runs.

    During a job it is the job's start, the very time the firmware stamps what it reads with.

    >>> clock = FirmwareClock(lambda: 84_000_000, 168_000_000); clock() is None
    True
    >>> clock.started = True; clock()
    0.5
    """

    def __init__(self, now_cycles: Callable[[], int], f_cpu_hz: int) -> None:
        """Not started: None until ``started`` is set (right before the scheduler runs)."""
        self.now_cycles = now_cycles
        self.f_cpu_hz = f_cpu_hz
        self.started = False

    def __call__(self) -> float | None:
        """Seconds since the firmware's start, or None before it."""
        return self.now_cycles() / self.f_cpu_hz if self.started else None


def follow_firmware(uarts: Iterable[object], fw: Firmware, now_s: FirmwareClock, stride_s: float) -> None:
    """Tell every ``fault://`` port (hal/serial/protocol_fault.py) the firmware's clock, so ``at=S`` counts from the
    firmware's start however long the start-up took, and its gait clock, so a fault given as a gait phase starts at
    that phase (a host instrument: the firmware does not know the port is wrapped)."""
    def gait_time_s() -> float | None:
        start, t = fw.gait_start_s, now_s()
        return None if start is None or t is None else t - start

    for uart in uarts:
        while uart is not None and not hasattr(uart, "serial"):  # a capture's tap or the recorder's wrapper
            uart = getattr(uart, "inner", None)
        port = getattr(uart, "serial", None)
        if hasattr(port, "follow_clock") and hasattr(port, "follow_gait"):
            port.follow_clock(now_s)  # type: ignore[union-attr]
            port.follow_gait(gait_time_s, stride_s)  # type: ignore[union-attr]
