"""`pafp monitor PORT|FILE [--csv OUT] [--plot]`: decode a telemetry stream live.

A FILE (an existing regular file, e.g. a run's telemetry.bin) is decoded to its end; a PORT (device
path or pyserial URL) is read until Ctrl-C, SIGTERM, ``--duration`` or the port vanishing. The view
refreshes at most 5 times a second (on a terminal; otherwise one status line a second).
"""

from __future__ import annotations

import argparse
import os
import signal
import sys
import time
from pathlib import Path
from types import FrameType

from host_tools.arguments import float_in, int_in

HELP = "decode a live telemetry stream (port or file): latest values, rates, losses; --csv, --plot"
REFRESH_S = 0.2


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """Options of `pafp monitor`."""
    parser.add_argument("source", metavar="PORT|FILE", help="serial port / pyserial URL, or a telemetry capture file")
    parser.add_argument("--csv", type=Path, default=None, metavar="OUT", help="write every record to this CSV")
    parser.add_argument("--plot", action="store_true", help="live angle/reference plot (needs a display)")
    parser.add_argument("--baud", type=int_in(1, 20_000_000), default=921600, help="port baud rate (default 921600)")
    parser.add_argument("--duration", type=float_in(0.0, lo_open=True, unit="s"), default=None, metavar="S",
                        help="stop after S seconds")


def _has_display() -> bool:
    return sys.platform in ("win32", "darwin") or bool(os.environ.get("DISPLAY") or os.environ.get("WAYLAND_DISPLAY"))


class _Plot:
    """A live angle/reference plot (interactive matplotlib), or nothing without a display."""

    def __init__(self, enabled: bool) -> None:
        self.ok = enabled and _has_display()
        if enabled and not self.ok:
            print("pafp monitor: no display, --plot ignored", file=sys.stderr)
        self.t: list[float] = []
        self.ref: list[float] = []
        self.ang: list[float] = []
        if self.ok:
            import matplotlib.pyplot as plt

            plt.ion()
            self.plt = plt
            self.fig, self.ax = plt.subplots()
            (self.l_ref,) = self.ax.plot([], [], label="reference (deg)")
            (self.l_ang,) = self.ax.plot([], [], label="fused angle (deg)")
            self.ax.legend(loc="upper right")

    def add(self, records: list) -> None:
        """Keep the last 5000 samples."""
        if not self.ok:
            return
        import math

        for r in records:
            self.t.append(r.seq)
            self.ref.append(math.degrees(r.reference_rad))
            self.ang.append(math.degrees(r.fused_angle_rad))
        del self.t[:-5000], self.ref[:-5000], self.ang[:-5000]

    def draw(self) -> None:
        """Redraw."""
        if not self.ok or not self.t:
            return
        self.l_ref.set_data(self.t, self.ref)
        self.l_ang.set_data(self.t, self.ang)
        self.ax.relim()
        self.ax.autoscale_view()
        self.plt.pause(0.001)


def _reader(source: str, baud: int):  # type: ignore[no-untyped-def]
    """(read() -> bytes | None at end, close(), is_file) for a capture file or a port."""
    if os.path.isfile(source):
        f = open(source, "rb")  # noqa: SIM115 (closed by the returned closer)
        return (lambda: f.read(65536) or None), f.close, True
    import serial

    from hal.serial.protocol_sim import register_sim_handler

    register_sim_handler()
    port = serial.serial_for_url(source, baudrate=baud, timeout=0.05)
    return (lambda: port.read(65536)), port.close, False


def run(args: argparse.Namespace) -> int:
    """Decode until the end of the file (or stop); 0 when done, 1 if the port was lost, 2 if it cannot open."""
    import serial

    from host_tools.serial_mode.monitor import CsvSink, MonitorState, render

    try:
        read, close, is_file = _reader(args.source, args.baud)
    except (serial.SerialException, OSError, ValueError) as exc:
        print(f"pafp monitor: cannot open {args.source!r}: {exc}", file=sys.stderr)
        return 2
    try:
        sink = CsvSink(args.csv) if args.csv else None
    except OSError as exc:
        close()
        print(f"pafp monitor: cannot write {args.csv}: {exc}", file=sys.stderr)
        return 2
    stop: list[str] = []

    def on_signal(signum: int, frame: FrameType | None) -> None:
        """Stop at the next read."""
        stop.append(signal.Signals(signum).name)

    previous = signal.signal(signal.SIGTERM, on_signal)
    state, plot, tty = MonitorState(), _Plot(args.plot), sys.stdout.isatty()
    t0 = last_view = time.monotonic()
    code = 0
    try:
        while not stop:
            if args.duration is not None and time.monotonic() - t0 >= args.duration:
                break
            try:
                data = read()
            except (serial.SerialException, OSError) as exc:
                print(f"pafp monitor: port {args.source!r} lost: {exc}", file=sys.stderr)
                code = 1
                break
            if data is None:
                break
            now = time.monotonic()
            records = state.feed(data, now)
            if sink is not None:
                sink.write(records)
            plot.add(records)
            if not is_file and now - last_view >= (REFRESH_S if tty else 1.0):
                last_view = now
                view = render(state, args.source)
                print("\x1b[H\x1b[J" + view if tty else view.splitlines()[1], flush=True)
                plot.draw()
    except KeyboardInterrupt:
        pass
    finally:
        signal.signal(signal.SIGTERM, previous)
        close()
        if sink is not None:
            sink.close()
    print(f"pafp monitor: {state.summary()}" + (f"; csv {args.csv} ({sink.rows} rows)" if sink else ""), flush=True)
    return code
