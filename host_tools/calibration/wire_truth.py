"""Emulation only: the motor link's timing as the emulator saw it, against what `pafp fit` infers from the record.

`pafp emulate ... --capture DIR` stamps each chunk of bytes the emulated motor received with the time the
emulator read it, the stop-bit end of its last byte (`hal.serial.sim_port.arrival_end_times` spaces the
chunk's bytes back from there, as the emulator hands them to the motor model; it also keeps them after the time
its world has reached, which the capture does not hold: after a stall of the emulator a chunk's first bytes may
be dated a little early here), and each reply it sent. The two processes have different clocks: `compare`
aligns them on the frames (the n-th SetCurrent each side saw, the replies by their bytes) and reports, against
`fit_data`'s inference from record.bin alone:

* the commands' arrival after their job, the median taken as the fit's COMMAND_DELAY_S (the clocks' offset is
  unknown: a constant delay is not seen, its spread is);
* for each telemetry sample, whether the request whose reply its current (and its encoder angle, serial mode's
  `--encoder motor`) is matches the one `fit_data` picks, and when that request reached the motor;
* replies lost, and how long after their request's job the firmware read them.

This is a diagnostic of the fit's timing model (docs/calibration.md, "Through serial mode"); the fit never reads
a capture of the emulator. ``python -m host_tools.calibration.wire_truth RUN_DIR CAPTURE_DIR`` prints it as JSON.
"""

from __future__ import annotations

import csv
import json
import sys
from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np

from hal.serial.sim_port import NS_PER_S, arrival_end_times
from host_tools.calibration.fit_data import Experiment, _Wire

__all__ = ["EmulatorLink", "compare", "emulator_link", "true_timing"]

BAUD = 921600  # the motor link's default (`pafp emulate --baud` changes it: pass it on)


@dataclass
class EmulatorLink:
    """What the emulated motor received and sent, on the emulator's clock (s)."""

    t_cmd: np.ndarray  # when each SetCurrent's last byte arrived
    i_cmd: np.ndarray  # its current (A)
    t_req: np.ndarray  # when each feedback request's last byte arrived (the driver's averages reset there)
    replies: list[bytes]  # each feedback reply's frame, in the order sent (the n-th answers the n-th request)


def emulator_link(capture: Path, baud: int = BAUD) -> EmulatorLink:
    """Read an emulator's capture (`pafp emulate --capture`); ValueError (one line) for a missing or damaged one."""
    from protocol import vesc
    from protocol.vesc_values import Values, ValuesSelective

    index = capture / "index.csv"
    try:
        rx, tx = (capture / "motor.rx.bin").read_bytes(), (capture / "motor.tx.bin").read_bytes()
        with index.open(encoding="ascii", newline="") as f:
            rows = [(float(r["t_s"]), r["file"], int(r["offset"]), int(r["bytes"])) for r in csv.DictReader(f)]
    except (OSError, KeyError, ValueError, TypeError) as exc:
        raise ValueError(f"{capture}: not an emulator's capture of the motor ({exc})") from None
    byte_ns = 10.0 * NS_PER_S / baud
    to_motor, from_motor = vesc.Decoder(direction="to-motor"), vesc.Decoder(direction="from-motor")
    t_cmd, i_cmd, t_req, replies = [], [], [], []
    last_end = -1
    for t_s, name, offset, n in rows:
        if name == "motor.rx.bin":
            chunk = rx[offset:offset + n]
            ends = arrival_end_times(n, round(t_s * NS_PER_S), byte_ns, last_end)
            last_end = ends[-1]
            for k in range(n):  # byte by byte: each message at the end of the byte that completes it
                for msg in to_motor.feed(chunk[k:k + 1]):
                    if isinstance(msg, vesc.SetCurrent):
                        t_cmd.append(ends[k] / NS_PER_S)
                        i_cmd.append(msg.current_a)
                    elif isinstance(msg, (vesc.GetValues, vesc.GetValuesSelective)):
                        t_req.append(ends[k] / NS_PER_S)
        elif name == "motor.tx.bin":
            replies.extend(msg.encode() for msg in from_motor.feed(tx[offset:offset + n])
                           if isinstance(msg, (Values, ValuesSelective)))
    return EmulatorLink(np.array(t_cmd), np.array(i_cmd), np.array(t_req), replies)


def _record_replies(record: Path) -> tuple[np.ndarray, list[bytes]]:
    """(the job start that read each feedback reply, the reply's frame) from a run's record.bin, in order."""
    from hal.record.format import Kind
    from hal.record.reader import RecordReader
    from protocol import vesc
    from protocol.vesc_values import Values, ValuesSelective

    reader = RecordReader(record)
    f_cpu = int(reader.header["f_cpu_hz"])
    decoder = vesc.Decoder(direction="from-motor")
    times, frames = [], []
    for s in reader.sections():
        for data in s.inputs.get(Kind.READ << 2, ()):
            for msg in decoder.feed(data):
                if isinstance(msg, (Values, ValuesSelective)):
                    times.append(s.start / f_cpu)
                    frames.append(msg.encode())
    return np.array(times), frames


def _match(read: list[bytes], sent: list[bytes]) -> np.ndarray:
    """For each reply the firmware read, the index of the same reply among those sent (in order; -1: none)."""
    out, j = np.full(len(read), -1), 0
    for k, frame in enumerate(read):
        for m in range(j, min(j + 64, len(sent))):  # a reply lost on the way is skipped over
            if sent[m] == frame:
                out[k], j = m, m + 1
                break
    return out


@dataclass
class _Aligned:
    """A serial run's record and its emulator's capture on the run's clock (`_align`)."""

    exp: Experiment  # `fit_data`'s inference from the record alone
    w: _Wire
    link: EmulatorLink
    shift: int  # the emulator's index of the record's first SetCurrent
    delay: np.ndarray  # per command: its arrival minus its job's start (s, the clocks' offset included)
    offset: float  # the clocks' offset (s), the median command taken as arriving COMMAND_DELAY_S after its job
    t_reply: np.ndarray  # per reply read: the start of the job that read it (s)
    read: list[bytes]  # those replies' frames
    sent: np.ndarray  # per reply read: its index among the replies the emulator sent (-1: none matched)
    match: np.ndarray  # per reply read: the request it answers, in the fit's numbering (-1: none matched)
    t_req: np.ndarray  # when each request reached the motor, on the run's clock (s)
    current: np.ndarray  # per sample: the request whose reply its current really is
    angle: np.ndarray  # per sample: the request whose reply its encoder angle really is


def _align(run_dir: Path, capture: Path, baud: int) -> _Aligned:
    """Align an emulator's capture with a serial run's record on the frames; ValueError if they do not match."""
    from host_tools.calibration.fit_data import COMMAND_DELAY_S, _wire, load_experiment
    from host_tools.recording import RECORD_NAME

    exp = load_experiment(run_dir)
    w = _wire(run_dir / RECORD_NAME)
    link = emulator_link(capture, baud)
    n = len(w.t_cmd)
    shift = next((k for k in range(min(64, len(link.i_cmd) - n + 1))
                  if np.allclose(link.i_cmd[k:k + n], w.i_cmd, atol=1e-3)), None)
    if shift is None:
        raise ValueError(f"{capture}: its SetCurrent commands are not the run's ({run_dir}): not the same run?")
    delay = link.t_cmd[shift:shift + n] - w.t_cmd
    offset = float(np.median(delay)) - COMMAND_DELAY_S  # the clocks' offset, taking the fit's median delay as right
    t_reply, read = _record_replies(run_dir / RECORD_NAME)
    # the emulator numbers the requests it received, the fit those the record shows sent: the same from the first
    # matched command on when none is lost
    first = int(np.searchsorted(link.t_req, link.t_cmd[shift]))
    sent = _match(read, link.replies)  # per reply read: its index among the replies sent (-1: none matched)
    match = np.where(sent >= first, sent - first, -1)  # the request it answers, in the fit's numbering
    t_req = link.t_req[first:] - offset  # on the run's clock

    def truth(reply: np.ndarray) -> np.ndarray:
        return np.where(reply >= 0, match[np.maximum(reply, 0)], -1)

    current = truth(np.searchsorted(t_reply, exp.t, side="right") - 1)
    t_enc = w.t_enc[np.maximum(np.searchsorted(w.t_enc, exp.t, side="right") - 1, 0)]
    angle = truth(np.searchsorted(t_reply, t_enc, side="left") - 1)
    return _Aligned(exp, w, link, shift, delay, offset, t_reply, read, sent, match, t_req, current, angle)


def true_timing(run_dir: Path, capture: Path, baud: int = BAUD) -> Experiment:
    """Emulation only: the run's `Experiment` with the emulator's timing in place of the inferred one: each command
    arriving when the emulated motor received it, each request likewise, and each sample carrying the replies it
    really carried. `fit_plant` on it tells whether the link's per-frame timing is what the fit gets wrong."""
    from host_tools.calibration.fit_data import COMMAND_DELAY_S

    a = _align(run_dir, capture, baud)
    n = len(a.w.t_cmd)
    arrival = a.link.t_cmd[a.shift:a.shift + n] - a.offset
    # `simulate` has a command act COMMAND_DELAY_S after its time: its time is its true arrival less that
    return replace(a.exp, t_cmd=arrival - COMMAND_DELAY_S, t_req=a.t_req, req_of=a.current,
                   angle_req_of=a.angle if a.exp.angle_from_reply else None)


def compare(run_dir: Path, capture: Path, baud: int = BAUD) -> dict:
    """The emulator's truth against `fit_data`'s inference for a serial run (see the module's docstring)."""
    a = _align(run_dir, capture, baud)
    exp, w, link, t_req, match, t_reply, read = a.exp, a.w, a.link, a.t_req, a.match, a.t_reply, a.read
    n, delay, offset, current, angle = len(w.t_cmd), a.delay, a.offset, a.current, a.angle
    sent = a.sent
    inferred_angle = exp.angle_req_of if exp.angle_req_of is not None else exp.req_of

    def agreement(true: np.ndarray, inferred: np.ndarray) -> dict:
        ok = (true >= 0) & (inferred >= 0) & (true < len(t_req)) & (inferred < len(w.t_req))
        if not ok.any():
            return {"samples": 0}
        error_ms = np.abs(t_req[true[ok]] - w.t_req[inferred[ok]]) * 1e3
        return {"samples": int(ok.sum()), "same_request": round(float(np.mean(true[ok] == inferred[ok])), 5),
                "request_time_error_ms": {"p50": round(float(np.percentile(error_ms, 50)), 4),
                                          "p99": round(float(np.percentile(error_ms, 99)), 4),
                                          "max": round(float(error_ms.max()), 4)}}

    spread = (delay - offset) * 1e3
    answered = match >= 0
    read_after = (t_reply[answered] - w.t_req_job[np.minimum(match[answered], len(w.t_req_job) - 1)]) * 1e3
    return {
        "commands": {"record": n, "emulator": int(len(link.t_cmd)), "first_matched": int(a.shift),
                     "arrival_after_job_ms": {p: round(float(np.percentile(spread, q)), 4)
                                              for p, q in (("p1", 1), ("p50", 50), ("p90", 90), ("p99", 99),
                                                           ("p99.9", 99.9))},
                     "arrival_after_job_ms_max": round(float(spread.max()), 4)},
        "requests": {"record": int(len(w.t_req)), "emulator": int(len(link.t_req))},
        "replies": {"sent": len(link.replies), "read": len(read), "read_unmatched": int(np.sum(sent < 0)),
                    "never_read": len(link.replies) - int(np.sum(sent >= 0)),
                    "read_after_request_job_ms": {p: round(float(np.percentile(read_after, q)), 3)
                                                  for p, q in (("p50", 50), ("p90", 90), ("p99", 99), ("max", 100))}},
        "current": agreement(current, exp.req_of),
        "angle": agreement(angle, inferred_angle),
    }


def main(argv: list[str] | None = None) -> int:
    """``RUN_DIR CAPTURE_DIR [BAUD]``: print `compare` as JSON; 2 with one line for bad input."""
    args = sys.argv[1:] if argv is None else argv
    if len(args) not in (2, 3):
        print("usage: python -m host_tools.calibration.wire_truth RUN_DIR CAPTURE_DIR [BAUD]", file=sys.stderr)
        return 2
    try:
        baud = int(args[2]) if len(args) == 3 else BAUD
        if not 1 <= baud <= 20_000_000:
            raise ValueError(f"BAUD {baud} out of range 1..20000000")
        print(json.dumps(compare(Path(args[0]), Path(args[1]), baud), indent=1))
    except ValueError as exc:  # RecordError and load_experiment's refusals are ValueErrors
        print(f"wire_truth: {exc}", file=sys.stderr)
        return 2
    return 0


if __name__ == "__main__":
    sys.exit(main())
