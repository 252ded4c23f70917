"""`pafp fit`'s data: what a bench measured in a run directory, never the emulator's truth.

From record.bin's motor port: the current commands the firmware sent (each at its job's time, later when a late
reply shows its write arrived late: `_late_commands`, `date_within`), the feedback requests that followed them and
the jobs whose reads brought a reply; from telemetry.csv, over the span the supervisor was in RUN (from the foot's
first rest when it swung up from a stop: `_swing_up`): the encoder angle, the IMU pitch and the motor's measured
current (`load_experiment`; each reply's truncated reading taken at the middle of what it allows: `reading_mean`)."""

from __future__ import annotations

import csv
import math
from dataclasses import dataclass, field, replace
from pathlib import Path

import numpy as np

from hal.record.format import Kind
from hal.record.reader import RecordReader
from host_tools.recording import RECORD_NAME, read_record_header
from host_tools.reports.run_files import check_same_run

__all__ = ["COMMAND_DELAY_S", "CURRENT_FIELD", "EXOGENOUS", "STALL_BOUND_S", "WINDOW_S", "Experiment",
           "encoder_velocity", "load_experiment", "reading_mean"]

WINDOW_S = 0.25  # each simulated window starts from the measured state (docs/calibration.md: why this short)
# a simulation window whose writes' arrivals the record leaves unknown by more than one and a half motor periods on
# average (a stall: docs/calibration.md, "Stalled stretches") is left out of the fit (`Experiment.stalled`): which
# command acted when is then unknown by more than a command, and the fit's linearised timing term does not hold.
# Chosen on eleven pty recordings: above every window's mean (0.6-1.4 ms) of the ten that did not stall throughout
# but one; 1 ms left out 6-17 % of four of them and moved one's damping out of its interval
STALL_BOUND_S = 1.5e-3
# the sysid experiment's reference and excitation (firmware/control/sysid.py publishes them): functions of time only
EXOGENOUS = ("sysid_target_deg", "sysid_excitation_a")


@dataclass
class Experiment:
    """What the bench measured: commands (time, A, brake) and samples (time, encoder, IMU, current)."""

    t_cmd: np.ndarray  # each command's job start (s), later by what the replies tell of its arrival (`_late_commands`)
    i_cmd: np.ndarray
    t: np.ndarray
    angle: np.ndarray
    imu: np.ndarray
    current: np.ndarray
    source: str
    vel: np.ndarray  # the encoder angle's velocity (`encoder_velocity`)
    t_req: np.ndarray  # when each feedback request reached the motor at COMMAND_DELAY_S (the averages reset there)
    req_of: np.ndarray  # per sample: the request whose reply its current is (index into t_req; -1: none yet)
    angle_from_reply: bool = False  # the encoder angle is the motor reply's position (serial mode's `--encoder motor`)
    # per sample: the request whose reply's position the encoder angle is (None: the same as req_of). The encoder
    # task opens each period, before the motor task reads that period's reply: its angle is one reply older
    angle_req_of: np.ndarray | None = None
    # per command: (earliest, latest) its write may have reached the motor, relative to its dated arrival, as far as
    # the record bounds it (s, `arrival_bounds`; None: the timing is exact, the virtual bench); per request: its
    # write's command
    bounds: np.ndarray | None = None
    req_cmd: np.ndarray | None = None
    # per sample: how far above its encoder reading a simulation window starting there starts (rad; None: 0). The
    # reading places the foot only to its count: `fit_consider.stuck_starts_term` draws it within the count
    start_shift: np.ndarray | None = None
    # the experiment's own signals, the same whatever the bench does (telemetry's `EXOGENOUS` columns, when the
    # controller published them): {name: value at each time of t_exo}, the adequacy check's inputs in closed loop
    t_exo: np.ndarray | None = None
    exogenous: dict[str, np.ndarray] | None = None

    def interleave(self, every: int, window_s: float = 4 * WINDOW_S,
                   drop: np.ndarray | None = None) -> tuple[Experiment, Experiment]:
        """(the fitting part, the held-out part): every `every`-th stretch of window_s is held out; the samples
        `drop` marks (`stalled`) are in neither.

        Stretches are whole numbers of simulation windows, so each is simulated from its own start."""
        k = ((self.t - self.t[0]) // window_s).astype(int)
        held = (k % every) == every - 1
        keep = np.ones(len(self.t), dtype=bool) if drop is None else ~drop
        return self._select(~held & keep), self._select(held & keep)

    def stalled(self, bound_s: float = STALL_BOUND_S) -> np.ndarray:
        """Per sample: whether its simulation window (WINDOW_S from the first sample, as `interleave` cuts them) is
        a stall's: its writes' arrival windows (`bounds`) are wider than bound_s on average. All False when the
        timing is exact (the virtual bench)."""
        out = np.zeros(len(self.t), dtype=bool)
        if self.bounds is None or len(self.t) == 0:
            return out
        k = ((self.t - self.t[0]) // WINDOW_S).astype(int)
        kc = np.floor((self.t_cmd - self.t[0]) / WINDOW_S).astype(int)
        inside = (kc >= 0) & (kc <= k[-1])
        width = (self.bounds[:, 1] - self.bounds[:, 0])[inside]
        count = np.bincount(kc[inside], minlength=k[-1] + 1)
        wide = np.bincount(kc[inside], width, minlength=k[-1] + 1) > bound_s * np.maximum(count, 1)
        return wide[k]

    def _select(self, keep: np.ndarray) -> Experiment:
        """The samples `keep` marks (every per-sample field), the commands and requests all kept."""
        def rows(a: np.ndarray | None) -> np.ndarray | None:
            return None if a is None else a[keep]

        return replace(self, t=self.t[keep], angle=self.angle[keep], imu=self.imu[keep], current=self.current[keep],
                       vel=self.vel[keep], req_of=self.req_of[keep], angle_req_of=rows(self.angle_req_of),
                       start_shift=rows(self.start_shift))

    def span(self, t0: float, t1: float) -> Experiment:
        """The part between t0 and t1 (s)."""
        k = (self.t >= t0) & (self.t < t1)
        c = (self.t_cmd >= t0 - 0.01) & (self.t_cmd < t1)
        # the commands kept are a run of them: a request's command index moves by the first one's (-1: not kept)
        first = int(np.argmax(c)) if c.any() else 0
        req_cmd = None if self.req_cmd is None else np.where(
            (self.req_cmd >= first) & (self.req_cmd < first + int(c.sum())), self.req_cmd - first, -1)
        return replace(self._select(k), t_cmd=self.t_cmd[c], i_cmd=self.i_cmd[c],
                       bounds=None if self.bounds is None else self.bounds[c], req_cmd=req_cmd)

    def shifted(self, delay: np.ndarray) -> Experiment:
        """The same experiment with each write (a command and the request that follows it) reaching the motor
        delay[c] (s, per command) later; the link keeps the order of the writes."""
        t_cmd = np.maximum.accumulate(self.t_cmd + delay)
        t_req = self.t_req
        if self.req_cmd is not None:
            t_req = np.maximum.accumulate(self.t_req + np.where(self.req_cmd >= 0, delay[self.req_cmd], 0.0))
        return replace(self, t_cmd=t_cmd, t_req=t_req)


def encoder_velocity(t: np.ndarray, angle: np.ndarray) -> np.ndarray:
    """The encoder angle's velocity: a Savitzky-Golay derivative over about 30 ms (the counts' steps smoothed)."""
    if len(t) < 17:
        return np.zeros_like(t)
    from scipy.signal import savgol_filter

    return savgol_filter(angle, 15, 2, deriv=1, delta=float(np.median(np.diff(t))))


COMMAND_DELAY_S = 1.5e-4  # a command reaches the motor this long after its job starts (frame at 921600 baud)
_COMMAND_FRAME_BYTES = 10  # a SetCurrent frame: start, length, id, 4 bytes, CRC, end


@dataclass
class _Wire:
    """What the motor port carried: the current commands, the feedback requests and when replies came in."""

    t_cmd: np.ndarray  # job start of each SetCurrent (s)
    i_cmd: np.ndarray  # its current (A)
    t_req: np.ndarray  # when each feedback request reached the motor at COMMAND_DELAY_S (s)
    t_req_job: np.ndarray  # the job start that sent it (s)
    t_reply: np.ndarray  # per feedback reply read: the start of the job whose read brought it (s)
    t_enc: np.ndarray  # the encoder task's job starts (s): each period's first job, before the motor task's
    t_motor: np.ndarray = field(default_factory=lambda: np.zeros(0))  # the motor task's job starts (s)
    reply_bytes: np.ndarray = field(default_factory=lambda: np.zeros(0))  # per reply read: its frame's length
    req_cmd: np.ndarray = field(default_factory=lambda: np.zeros(0, dtype=int))  # per request: its write's command
    baud: float = 921600.0  # the motor link's


def _wire(record: Path) -> _Wire:
    """The motor port's traffic in a record, up to the first brake or stop.

    A write is the command frame then (usually) a feedback request: the request reaches the motor
    COMMAND_DELAY_S plus its own frame's wire time after the job's start (`simulate` moves it by a fitted
    `command_delay_s`'s difference); the driver's averages (``avg_iq``) reset there. A reply is the firmware's
    from the job whose read decoded it.
    """
    from protocol import vesc
    from protocol.vesc_values import Values, ValuesSelective

    reader = RecordReader(record)
    f_cpu = int(reader.header["f_cpu_hz"])
    baud = float(reader.header.get("ports", {}).get("motor", {}).get("baud", 921600))
    to_motor, from_motor = vesc.Decoder(direction="to-motor"), vesc.Decoder(direction="from-motor")
    times: list[float] = []  # the _Wire's fields, as they are read
    currents: list[float] = []
    t_req: list[float] = []
    t_req_job: list[float] = []
    t_reply: list[float] = []
    t_enc: list[float] = []
    t_motor: list[float] = []
    reply_bytes: list[int] = []
    req_cmd: list[int] = []
    write_key, read_key = Kind.WRITE << 2, Kind.READ << 2
    tasks = list(reader.header.get("tasks", ()))
    encoder_task = tasks.index("encoder") if "encoder" in tasks else -1
    motor_task = tasks.index("motor") if "motor" in tasks else -1

    def wire() -> _Wire:
        return _Wire(np.array(times), np.array(currents), np.array(t_req), np.array(t_req_job), np.array(t_reply),
                     np.array(t_enc), np.array(t_motor), np.array(reply_bytes), np.array(req_cmd, dtype=int), baud)

    for s in reader.sections():
        t = s.start / f_cpu
        if s.task_id == encoder_task:
            t_enc.append(t)
        elif s.task_id == motor_task:
            t_motor.append(t)
        for data in s.inputs.get(read_key, ()):
            for m in from_motor.feed(data):
                if isinstance(m, (Values, ValuesSelective)):
                    t_reply.append(t)
                    reply_bytes.append(len(m.encode()))
        for accepted, data in s.outputs.get(write_key, ()):
            sent = data[:accepted]
            for msg in to_motor.feed(sent):
                if isinstance(msg, vesc.SetCurrent):
                    times.append(t)
                    currents.append(msg.current_a)
                elif isinstance(msg, (vesc.GetValues, vesc.GetValuesSelective)) and times and times[-1] == t:
                    frame = len(sent) - _COMMAND_FRAME_BYTES  # the request's frame follows the command's
                    t_req.append(t + COMMAND_DELAY_S + 10.0 * max(frame, 0) / baud)
                    t_req_job.append(t)
                    req_cmd.append(len(times) - 1)
                elif isinstance(msg, vesc.SetCurrentBrake):
                    return wire()
    return wire()


def _reply_requests(t: np.ndarray, w: _Wire) -> np.ndarray:
    """Per sample: the request the current it carries answers (-1: none). A sample shows the last reply the
    firmware read at or before it; which request that reply answers: `_reply_answers`."""
    return _answered(np.searchsorted(w.t_reply, t, side="right") - 1, w)


def _angle_requests(t: np.ndarray, w: _Wire) -> np.ndarray:
    """Per sample: the request whose reply's position its encoder angle is (serial mode's `--encoder motor`).

    The encoder task opens each period and reads the position of the last reply read before it: the one the
    motor task read in an earlier period, not the reply of the sample's own period that its current is."""
    if len(w.t_enc) == 0:
        return _reply_requests(t, w)
    t_enc = w.t_enc[np.maximum(np.searchsorted(w.t_enc, t, side="right") - 1, 0)]
    return _answered(np.searchsorted(w.t_reply, t_enc, side="left") - 1, w)


LOST_AFTER_S = 0.05  # replies behind their requests this long on end: the oldest request waiting lost its reply


def _answered(reply: np.ndarray, w: _Wire) -> np.ndarray:
    """The request each reply index (into w.t_reply; -1: none) answers (-1: none)."""
    answers = _reply_answers(w.t_reply, w.t_req_job)
    return np.where(reply >= 0, answers[np.maximum(reply, 0)], -1) if len(answers) else np.full(len(reply), -1)


def _reply_answers(t_reply: np.ndarray, t_req_job: np.ndarray) -> np.ndarray:
    """Per reply read (the job start that read it): the request it answers (index into t_req_job; -1: none).

    Replies come back in the order of their requests, so the n-th reply read answers the n-th request sent, also
    when a stalled link or emulator brings several in one read, two or more periods late (through a pty 7 to 26 %
    of replies were read later than the next period; taking the last request sent before the reading job instead
    was right for 75 to 94 % of them, counting for all: the emulator's truth, docs/calibration.md). A reply that
    never came (lost on the wire) would shift every later one by a request: when requests have waited for their
    replies for LOST_AFTER_S on end, the oldest one waiting is taken as lost. A link that catches up undoes a
    wrong skip: a reply read with no request waiting is not matched (-1).
    """
    out = np.full(len(t_reply), -1)
    j = 0  # the oldest request not yet answered
    behind_since = -1.0
    for i, t in enumerate(t_reply):
        sent = int(np.searchsorted(t_req_job, t, side="left"))  # requests sent before the job that read it
        if j < sent:
            out[i] = j
            j += 1
        if j < sent:  # requests still wait for their replies
            if behind_since < 0.0:
                behind_since = float(t)
            elif t - behind_since > LOST_AFTER_S:
                j, behind_since = j + 1, -1.0
        else:
            behind_since = -1.0
    return out


# how long after its last byte's stop bit a reply may still not be readable by the firmware: the far end's write
# granularity (`pafp emulate` writes what has ended each time its loop wakes, at most 1 ms apart; a USB adapter's
# latency timer on a real bench). 0.5 ms: a short reply read one job late then dates nothing (its bound falls before
# the fit's own arrival), only one that skipped two jobs or more; chosen on one recording's arrival errors against
# the emulator's capture (0.25 ms dated 28 % of its commands, many too late: docs/calibration.md)
LINK_READ_LATENCY_S = 5e-4


def _late_commands(w: _Wire) -> np.ndarray:
    """Per command: how much later than COMMAND_DELAY_S after its job it reached the motor, as far as the replies
    tell (s, >= 0).

    A command and its feedback request leave in one write, and the motor answers the request as it arrives. When
    the reply was not read by the motor task's first job after the write but later, although the reply before it
    had been read (the motor's UART was free), the reply's last byte had not ended LINK_READ_LATENCY_S before that
    skipped job: the request, and the command before it, arrived no sooner than the skipped job less the reply's
    wire time and that latency. A stalled host or emulator delays a write's arrival by up to a few ms that way
    (docs/calibration.md, "Through serial mode"); the record shows it only through the late reply.
    """
    late = np.zeros(len(w.t_cmd))
    if len(w.t_motor) == 0 or len(w.req_cmd) != len(w.t_req) or len(w.reply_bytes) != len(w.t_reply):
        return late
    answers = _reply_answers(w.t_reply, w.t_req_job)
    skipped = np.searchsorted(w.t_motor, w.t_reply, side="left") - 1  # the motor job before the one that read it
    for i, q in enumerate(answers):
        k = int(skipped[i])
        if q < 0 or k < 0 or w.t_motor[k] <= w.t_req_job[q]:
            continue  # read by the first motor job after its write: no bound
        if i > 0 and w.t_reply[i - 1] > w.t_motor[k]:
            continue  # the reply before it was still on the wire then: it may have waited behind that one
        frame = 10.0 * float(w.reply_bytes[i]) / w.baud
        earliest = float(w.t_motor[k]) - frame - LINK_READ_LATENCY_S
        c = int(w.req_cmd[q])
        late[c] = max(late[c], earliest - float(w.t_req[q]))  # the request's frame after the command's
    # the link keeps the order of the bytes: a write does not arrive before the one written before it has
    frame = 10.0 * _COMMAND_FRAME_BYTES / w.baud
    req_of_cmd = np.full(len(late), -1)
    req_of_cmd[w.req_cmd] = np.arange(len(w.req_cmd))
    end = -math.inf  # when the previous write's last frame arrived (s)
    for c in range(len(late)):
        late[c] = max(late[c], end + frame - (float(w.t_cmd[c]) + COMMAND_DELAY_S))
        q = int(req_of_cmd[c])
        end = float(w.t_req[q]) + late[c] if q >= 0 else float(w.t_cmd[c]) + COMMAND_DELAY_S + late[c]
    return late


def arrival_bounds(w: _Wire, late: np.ndarray) -> np.ndarray:
    """Per command: (earliest, latest) its write may have reached the motor, as far as the record tells, relative to
    its dated arrival (COMMAND_DELAY_S plus `late` after its job) (s; shape (n, 2), earliest <= 0 <= latest).

    Earliest: COMMAND_DELAY_S after its job (its frame's wire time), `late` earlier than the dating: that a late
    reply dates a write is an inference on the link's read latency (`_late_commands`), and after a stall of the
    far end it dated some writes 1 to 3 ms too late (docs/calibration.md, "Late writes"); not a bound.

    Its request follows it in the same write and the motor answers the request as it arrives, so the reply's last
    byte ended no later than the start of the job that read it: the write arrived no later than that less the
    reply's wire time. The link keeps the order of the writes, so a write arrived no later than the next one's
    bound either. A write with no bound (its reply never read, the last ones) takes the median slack. Through a pty
    the record leaves most writes a slack of about 0.6 ms (a reply read by the next 1 ms job) of which the
    emulator's capture shows most used by 0.1 ms, a few by 0.8-1 ms (docs/calibration.md, "Late writes").
    """
    n = len(w.t_cmd)
    upper = np.full(n, math.inf)
    if n == 0 or len(w.req_cmd) != len(w.t_req) or len(w.reply_bytes) != len(w.t_reply):
        return np.zeros((n, 2))
    answers = _reply_answers(w.t_reply, w.t_req_job)
    for i, q in enumerate(answers):
        if q < 0:
            continue
        c = int(w.req_cmd[q])
        upper[c] = min(upper[c], float(w.t_reply[i]) - 10.0 * float(w.reply_bytes[i]) / w.baud)
    upper = np.minimum.accumulate(upper[::-1])[::-1]  # no later than the next write's bound
    slack = upper - (w.t_cmd + COMMAND_DELAY_S + late)
    known = np.isfinite(slack)
    fill = float(np.median(slack[known])) if known.any() else 0.0
    return np.column_stack([-late, np.clip(np.where(known, slack, fill), 0.0, None)])


def date_within(w: _Wire, late: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(late, bounds): each write `_late_commands` dates late moved to the middle of the window the record leaves it
    (from COMMAND_DELAY_S after its job to its latest, `arrival_bounds`) when that is sooner; the bounds relative to
    the new dating.

    A late reply's dating is an inference on the link's read latency, not a bound: after a stall of the far end it
    put writes up to several ms after the emulator's capture shows them arriving (docs/calibration.md, "Late
    writes"). The window's middle is the dating with the least worst error when the arrival may be anywhere in it;
    against the captures of eleven pty recordings it lowered the arrival error's RMS from 0.35 to 0.29 ms."""
    b = arrival_bounds(w, late)
    latest = late + b[:, 1]
    start = w.t_cmd + COMMAND_DELAY_S
    dated = np.where(late > 0.0, np.minimum(late, 0.5 * latest), 0.0)
    dated = np.maximum.accumulate(start + dated) - start  # the link keeps the order of the writes
    return dated, np.column_stack([-dated, np.clip(latest - dated, 0.0, None)])


CURRENT_FIELD = "avg_iq_a"  # the GET_VALUES field the firmware's measured current is (firmware/drivers/motor.py)


def reading_mean(current: np.ndarray) -> np.ndarray:
    """The driver's mean current each reply's reading stands for, in the middle of what the reading allows.

    VESC sends ``int32(value x scale)``, a C cast: truncated toward zero (PROTOCOLS.md A.3; buffer_append_float32 in
    vedderb/bldc buffer.c), 0.01 A steps for the current (`CURRENT_FIELD`'s scale). A reading r != 0 stands for a
    mean within [r, r + 0.01) A away from zero, one of 0 for a mean within (-0.01, 0.01) A: their middles are
    r + sign(r) 0.005 A and 0. Taken as read, every nonzero reading is 0.005 A smaller in magnitude than the driver's
    mean on average, against a current residual of about 0.008 A RMS: on the default 29 s experiment with the
    hand-made plant that bias took the damping +1.2 % and the current lag +1.3 %, out of their intervals (with the
    middles, -0.0 % and +0.3 %: docs/calibration.md, "The reply's current is truncated")."""
    from protocol.vesc_values import FIELDS

    step = 1.0 / float(next(f.scale for f in FIELDS if f.name == CURRENT_FIELD))
    return np.where(np.abs(current) < 0.5 * step, 0.0, current + np.copysign(0.5 * step, current))


def load_experiment(run_dir: Path) -> Experiment:
    """The commands (record.bin) and the measurements (telemetry.csv) of a run, over its RUN span.

    ValueError (one line, naming the file) when a file is missing, damaged or holds too little.
    """
    record, tel = run_dir / RECORD_NAME, run_dir / "telemetry.csv"
    for path in (record, tel):
        if not path.is_file():
            raise ValueError(f"{path}: not found (pafp fit reads a run directory with record.bin and telemetry.csv: "
                             "`pafp run --experiment sysid`, or any serial run)")
    read_record_header(record)  # a damaged or foreign header: one line naming the key, not a KeyError
    w = _wire(record)
    t_cmd, i_cmd = w.t_cmd, w.i_cmd
    cols = ("time_s", "encoder_angle_rad", "imu_pitch_rad", "current_meas_a", "supervisor_state_name")
    rows: list[tuple[float, ...]] = []
    with tel.open(encoding="utf-8", newline="") as f:
        reader = csv.DictReader(f)
        missing = [c for c in cols if c not in (reader.fieldnames or [])]
        if missing:
            raise ValueError(f"{tel}: not a telemetry table (no column {missing[0]!r})")
        exo = [c for c in EXOGENOUS if c in (reader.fieldnames or [])]
        started = False
        for line, r in enumerate(reader, start=2):
            if r["supervisor_state_name"] != "RUN":
                if started:
                    break  # the first RUN span only (a fault ends the experiment)
                continue
            started = True
            try:
                rows.append((float(r["time_s"]), float(r["encoder_angle_rad"]), float(r["imu_pitch_rad"]),
                             float(r["current_meas_a"]), *(float(r[c]) for c in exo)))
            except ValueError:
                raise ValueError(f"{tel}: line {line} is not numeric") from None
    if len(rows) < 100 or len(t_cmd) < 100:
        raise ValueError(f"{run_dir}: too short to fit: {len(rows)} samples in RUN and {len(t_cmd)} current "
                         "commands (at least 100 of each; run `pafp run --experiment sysid`)")
    a = np.array(rows)
    t_exo, exogenous = (a[:, 0], {c: a[:, 4 + k] for k, c in enumerate(exo)}) if exo else (None, None)
    a = a[_swing_up(a[:, 0], a[:, 1]):]
    if len(a) < 100:
        raise ValueError(f"{run_dir}: too short to fit: {len(a)} samples in RUN once the foot came to rest "
                         "(at least 100; run `pafp run --experiment sysid`)")
    check_same_run(run_dir)  # record.bin and telemetry.csv of one run, as its summary.json names them
    from_reply = _summary_field(run_dir, "encoder_source") == "motor"
    # a write that reached the motor late (`_late_commands`): its command and its request both later
    late = _late_commands(w)
    paired = len(w.req_cmd) == len(w.t_req)
    # through serial mode the record bounds each write's arrival only to a window (`arrival_bounds`), and a late
    # write is dated within it (`date_within`); the virtual bench's ports deliver at the modelled wire time, exactly
    # the fit's
    serial = _summary_field(run_dir, "mode") == "serial"
    bounds = None
    if serial and paired:
        late, bounds = date_within(w, late)
    t_req = w.t_req + late[w.req_cmd] if paired else w.t_req
    # the replies' currents at the middle of what each truncated reading allows (`reading_mean`)
    return Experiment(t_cmd + late, i_cmd, a[:, 0], a[:, 1], a[:, 2], reading_mean(a[:, 3]), str(run_dir),
                      encoder_velocity(a[:, 0], a[:, 1]), t_req, _reply_requests(a[:, 0], w), from_reply,
                      _angle_requests(a[:, 0], w) if from_reply else None, bounds,
                      np.array(w.req_cmd, dtype=int) if serial and paired else None, t_exo=t_exo,
                      exogenous=exogenous)


SWING_DEG = 4.0  # a start further than this from where the foot comes to rest is a swing-up (the foot hung on a stop)
SETTLED_S, SETTLED_DEG = 0.05, 0.05  # at rest: the encoder angle moves less than SETTLED_DEG over SETTLED_S


def _swing_up(t: np.ndarray, angle: np.ndarray) -> int:
    """The first sample at which the foot rests after a swing-up at RUN's start; 0 when there was none.

    A foot that hung on its stop before the run (a serial bench whose foot was not set at its zero mark)
    swings to the experiment's centre when RUN begins: tens of degrees in a tenth of a second against the
    current limit, leaving the stop. The fit starts once the foot has come to rest there: over the swing the
    IMU (a lagging sensor) gives the encoder's zero several degrees off (`fit_plant` takes the zero from the
    first 0.2 s it fits), which biased the damping and the Coulomb friction (docs/calibration.md).
    """
    limit = math.radians(SETTLED_DEG)
    for i in range(len(t)):
        j = int(np.searchsorted(t, t[i] + SETTLED_S))
        if j >= len(t):
            return 0
        if float(np.ptp(angle[i:j + 1])) < limit:
            moved = float(np.max(np.abs(angle[:i + 1] - angle[i]))) if i else 0.0
            return i if moved > math.radians(SWING_DEG) else 0
    return 0


def _summary_field(run_dir: Path, key: str) -> str:
    """A run summary's field as text ("" without a summary or the field): ``encoder_source`` (where a serial run's
    encoder angle came from; "" for the virtual bench, whose encoder reads the plant at the job's time), ``mode``
    ("serial" or "virtual"). ValueError (one line) for a damaged summary."""
    import json

    summary = run_dir / "summary.json"
    if not summary.is_file():
        return ""
    try:
        return str(json.loads(summary.read_text(encoding="utf-8")).get(key, ""))
    except (ValueError, AttributeError):
        raise ValueError(f"{summary}: not a run summary (not a JSON object)") from None
