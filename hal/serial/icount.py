"""Linux serial error counters (ioctl TIOCGICOUNT): framing and overrun counts of real UART drivers.

The kernel keeps ``struct serial_icounter_struct`` (include/uapi/linux/serial.h: cts, dsr, rng,
dcd, rx, tx, frame, overrun, parity, brk, buf_overrun, reserved[9]; 20 ints) for drivers that
support it (8250, many USB adapters). Ptys, sockets and other platforms do not: then None.
"""

from __future__ import annotations

import logging
import platform
import struct
import sys
from dataclasses import dataclass

__all__ = ["IcountSnapshot", "read_icount"]

log = logging.getLogger(__name__)

TIOCGICOUNT = 0x545D  # asm-generic/ioctls.h (x86, arm, arm64, riscv)
_STRUCT = struct.Struct("20i")
_GENERIC_IOCTL_MACHINES = ("x86_64", "i386", "i686", "aarch64", "arm64", "armv7l", "armv6l", "riscv64")


@dataclass(frozen=True)
class IcountSnapshot:
    """The error fields of one TIOCGICOUNT reading (cumulative since the driver loaded)."""

    frame: int
    overrun: int
    parity: int
    brk: int
    buf_overrun: int


def read_icount(fd: int) -> IcountSnapshot | None:
    """Read the error counters of the tty open on fd, or None where the ioctl is unsupported."""
    if not sys.platform.startswith("linux") or platform.machine() not in _GENERIC_IOCTL_MACHINES:
        return None
    try:
        import fcntl

        raw = fcntl.ioctl(fd, TIOCGICOUNT, bytes(_STRUCT.size))
    except (OSError, ValueError, TypeError) as exc:
        log.debug("TIOCGICOUNT unsupported on fd %r: %s", fd, exc)
        return None
    values = _STRUCT.unpack(raw)
    return IcountSnapshot(values[6], values[7], values[8], values[9], values[10])
