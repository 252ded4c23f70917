"""A faulty cable for serial-mode tests: relays bytes between new ptys and device ptys, spoiling some.

Run as a separate process (``python tests/serial_mitm.py --link motor=/dev/pts/N ...``) so that its
timing does not share the GIL with the firmware under test. For each ``--link ROLE=DEVICE`` it creates a
raw pty, prints ``ROLE: PATH`` (the path the firmware opens) and relays both directions. On the way from
the device to the firmware it injects seeded bursts of random bytes, drops single bytes, and now and then
holds everything back for ``--delay-s`` (a device replying late), from ``--start-s`` to ``--until-s``
after the first byte from the host (the firmware's start-up check: the fault window is tied to the run, not
to when this relay happened to start). With ``--capture DIR`` it writes every byte it relays, as it came in, to
``DIR/<role>.to_device.bin`` and ``DIR/<role>.to_host.bin`` (before spoiling: what each side sent). On SIGTERM
it relays what is still waiting, prints one JSON line with what it did per role and exits 0.
"""

from __future__ import annotations

import argparse
import json
import os
import random
import select
import signal
import sys
import termios
import time
import tty
from dataclasses import asdict, dataclass, field


@dataclass
class LinkCounts:
    """What the relay did on one link."""

    to_device: int = 0
    to_host: int = 0
    garbage_bytes: int = 0
    garbage_bursts: int = 0
    dropped_bytes: int = 0
    delays: int = 0
    write_errors: list[str] = field(default_factory=list)


@dataclass
class Link:
    """One relayed link: our pty master (the firmware's side) and the device's pty, opened as a client."""

    role: str
    host_fd: int
    host_slave: int
    device_fd: int
    counts: LinkCounts
    next_garbage_s: float
    next_delay_s: float
    garbage_rng: random.Random
    capture: dict[bool, object] = field(default_factory=dict)  # from_host -> open file


def _open_link(role: str, device: str, now_s: float, args: argparse.Namespace) -> Link:
    """A new raw pty for the firmware and the device's pty opened raw and non-blocking."""
    master, slave = os.openpty()
    tty.setraw(slave)
    os.set_blocking(master, False)
    dev = os.open(device, os.O_RDWR | os.O_NOCTTY | os.O_NONBLOCK)
    tty.setraw(dev)
    termios.tcflush(dev, termios.TCIFLUSH)  # what the device sent while nobody listened is gone
    print(f"{role}: {os.ttyname(slave)}", flush=True)
    link = Link(role, master, slave, dev, LinkCounts(), now_s + args.start_s, now_s + args.start_s,
                random.Random(f"{args.seed}:{role}"))
    if args.capture:
        link.capture = {True: open(os.path.join(args.capture, f"{role}.to_device.bin"), "wb"),  # noqa: SIM115
                        False: open(os.path.join(args.capture, f"{role}.to_host.bin"), "wb")}  # noqa: SIM115
    return link


def _write_all(fd: int, data: bytes, counts: LinkCounts) -> None:
    """Write everything (a pty takes a few kB; spin briefly if it is full)."""
    view = memoryview(data)
    deadline = time.monotonic() + 0.05
    while view:
        try:
            n = os.write(fd, view)
        except BlockingIOError:
            n = 0
        except OSError as exc:
            counts.write_errors.append(str(exc))
            return
        view = view[n:]
        if view and time.monotonic() > deadline:
            counts.write_errors.append(f"{len(view)} bytes not taken")
            return


def _spoil(link: Link, data: bytes, now_s: float, rng: random.Random, args: argparse.Namespace) -> bytes:
    # the bursts come from link.garbage_rng alone, so a seed gives the same bursts whatever the chunking
    """Device -> host bytes after the faults: a late hold, a garbage burst in front, single bytes dropped."""
    c = link.counts
    if args.t0_s is None or now_s >= args.t0_s + args.until_s:
        return data  # clean before the host's first byte and after the window
    lossy = args.lossy is None or link.role in args.lossy.split(",")
    if lossy and args.delay_every_s > 0 and now_s >= link.next_delay_s:
        link.next_delay_s = now_s + args.delay_every_s
        c.delays += 1
        time.sleep(args.delay_s)
    out = bytearray()
    if args.garbage_every_s > 0 and now_s >= link.next_garbage_s:
        link.next_garbage_s = now_s + args.garbage_every_s
        g = link.garbage_rng
        burst = g.randbytes(g.randint(1, args.garbage_max))
        out += burst
        c.garbage_bytes += len(burst)
        c.garbage_bursts += 1
    for b in data:
        if lossy and rng.random() < args.drop_p:
            c.dropped_bytes += 1
        else:
            out.append(b)
    return bytes(out)


def _anchor(links: list[Link], args: argparse.Namespace) -> None:
    """Start the fault clock: the first garbage burst and hold come ``start_s`` from now."""
    args.t0_s, args.t0_unix_s = time.monotonic(), time.time()
    for link in links:
        link.next_garbage_s = link.next_delay_s = args.t0_s + args.start_s


def serve(links: list[Link], rng: random.Random, args: argparse.Namespace, stop: list[int]) -> None:
    """Relay until stop is non-empty, then once more what is already waiting."""
    by_fd: dict[int, tuple[Link, bool]] = {}
    for link in links:
        by_fd[link.host_fd] = (link, True)
        by_fd[link.device_fd] = (link, False)
    host_fds = [link.host_fd for link in links]
    while True:
        final = bool(stop)  # stopping: what the host has written so far still goes through, then out
        try:
            readable, _, _ = select.select(host_fds if final else list(by_fd), [], [], 0.0 if final else 0.01)
        except InterruptedError:
            continue
        if final and not readable:
            return
        for fd in readable:
            link, from_host = by_fd[fd]
            try:
                data = os.read(fd, 4096)
            except (BlockingIOError, InterruptedError):
                continue
            except OSError:  # the firmware closed its end (EIO on the master): wait for it to come back
                if final:
                    return
                time.sleep(0.001)
                continue
            if link.capture:
                link.capture[from_host].write(data)  # type: ignore[attr-defined]
            if from_host and args.t0_s is None:  # the host's first byte: the fault window starts now
                _anchor(links, args)
            if from_host:
                link.counts.to_device += len(data)
                _write_all(link.device_fd, data, link.counts)
            else:
                data = _spoil(link, data, time.monotonic(), rng, args)
                link.counts.to_host += len(data)
                _write_all(link.host_fd, data, link.counts)


def main(argv: list[str] | None = None) -> int:
    """Parse the options, open the links, relay until SIGTERM, print the counts as JSON."""
    p = argparse.ArgumentParser(description=__doc__)
    p.add_argument("--link", action="append", required=True, metavar="ROLE=DEVICE")
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--start-s", type=float, default=0.5, help="clean relay this long first (start-up check)")
    p.add_argument("--until-s", type=float, default=1e9, help="clean relay again from this time on")
    p.add_argument("--garbage-every-s", type=float, default=0.05, help="0: no garbage")
    p.add_argument("--garbage-max", type=int, default=48)
    p.add_argument("--drop-p", type=float, default=0.002)
    p.add_argument("--delay-every-s", type=float, default=0.1, help="0: never late")
    p.add_argument("--delay-s", type=float, default=0.005)
    p.add_argument("--lossy", default=None, metavar="ROLE,...", help="drops and delays on these links only")
    p.add_argument("--capture", default=None, metavar="DIR", help="write the relayed bytes per role and direction")
    args = p.parse_args(argv)
    rng = random.Random(args.seed)  # which bytes are dropped
    now_s = time.monotonic()
    args.t0_s = args.t0_unix_s = None  # set by the host's first byte (_anchor)
    links = [_open_link(*spec.split("=", 1), now_s, args) for spec in args.link]
    stop: list[int] = []
    signal.signal(signal.SIGTERM, lambda signum, frame: stop.append(signum))
    serve(links, rng, args, stop)
    for link in links:
        for f in link.capture.values():
            f.close()  # type: ignore[attr-defined]
    report: dict[str, object] = {link.role: asdict(link.counts) for link in links}
    t0 = args.t0_unix_s
    report["faults_unix_s"] = None if t0 is None else [t0 + args.start_s, t0 + min(args.until_s, 1e6)]
    print(json.dumps(report), flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
