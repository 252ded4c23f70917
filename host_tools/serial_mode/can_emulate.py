"""`pafp emulate motor --can URL`: the virtual AK motor (servo or MIT mode) on a real CAN bus, in wall-clock time.

The device model (:class:`~hal.virtual.devices.ak60_can.Ak60Can`, the UART model's plant, meter and
protections) lives in a world clocked in nanoseconds of the wall clock. Frames read from the python-can
bus are handed to it in their order, stamped with the instant they were taken (their arrival as far as the
loop can tell: hal.can's frames carry no kernel timestamp), after the world has run everything due before
it; the frames it sends are written when their time comes
(the reply latency after the command, the status period). The real bus adds its own wire time. The
loop waits in ``recv`` until the next device event, at most 1 ms.
"""

from __future__ import annotations

import heapq
import time
from collections.abc import Callable
from typing import Any

from hal.can import CanFrame, CanPort
from hal.pycan import CanUrl
from hal.virtual.bench import fixture_by_name
from hal.virtual.devices.ak60_can import Ak60Can, Ak60CanConfig
from hal.virtual.devices.world import World
from hal.virtual.events import NEVER
from hal.virtual.plant import Fixture, Plant

__all__ = ["WallCanBus", "WallCanMotor", "deepen_receive_buffer"]

NS_PER_S = 1_000_000_000
MAX_SLEEP_S = 0.001
MAX_FRAMES_PER_STEP = 256  # then the due frames go out and a stop request is seen, however fast frames come
DRAIN_STEPS = 64  # at the stop: at most 64 x 256 frames already received are still taken
RECEIVE_BUFFER_BYTES = 4 << 20
"""Asked of the bus's socket: a burst that finds the emulator descheduled waits there instead of being dropped
(Linux books twice the size asked, within net.core.rmem_max; its default, 208 KiB, holds about 200 udp_multicast
frames)."""


def deepen_receive_buffer(bus: object, size: int = RECEIVE_BUFFER_BYTES) -> int:
    """Ask for a receive buffer of size bytes on a python-can bus's socket (socketcan, udp_multicast); return
    what the kernel granted (0: no socket found or refused; best effort, nothing else changes)."""
    import socket

    sock = getattr(bus, "socket", None) or getattr(getattr(bus, "_multicast", None), "_socket", None)
    if not isinstance(sock, socket.socket):
        return 0
    try:
        sock.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, size)
        return int(sock.getsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF))
    except OSError:
        return 0


class WallCanBus:
    """Stands in for the virtual bus: the device's frames wait here until their wall-clock time."""

    def __init__(self) -> None:
        """Nothing queued."""
        self._queue: list[tuple[int, int, CanFrame]] = []
        self._seq = 0

    def attach(self, node: object) -> None:
        """The device registers itself (frames from the real bus are handed to it by the loop)."""

    def offer(self, node: object, frame: CanFrame, ready: int) -> None:
        """Queue frame for tick ready."""
        self._seq += 1
        heapq.heappush(self._queue, (ready, self._seq, frame))

    def withdraw(self, node: object) -> int:
        """Drop everything queued."""
        n = len(self._queue)
        self._queue.clear()
        return n

    def due(self, now: int) -> list[CanFrame]:
        """The frames whose time has come, in order."""
        queue = self._queue
        out = []
        while queue and queue[0][0] <= now:
            out.append(heapq.heappop(queue)[2])
        return out

    def next_at(self) -> int:
        """Tick of the next queued frame (NEVER if none)."""
        return self._queue[0][0] if self._queue else NEVER


class WallCanMotor:
    """The AK60-6 over CAN on ``port`` (a :class:`~hal.can.CanPort`), one plant, wall-clock ns."""

    def __init__(self, port: CanPort, url: CanUrl, fixture: Fixture | str | None = "suspended",
                 clock_ns: Callable[[], int] | None = None, world: World | None = None, *,
                 plant_options: dict[str, Any] | None = None, can_config: Ak60CanConfig | None = None) -> None:
        """Start the plant and the device now; with `world` (and its clock), the device joins that plant
        (`pafp emulate bench --can`: the IMU on a pty sees the same foot). plant_options: the plant's parameters,
        initial angle and backlash (``plant_params``, ``initial_angle_rad``, ``backlash_rad``; default: the
        packaged AK60-6 plant); can_config: the CAN side (default: the URL's id and mode, the AK60-6's ranges)."""
        if clock_ns is None:
            t0 = time.perf_counter_ns()
            clock_ns = lambda: time.perf_counter_ns() - t0  # noqa: E731
        self.now = clock_ns
        self.port = port
        if world is None:
            fx = fixture_by_name(fixture) if isinstance(fixture, str) else fixture
            o = plant_options or {}
            world = World(Plant(o.get("plant_params"), fx, initial_angle_rad=o.get("initial_angle_rad", 0.0),
                                backlash_rad=o.get("backlash_rad", 0.0)), NS_PER_S)
        self.world = world
        self.bus = WallCanBus()
        cc = can_config if can_config is not None else Ak60CanConfig(driver_id=url.driver_id, mode=url.mode)
        self.device = Ak60Can(self.world, self.bus, cc)
        self.frames_in = 0
        self.frames_out = 0
        self.tx_refused = 0

    def step(self) -> int:
        """Take the frames that arrived, against the world advanced to their arrival; run the device up to now;
        send what is due.

        The frames waiting in the port arrived by the instant they are taken: they are handed to the device, in
        their order, at that instant (never before the world's present: not in the past, nor in the future),
        after everything due before it has run. A burst that finds the emulator behind (a busy host) is
        applied in order while the world catches up; the status frames that fell due while the emulator was away
        are not sent in a burst, only the latest of them (the device's ``late_before``: the others are counted as
        superseded). At most MAX_FRAMES_PER_STEP frames are taken per step; the rest wait in the bus's receive
        buffer. Returns the number of frames taken. The due frames sent, the plant is integrated up to now: a quiet
        spell is paid for as it passes, not by the reply to the next command.
        """
        world = self.world
        self.device.late_before = self.now()
        frames = []
        for _ in range(MAX_FRAMES_PER_STEP):
            frame = self.port.receive()
            if frame is None:
                break
            frames.append(frame)
        if frames:
            self.frames_in += len(frames)
            t = max(self.now(), world.now + 1)
            world.advance_to(t - 1)
            for frame in frames:
                self.device.on_frame(frame, t)
        now = max(self.now(), world.now)
        world.advance_to(now)
        for frame in self.bus.due(now):
            if self.port.send(frame):
                self.frames_out += 1
            else:
                self.tx_refused += 1
        world.commit_plant()
        return len(frames)

    def serve(self, stop: list[str], duration_s: float | None) -> None:
        """Step until stop is non-empty or duration_s has passed; sleep in between (at most 1 ms), unless the step
        took frames (more may be waiting). Then :meth:`drain`."""
        end = None if duration_s is None else self.now() + int(duration_s * NS_PER_S)
        while not stop:
            took = self.step()
            now = self.now()
            if end is not None and now >= end:
                break
            if took:
                continue
            wake = min(self.world_next(), self.bus.next_at())
            pause = min(MAX_SLEEP_S, max(0.0, (wake - now) / NS_PER_S))
            if pause > 0:
                time.sleep(pause)
        self.drain()

    def drain(self) -> None:
        """At the stop, take the frames that had already arrived (at most DRAIN_STEPS steps of them): a client's
        last commands before it stopped the emulator are handled and counted, whatever the signal interrupted."""
        for _ in range(DRAIN_STEPS):
            if not self.step():
                return

    def world_next(self) -> int:
        """The earliest device event."""
        return min(self.device.next_event, self.device.core.next_event)

    def summary(self, why: str) -> str:
        """One line: what was served and counted."""
        d = self.device
        echoes = getattr(self.port, "echoes", 0)
        servo = (f", {d.unknown_packets} unknown packets, {d.special_frames} special frames, "
                 f"{d.status_superseded} late status frames superseded" if d.mode == "servo" else "")
        return (f"pafp emulate: stopped ({why}); motor over CAN ({d.mode} mode, id {d.driver_id}): "
                f"{self.frames_in} frames in ({d.frames_in} to this id{servo}), {self.frames_out} out, "
                f"{d.ignored_frames} ignored, {d.core.stats.timeouts} command timeouts, {self.tx_refused} refused "
                f"by the bus, {echoes} own echoes dropped")
