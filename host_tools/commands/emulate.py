"""`pafp emulate`: serve the virtual AK60-6 and/or BNO08x (or the ground sensors' Firmata board) on new ptys or
real serial ports, in wall-clock time.

``pafp emulate motor|imu|bench|ground (--pty | --port DEVICE [--imu-port DEVICE]) [--baud N] [--fixture NAME]
[--seed S] [--duration S]``. ``bench`` serves the motor and the IMU on one shared plant. Before serving it
prints one line per device, ``motor: PATH`` / ``imu: PATH``, and flushes. It then runs until Ctrl-C or
SIGTERM or SIGHUP (or ``--duration``) and exits 0 after one summary line. A port that cannot be opened or a bad
combination of options: one line on stderr, exit 2.

Timing: bytes read from a port are stamped on arrival, the last one ending at the arrival instant and the
others back to back before it at the link's byte time, and handed to the device model; the device's
bytes are written when their stop bit ends (wall clock). The loop sleeps in ``select`` until the next
device event or byte end, at most 1 ms, so output comes in bursts of at most ~1 ms. A real port adds its
own transmission time on top (the bytes are written when they would have ended): prefer a pty for
timing studies.
"""

from __future__ import annotations

import argparse
import math
import os
import select
import signal
import sys
import tty
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from types import FrameType
from typing import TYPE_CHECKING

from hal.serial.sim_port import WallDevices, arrival_end_times
from hal.virtual.bench import FIXTURES
from host_tools.arguments import seed
from host_tools.outdir import check_capture_dir
from host_tools.serial_mode.realtime import RealtimeSection, RealtimeSettings
from host_tools.stop_signals import STOP_SIGNALS
from host_tools.wire_capture import WireCapture

if TYPE_CHECKING:
    from host_tools.serial_mode.can_emulate import WallCanMotor
    from host_tools.serial_mode.served_plant import ServedPlant

HELP = "serve the virtual AK60-6 / BNO08x on a pty or serial port (wall-clock time)"
MAX_SLEEP_S = 0.001
_ROLES = {"motor": ("motor",), "imu": ("imu",), "bench": ("motor", "imu"), "ground": ("ground",)}


class EmulateError(Exception):
    """A problem reported as one line on stderr with exit code 2."""


@dataclass
class Endpoint:
    """One served device: the file descriptor the far end talks through, and its counters."""

    role: str
    fd: int
    path: str
    close: Callable[[], None]
    bytes_in: int = 0
    bytes_out: int = 0
    dropped_out: int = 0
    last_end_ns: int = -1
    failed: str = ""


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """Register the options of `pafp emulate`."""
    parser.add_argument("device", choices=sorted(_ROLES), help="what to serve (bench = motor + imu, one plant)")
    where = parser.add_mutually_exclusive_group(required=True)
    where.add_argument("--pty", action="store_true", help="create a new pty per device and print its path")
    where.add_argument("--port", metavar="DEVICE", help="serve on this serial port (bench: the motor's)")
    where.add_argument("--can", metavar="URL",
                       help="serve the AK60-6 on a CAN bus, can://INTERFACE/CHANNEL?id=N&mode=servo|mit (any "
                            "python-can interface, e.g. socketcan/can0 or udp_multicast/239.74.163.2); with bench, "
                            "the IMU on the same plant goes on a new pty (or --imu-port)")
    parser.add_argument("--imu-port", metavar="DEVICE", help="bench with --port or --can: the IMU's serial port")
    parser.add_argument("--baud", type=int, default=None,
                        help="link baud: the motor's (default 921600), or the IMU's for `imu` or the Firmata "
                             "board's for `ground` (default 115200)")
    parser.add_argument("--fixture", default="suspended", choices=sorted(FIXTURES), help="bench fixture")
    parser.add_argument("--seed", type=seed, default=0, help="seed of the IMU noise and the imperfections (default 0)")
    parser.add_argument("--plant", type=Path, default=None, metavar="FILE",
                        help="plant profile TOML instead of the packaged one (e.g. one `pafp fit` wrote)")
    parser.add_argument("--plant-seed", type=seed, default=None, metavar="N",
                        help="draw the plant from its tolerances around the profile with seed N")
    parser.add_argument("--ideal", action="append", default=[], metavar="NAME",
                        help="switch one imperfection of the real bench off (as `pafp run --ideal`), or all")
    parser.add_argument("--motor", default=None, metavar="NAME",
                        help="serve this catalogue motor (profiles/motors/ name or a motor profile): its Kt, ratio, "
                             "pole pairs, peak current, thermal model and CAN ranges (default ak60_6)")
    parser.add_argument("--profile", type=Path, default=None, metavar="DESIGN.toml",
                        help="serve a design profile's [design] (profiles/designs/): its motor, belt and spring")
    parser.add_argument("--status-hz", type=float, default=500.0, metavar="HZ",
                        help="--can servo mode: the status frame's rate, as set in the drive (1..500, default 500)")
    parser.add_argument("--current-convention", default="catalogue", choices=("catalogue", "rms", "peak"),
                        help="--can servo mode: what an amp on the wire is: the catalogue's (torque = the maker's Kt "
                             "x I, default), the RMS phase current (Kt x sqrt(3/2): opensourceleg's AK80-9 0.115 "
                             "N m/A) or the peak phase current (Kt x sqrt(3)/2); docs/hardware.md")
    parser.add_argument("--duration", type=float, default=None, metavar="S",
                        help="stop after S seconds (default, or inf: run until Ctrl-C or SIGTERM)")
    parser.add_argument("--no-realtime", action="store_true",
                        help="do not ask the OS for SCHED_FIFO while serving (granted to root, CAP_SYS_NICE or an "
                             "RLIMIT_RTPRIO: a busy host then delays the replies less; docs/serial_mode.md)")
    parser.add_argument("--capture", type=Path, default=None, metavar="DIR",
                        help="write the raw bytes each device received (<role>.rx.bin) and sent (<role>.tx.bin) "
                             "with a time index into DIR (docs/serial_mode.md)")


def _open_pty(role: str) -> Endpoint:
    """A new pty pair in raw mode; we keep both ends (the slave stays open so a client may come and go)."""
    master, slave = os.openpty()
    tty.setraw(slave)
    os.set_blocking(master, False)

    def close() -> None:
        """Close both ends of the pty."""
        os.close(master)
        os.close(slave)

    return Endpoint(role, master, os.ttyname(slave), close)


def _open_port(role: str, path: str, baud: int) -> Endpoint:
    """A real serial port through pyserial (8N1, non-blocking file descriptor)."""
    import serial

    try:
        port = serial.Serial(path, baudrate=baud, timeout=0, write_timeout=0)
        fd = port.fileno()
    except (serial.SerialException, OSError, ValueError) as exc:
        raise EmulateError(f"cannot open {role} port {path!r}: {exc}") from None
    os.set_blocking(fd, False)
    return Endpoint(role, fd, path, port.close)


def _bauds(args: argparse.Namespace) -> dict[str, int]:
    if args.baud is None:
        return {}
    if not 1 <= args.baud <= 20_000_000:
        raise EmulateError(f"--baud {args.baud} out of range: 1..20000000")
    return {args.device if args.device in ("imu", "ground") else "motor": args.baud}


def _endpoints(args: argparse.Namespace, devices: WallDevices) -> list[Endpoint]:
    roles = _ROLES[args.device]
    if args.pty:
        return [_open_pty(role) for role in roles]
    paths = {roles[0]: args.port}
    if args.device == "bench":
        paths["imu"] = args.imu_port
    opened: list[Endpoint] = []
    try:
        for role, path in paths.items():
            opened.append(_open_port(role, path, devices.uarts[role].baud))
    except EmulateError:
        for ep in opened:
            ep.close()
        raise
    return opened


def _check(args: argparse.Namespace) -> None:
    if args.imu_port and not (args.device == "bench" and (args.port or getattr(args, "can", None))):
        raise EmulateError("--imu-port is only for `bench` with --port or --can")
    if args.device == "bench" and args.port and not args.imu_port:
        raise EmulateError("`bench --port MOTOR_DEVICE` also needs --imu-port IMU_DEVICE")
    if args.duration is not None and not args.duration > 0:
        raise EmulateError(f"--duration {args.duration} out of range: > 0 seconds (inf: until stopped)")
    if args.duration is not None and not math.isfinite(args.duration * 1e9):
        args.duration = None  # inf, or so long that its nanoseconds overflow: until stopped


def _run_can(args: argparse.Namespace) -> int:
    """`emulate motor|bench --can URL` (host_tools/serial_mode/can_emulate.py); bench: the IMU on a new pty, or on
    --imu-port, on the motor's plant."""
    import time

    from hal.errors import HalError
    from hal.pycan import open_can, parse_can_url
    from hal.virtual.devices.ak60_can import Ak60CanConfig
    from host_tools.serial_mode.can_emulate import WallCanMotor, deepen_receive_buffer

    stop: list[str] = []

    def on_signal(signum: int, frame: FrameType | None) -> None:
        """Ask the serving loop to stop."""
        stop.append(signal.Signals(signum).name)

    previous = {s: signal.signal(s, on_signal) for s in STOP_SIGNALS}
    port, capture, devices, endpoints = None, None, None, []
    try:
        try:
            if args.device not in ("motor", "bench"):
                raise EmulateError(f"--can serves the motor, not `{args.device}`: `motor --can URL`, or "
                                   "`bench --can URL` with the IMU on a pty")
            _check(args)
            url = parse_can_url(args.can, "--can")
            if not 1.0 <= args.status_hz <= 500.0:
                raise EmulateError(f"--status-hz {args.status_hz} out of range: 1..500 Hz (the drive's upload "
                                   "rates, CubeMars manual 5.2.1)")
            served = _served(args)
            t0 = time.perf_counter_ns()
            clock_ns: Callable[[], int] = lambda: time.perf_counter_ns() - t0  # noqa: E731
            if args.device == "bench":
                devices = WallDevices(["imu"], bauds=_bauds(args), fixture=args.fixture, seed=args.seed,
                                      clock_ns=clock_ns, **served.options)
            if args.capture is not None:
                capture = WireCapture(args.capture, lambda: clock_ns() / 1e9, side="device")
            port = open_can(url)
            deepen_receive_buffer(port.bus)
            can_config = Ak60CanConfig(driver_id=url.driver_id, mode=url.mode, limits=served.limits,
                                       status_period_s=1.0 / args.status_hz, current_convention=args.current_convention)
            motor = WallCanMotor(capture.tap_can("motor", port, f"can-{url.mode}") if capture else port, url,
                                 args.fixture, clock_ns, world=devices.world if devices is not None else None,
                                 plant_options=served.options, can_config=can_config)
            served.attach_thermal(motor.device.core.meter)
            if devices is not None:
                if capture is not None:
                    capture.open("imu", "rx", "tx")
                endpoints = ([_open_port("imu", args.imu_port, devices.uarts["imu"].baud)] if args.imu_port
                             else [_open_pty("imu")])
        except (EmulateError, ValueError, HalError, OSError) as exc:
            print(f"pafp emulate: {exc}", file=sys.stderr)
            return 2
        print(f"motor: {args.can}", flush=True)
        for ep in endpoints:
            print(f"{ep.role}: {ep.path}", flush=True)
        try:
            with _realtime(args) as rt:
                if devices is None:
                    motor.serve(stop, args.duration)
                else:
                    _serve(devices, endpoints, stop, args.duration, capture, motor)
        except HalError as exc:
            line = f"pafp emulate: the bus failed ({exc})"
        else:
            why = stop[0] if stop else "duration"
            imu = _summary(devices, endpoints, why) if devices is not None else ""
            line = motor.summary(why) + imu.removeprefix(f"pafp emulate: stopped ({why})") + _granted(rt)
    finally:
        for s, handler in previous.items():
            signal.signal(s, handler)
        for ep in endpoints:
            ep.close()
        if port is not None:
            port.close()
        if capture is not None:
            capture.close()
        if devices is not None:
            devices.close()
    print(line, flush=True)
    return 0


def _served(args: argparse.Namespace) -> ServedPlant:
    """The plant, motor and CAN ranges of --plant, --plant-seed, --ideal, --motor, --profile (served_plant.py)."""
    from host_tools.serial_mode.served_plant import served_plant

    return served_plant(seed=args.seed, plant_seed=getattr(args, "plant_seed", None),
                        plant_file=getattr(args, "plant", None), ideal=tuple(getattr(args, "ideal", ())),
                        motor=getattr(args, "motor", None), profile=getattr(args, "profile", None))


def run(args: argparse.Namespace) -> int:
    """Serve until stopped; print the paths first and a summary line last; 2 on bad options or ports."""
    if getattr(args, "can", None):
        return _run_can(args)
    capture = None
    try:
        _check(args)
        served = _served(args)
        devices = WallDevices(_ROLES[args.device], bauds=_bauds(args), fixture=args.fixture, seed=args.seed,
                              **served.options)
        if devices.motor is not None:
            served.attach_thermal(devices.motor.meter)
        if args.capture is not None:
            check_capture_dir(args.capture)
            capture = WireCapture(args.capture, lambda: devices.now() / 1e9, side="device")
            for role in _ROLES[args.device]:
                capture.open(role, "rx", "tx")
        endpoints = _endpoints(args, devices)
    except (EmulateError, ValueError, OSError) as exc:
        if capture is not None:
            capture.close()
        print(f"pafp emulate: {exc}", file=sys.stderr)
        return 2
    for ep in endpoints:
        print(f"{ep.role}: {ep.path}", flush=True)
    stop: list[str] = []

    def on_signal(signum: int, frame: FrameType | None) -> None:
        """Ask the serving loop to stop."""
        stop.append(signal.Signals(signum).name)

    previous = {s: signal.signal(s, on_signal) for s in STOP_SIGNALS}
    try:
        with _realtime(args) as rt:
            _serve(devices, endpoints, stop, args.duration, capture)
    except OSError as exc:
        if capture is None or capture.error is not exc:
            raise
        from host_tools.outdir import EXIT_WRITE_FAILED, write_failed

        print(write_failed("emulate", exc, f"the capture in {args.capture} holds what was written before; "
                           "serving stopped"), file=sys.stderr)
        return EXIT_WRITE_FAILED
    finally:
        if capture is not None:
            capture.close()
        for s, handler in previous.items():
            signal.signal(s, handler)
        for ep in endpoints:
            ep.close()
        devices.close()
    print(_summary(devices, endpoints, stop[0] if stop else "duration") + _granted(rt), flush=True)
    return 0


def _realtime(args: argparse.Namespace) -> RealtimeSection:
    """SCHED_FIFO for the serving loop, unless --no-realtime (host_tools/serial_mode/realtime.py; undone after): a
    frame that arrives while a busy process holds the core is then taken, and answered, without waiting for the
    scheduler's next turn. The loop sleeps between events; the kernel's RT throttling bounds it when it catches up."""
    wanted = RealtimeSettings.none() if args.no_realtime else RealtimeSettings(gc=False, pin=False, mlock=False,
                                                                                 spin_s=0.0)
    return RealtimeSection(wanted)


def _granted(rt: RealtimeSection) -> str:
    """The summary's last words: whether the loop ran under SCHED_FIFO."""
    return f"; real-time: {rt.granted.get('fifo', 'not requested')}"


def _serve(devices: WallDevices, endpoints: list[Endpoint], stop: list[str], duration_s: float | None,
           capture: WireCapture | None = None, can_motor: WallCanMotor | None = None) -> None:
    """The wall-clock loop: take bytes (and CAN frames) in, let the world catch up, write what has ended, sleep."""
    end_ns = None if duration_s is None else devices.now() + int(duration_s * 1e9)
    by_fd = {ep.fd: ep for ep in endpoints}
    while not stop:
        if can_motor is not None:
            can_motor.step()
        now = devices.now()
        if end_ns is not None and now >= end_ns:
            break
        wake = devices.next_event_ns()
        if can_motor is not None:
            wake = min(wake, can_motor.world_next(), can_motor.bus.next_at())
        for uart in devices.uarts.values():
            if uart.rx_line_busy_until > now:
                wake = min(wake, uart.rx_line_busy_until)
        timeout = min(MAX_SLEEP_S, max(0.0, (wake - now) / 1e9))
        live = [fd for fd, ep in by_fd.items() if not ep.failed]
        readable, _, _ = select.select(live, [], [], timeout)
        now = devices.now()
        for fd in readable:
            data = _take(devices, by_fd[fd], now)
            if capture is not None and data:
                capture.record(by_fd[fd].role, "rx", data, now / 1e9)
        for ep in endpoints:
            data = devices.uarts[ep.role].read()
            if data and not ep.failed:
                written = _give(ep, data)
                if capture is not None:
                    capture.record(ep.role, "tx", data[:written])
        devices.world.commit_plant()  # a quiet spell is integrated as it passes, not by the next command's reply
    _drain(devices, endpoints)
    if can_motor is not None:
        can_motor.drain()


def _drain(devices: WallDevices, endpoints: list[Endpoint], max_reads: int = 64) -> None:
    """At the stop, hand the devices the bytes that had already arrived (at most max_reads reads of each port): a
    client's last commands before it stopped the emulator are handled and counted, whatever the signal interrupted."""
    for ep in endpoints:
        took = 0
        while took < max_reads and not ep.failed and _take(devices, ep, devices.now()):
            took += 1
        if took:
            devices.world.advance_to(ep.last_end_ns)  # up to the last byte's end: they are decoded, nothing after


def _take(devices: WallDevices, ep: Endpoint, now: int) -> bytes:
    """Read what the far end sent and hand it to the device with its arrival times; return the bytes."""
    try:
        data = os.read(ep.fd, 4096)
    except BlockingIOError:
        return b""
    except OSError as exc:
        ep.failed = f"read failed: {exc}"
        return b""
    if not data:
        return b""
    ep.bytes_in += len(data)
    after = max(ep.last_end_ns, devices.world.now)
    ends = arrival_end_times(len(data), now, devices.byte_ns(ep.role), after)
    ep.last_end_ns = ends[-1]
    devices.device(ep.role).on_bytes(data, ends)
    return data


def _give(ep: Endpoint, data: bytes) -> int:
    """Write the device's bytes without blocking; what the far end cannot take is dropped and counted."""
    try:
        written = os.write(ep.fd, data)
    except BlockingIOError:
        written = 0
    except OSError as exc:
        ep.failed = f"write failed: {exc}"
        written = 0
    ep.bytes_out += written
    ep.dropped_out += len(data) - written
    return written


def _summary(devices: WallDevices, endpoints: list[Endpoint], reason: str) -> str:
    """One line: frames in and out per device, errors, and why we stopped."""
    parts = [f"pafp emulate: stopped ({reason})"]
    for ep in endpoints:
        dev = devices.device(ep.role)
        if ep.role == "motor":
            st, ds = dev.stats, dev.decoder.stats  # type: ignore[union-attr]
            errors = ds.crc_errors + ds.bad_end_bytes + ds.short_payloads + ds.unknown_ids
            counts = (f"frames_in={ds.frames} frames_out={st.requests + st.stream_frames} "
                      f"errors={errors} junk_bytes={ds.dropped_bytes}")
        elif ep.role == "ground":
            ds = dev.decoder.stats  # type: ignore[union-attr]
            counts = (f"frames_in={ds.report_analog + ds.sysex} frames_out={dev.messages_sent} "  # type: ignore[union-attr]
                      f"junk_bytes={ds.dropped}")
        else:
            counts = f"frames_in=0 frames_out={dev.frames_sent} ignored_bytes={dev.bytes_ignored}"  # type: ignore[union-attr]
        failed = f" failed='{ep.failed}'" if ep.failed else ""
        parts.append(f"{ep.role}: {counts} bytes_in={ep.bytes_in} bytes_out={ep.bytes_out} "
                     f"dropped_out={ep.dropped_out}{failed}")
    return "; ".join(parts)
