"""Multicast groups for the tests' udp_multicast buses: a fresh one per call, drawn at random in 239.64.0.0/10.

A group named after the test process's pid is not enough. Two test runs in separate pid namespaces (containers on
one host and one network) start their workers at the same pids, and a test may leave its emulator sending on its
group for a moment after it ends. Linux hands a group's datagrams to every socket on the host that joined it, so
such buses would hear each other's motors. This draw is the tests' one random choice without a seed: it names an
address, not a result.
"""

from __future__ import annotations

import random

__all__ = ["multicast_group"]

_RNG = random.SystemRandom()
_DRAWN: set[str] = set()


def multicast_group() -> str:
    """A multicast group no other call in this process returned (and, by the draw, very likely no other process)."""
    while True:
        n = _RNG.getrandbits(22)
        group = f"239.{64 + (n >> 16)}.{(n >> 8) & 0xFF}.{n & 0xFF}"
        if group not in _DRAWN:
            _DRAWN.add(group)
            return group
