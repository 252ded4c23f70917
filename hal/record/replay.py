"""The replay backend: a `Board` whose peripherals and clock serve back what a record says they returned.

A record is read one section (one job) at a time (hal/record/reader.py). Each call of the replayed firmware
takes the next recorded result of the same kind on the same port (the first not yet taken: a job makes a
handful of calls, a scan is cheaper than a queue per key), so a firmware that makes its calls in another
order still gets the same bytes; a call beyond the record gets a neutral answer (no bytes, the last CNT)
and is counted (``starved``). What the firmware writes is kept for the comparison (`ReplayBoard.finish`),
never sent anywhere (the peripherals: hal/record/replay_peripherals.py). The firmware does not know it is
replayed.

`replay_sections` is the replay loop: each section's job run at its recorded time, its outputs compared
and added to each port's stream (hal/record/streams.py: counts and SHA-256 of the bytes recorded and
replayed). The module is compiled (setup.py's COMPILED): the loop and the board are what a replay costs
beyond the firmware's own work.
"""

from __future__ import annotations

from collections.abc import Callable, Iterator
from typing import Any, BinaryIO, Final

from hal.errors import HalError
from hal.interfaces import Board
from hal.record.format import Kind
from hal.record.reader import Section
from hal.record.recorder import PORTS
from hal.record.replay_peripherals import ReplayCan, ReplayEncoder, ReplayLed, ReplayPin, ReplayUart, ReplayWatchdog
from hal.record.streams import Stream, item_bytes_all, port_name
from rtos.job import Job

__all__ = ["ReplayBoard", "replay_sections"]

_CLOCK_KEY: Final = Kind.CLOCK << 2
_HEALTH_KEY: Final = Kind.HEALTH << 2
_FLUSH_BYTES: Final = 1 << 16  # a stream hashes its bytes once this many are pending (one update per ~64 KB)


class ReplayBoard:
    """The replayed peripherals: `board` for the firmware, `begin(section)` before each job, `finish()` after."""

    def __init__(self, header: dict, sinks: dict[str, BinaryIO] | None = None) -> None:
        """Peripherals shaped like the recorded ones (bauds, encoder width, CAN) from the record's header;
        `sinks` by port name receive the replayed bytes of that port (e.g. telemetry)."""
        ports = header["ports"]
        self.section = Section(-1, 0, 0)
        self.produced: dict[int, list] = {}
        self.starved = 0  # calls the record had no answer for (a changed firmware asking more)
        self.unused = 0  # recorded answers no call took (a changed firmware asking less)
        self.last: dict[int, Any] = {}
        self.last_control = -1  # the start of the latest control job replayed (replay_sections)
        self.streams: dict[str, Stream] = {}
        self._by_key: dict[int, Stream] = {}
        self._sinks: dict[str, BinaryIO] = dict(sinks or {})
        self.f_cpu_hz = int(header["f_cpu_hz"])
        can = ReplayCan(self, int(header["can_bitrate"])) if header.get("can_bitrate") else None
        self.board = Board(
            motor_uart=ReplayUart(self, PORTS["motor"], int(ports["motor"]["baud"]), ports["motor"]["name"]),
            imu_uart=ReplayUart(self, PORTS["imu"], int(ports["imu"]["baud"]), ports["imu"]["name"]),
            telemetry_uart=ReplayUart(self, PORTS["telemetry"], int(ports["telemetry"]["baud"]),
                                      ports["telemetry"]["name"]),
            encoder=ReplayEncoder(self, int(header["encoder"]["bits"]), int(header["encoder"]["arr"])),
            estop=ReplayPin(self), led=ReplayLed(self, bool(header.get("led", False))), watchdog=ReplayWatchdog(self),
            now_cycles=self.now_cycles, f_cpu_hz=self.f_cpu_hz, can=can)

    def begin(self, section: Section) -> None:
        """Serve this section's recorded results to the calls of the job about to run."""
        self.section = section
        self.produced = {}

    def finish(self) -> dict[int, tuple[list, list]]:
        """After the job: the outputs that differ from the record, by key: (expected, produced)."""
        s = self.section
        self.unused += s.untaken()
        if s.outputs == self.produced:
            return {}
        diff: dict[int, tuple[list, list]] = {}
        for key in s.outputs.keys() | self.produced.keys():
            expected, produced = s.outputs.get(key, []), self.produced.get(key, [])
            if expected != produced:
                diff[key] = (expected, produced)
        return diff

    def stream(self, key: int) -> Stream:
        """The stream of an output key (one per port name)."""
        s = self._by_key.get(key)
        if s is None:
            name = port_name(key)
            s = self.streams.get(name)
            if s is None:
                s = self.streams[name] = Stream(self._sinks.get(name))
            self._by_key[key] = s
        return s

    def account(self, diff: dict[int, tuple[list, list]]) -> None:
        """Add the job's outputs to the streams: the replayed ones, and the recorded ones (the same when no diff)."""
        for key, items in self.produced.items():
            s = self.stream(key)
            data = item_bytes_all(key, items)
            s.produced += data
            s.produced_n += len(items)
            if not diff:  # the same items were recorded
                s.expected += data
                s.expected_n += len(items)
            if len(s.produced) >= _FLUSH_BYTES or len(s.expected) >= _FLUSH_BYTES:
                s.flush()
        if diff:
            for key, items in self.section.outputs.items():
                s = self.stream(key)
                s.expected += item_bytes_all(key, items)
                s.expected_n += len(items)

    def take(self, key: int, default: Any) -> Any:
        """The next recorded result of this call (key: kind << 2 | port); a HalError recorded there is raised."""
        s = self.section
        i = s.find(key)
        if i < 0:
            self.starved += 1
            return self.last.get(key, default)
        s.keys[i] = -1
        value = s.values[i]
        if isinstance(value, HalError):
            raise HalError(str(value))
        self.last[key] = value
        return value

    def put(self, key: int, value: Any) -> None:
        """Keep an output of the replayed firmware."""
        out = self.produced.get(key)
        if out is None:
            self.produced[key] = [value]
        else:
            out.append(value)

    def expected_accept(self, key: int, data: bytes) -> int:
        """How many bytes the recorded port accepted for this write (all, when the record has no such write)."""
        recorded = self.section.outputs.get(key)
        if recorded is not None:
            done = self.produced.get(key)
            i = 0 if done is None else len(done)
            if i < len(recorded):
                accepted, was = recorded[i]
                if was == data or accepted < len(was):
                    return min(int(accepted), len(data))
        return len(data)

    def now_cycles(self) -> int:
        """A recorded clock reading (the job's start when the record has none left)."""
        return int(self.take(_CLOCK_KEY, self.section.start))

    def health(self) -> tuple[int, int]:
        """The recorded kernel deadline health."""
        h = self.take(_HEALTH_KEY, (0, 0))
        return int(h[0]), int(h[1])



def replay_sections(replay: ReplayBoard, sections: Iterator[Section],
                    bodies: dict[int, tuple[Callable[[Job], object], Job]], control_task: int, stop_task: int,
                    stop: Callable[[int], object], on_diff: Callable[[Section, dict[int, tuple[list, list]]], None],
                    progress: Callable[[int], None] | None) -> tuple[int, int]:
    """Run each section's job on its recorded inputs, compare and account its outputs; (jobs run, last start).

    `stop(start)` runs the stop path's section; `on_diff(section, diff)` is told of each diverging job
    (`replay.last_control` is then the start of the latest job of `control_task`); `progress(start)` is
    called every 8192 jobs.
    """
    jobs, last = 0, 0
    for section in sections:
        replay.begin(section)
        tid = section.task_id
        if tid == control_task:
            replay.last_control = section.start
        if tid == stop_task:
            stop(section.start)
        else:
            body, job = bodies[tid]
            job.release = job.ready = job.start = section.start
            job.index = section.index
            body(job)
        jobs += 1
        diff = replay.finish()
        replay.account(diff)
        if diff:
            on_diff(section, diff)
        last = section.start
        if progress is not None and jobs % 8192 == 0:
            progress(last)
    return jobs, last
