"""The plant's run over one simulation window of `pafp fit`'s model (`fit_model.simulate`): the bench's plant driven by
the recorded commands from the window's start, read as the bench reads it (the encoder's angle, the mean current each
reply carries); the IMU's lag and the window's projections are `fit_model`'s. The event loop runs on Python floats
(`Events`: a numpy scalar per access cost most of a simulation's time), the same values, so the same arithmetic; the
module is compiled (setup.py's COMPILED, docs/compiled.md), and calls the plant's methods directly (a bound method
kept in a local would be a Python call from compiled code). Within one fit (`fit_memo.one_fit`) a window's run is
taken from the memo when everything it depends on is the same (`window_key`): a fit asks for it again when only the
IMU's lag or bias moved, or only the backlash in a window whose command never reverses (the rotor never leaves the
teeth: every command passes whole), or only the start of another window (the stuck starts' draws).
"""

from __future__ import annotations

import math
from dataclasses import fields
from typing import Any

import numpy as np

from hal.virtual.plant import Plant, PlantParams, suspended
from host_tools.calibration.fit_data import COMMAND_DELAY_S, Experiment
from host_tools.calibration.fit_gap import GAP_BLEND, GapShare

__all__ = ["Events", "run_plant", "window_key"]


class Events:
    """A recording's commands and requests as one simulation takes them (its command delay, the plant's peak current),
    as Python floats; the recording's arrays that a window's run reads (`keep`)."""

    def __init__(self, exp: Experiment, delay: float, params: PlantParams) -> None:
        self.exp: Experiment = exp
        self.delay: float = delay
        self.peak: float = params.peak_current_a
        self.t_cmd: Any = exp.t_cmd
        self.t_req: Any = exp.t_req + (delay - COMMAND_DELAY_S)
        angle_of = exp.req_of if exp.angle_req_of is None else exp.angle_req_of  # the reply the encoder reads
        self.band: float = GAP_BLEND * float(np.median(np.diff(exp.t_cmd))) if len(exp.t_cmd) > 1 else 1e-3
        self.arrival_times: Any = exp.t_cmd + delay
        self.ts: list[float] = exp.t.tolist()
        self.arrivals: list[float] = self.arrival_times.tolist()
        self.reqs: list[float] = self.t_req.tolist()
        self.amps: list[float] = exp.i_cmd.tolist()
        self.targets: list[float] = np.clip(exp.i_cmd, -self.peak, self.peak).tolist()  # as the plant clamps them
        self.req_of: list[int] = exp.req_of.tolist()
        self.reply_of: list[int] = angle_of.tolist()
        self.measured: list[float] = exp.current.tolist()
        self.keep: tuple[Any, ...] = (exp.t, exp.t_cmd, exp.i_cmd, exp.t_req, exp.req_of, exp.current,
                                      exp.angle_req_of)
        # the commands of each sign before each command: a window whose commands all have one sign never reverses
        signs = np.sign(exp.i_cmd)
        self.positive: Any = np.r_[0, np.cumsum(signs > 0)]
        self.negative: Any = np.r_[0, np.cumsum(signs < 0)]
        self.plant_bits: tuple[object, ...] = tuple(_bits(getattr(params, f.name)) for f in fields(params)
                                                    if f.name != "backlash_deg")

    def acting(self, t0: float) -> int:
        """The command acting at t0 (-1: none yet)."""
        return int(np.searchsorted(self.t_cmd, t0 - self.delay, side="right")) - 1

    def reverses(self, c: int, end: int) -> bool:
        """Whether the commands from c (the one acting at the start) to the last arriving by sample end - 1 include
        both signs (one more counted: a bound that errs towards a reversal)."""
        last = min(len(self.arrivals), int(np.searchsorted(self.arrival_times, self.ts[end - 1], side="right")) + 1)
        first = max(c, 0)
        return bool(self.positive[last] > self.positive[first] and self.negative[last] > self.negative[first])

    def gap(self, c: int, end: int, backlash: float) -> bool:
        """Whether the backlash acts in the window [c's start, end): a command of each sign in it, or the encoder reads
        the reply's rotor angle (which has the rotor's place in the gap in it). Where it does not, every command passes
        whole (`GapShare.share` is 1 once the teeth rest on the commands' side) and the run is the one without it."""
        return backlash > 0.0 and (self.exp.angle_from_reply or self.reverses(c, end))


def _bits(x: object) -> object:
    """A float by its bits (-0.0 is not 0.0); anything else as it is."""
    return x.hex() if isinstance(x, float) else x


def window_key(ev: Events, k: int, end: int, t0: float, v_start: float, start_angle: float, c: int,
               backlash: float) -> tuple:
    """What a window's run (`run_plant`) depends on: the recording's arrays (by identity: `Events.keep`) and which
    angle its encoder reads, the window, its start, the plant's parameters but the backlash, and the backlash only
    where it acts (`Events.gap`)."""
    return (tuple(map(id, ev.keep)), ev.exp.angle_from_reply, k, end, ev.plant_bits,
            tuple(_bits(float(x)) for x in (t0, v_start, start_angle, ev.delay, backlash if ev.gap(c, end, backlash)
                                             else 0.0)))


def run_plant(ev: Events, params: PlantParams, backlash: float, k: int, end: int, t0: float, v_start: float,
              start_angle: float, c: int) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """(the output angle, the angle the encoder reads before its offset, the current the firmware last heard, whether
    it heard one) at samples [k, end) of a window started at t0 at start_angle and v_start (0: stuck), c the command
    acting then; see `fit_model.simulate`."""
    exp = ev.exp
    ts, arrivals, reqs, amps_of, targets = ev.ts, ev.arrivals, ev.reqs, ev.amps, ev.targets
    req_of, reply_of, measured, from_reply = ev.req_of, ev.reply_of, ev.measured, exp.angle_from_reply
    n_cmd, n_req = len(arrivals), len(reqs)
    tau: float = params.current_time_constant_s
    ratio: float = params.total_ratio
    i0 = measured[k]
    # the backlash is the fit's (`fit_gap`): the plant runs without it and is given the share of each command
    # that reaches the output; its friction switches where it happens, not on its step grid (a cost without
    # jumps)
    plant = Plant(params, suspended(), initial_angle_rad=start_angle, initial_velocity_rad_s=v_start,
                  start_time_s=t0, initial_current_a=i0, located_switching=True)
    gap = GapShare(params, backlash, t0, ev.band) if ev.gap(c, end, backlash) else None
    # the command clamped as the plant clamps it, and the share of it past the backlash (`fit_gap`)
    if c >= 0:
        plant.set_current_command(amps_of[c] if gap is None
                                  else targets[c] * gap.share(t0, targets[c], plant.output_accel_rad_s2(t0)), t0)
    target = targets[c - 1] if c >= 1 else 0.0
    c += 1
    r = int(np.searchsorted(ev.t_req, t0, side="right"))  # the next request to reach the motor
    means: dict[int, float] = {}  # request index -> the mean its reply carries
    positions: dict[int, float] = {}  # request index -> the rotor angle its reply carries
    t_mark = reqs[r - 1] if r >= 1 else t0  # the driver's averages reset here
    acc = i0 * (t0 - t_mark)  # before t0 the current is taken as the measured one
    t_last, i_last = t0, i0
    ta = arrivals[c] if c < n_cmd else math.inf  # the next command's arrival
    tr = reqs[r] if r < n_req else math.inf  # the next request's
    out_th: list[float] = []
    out_angle: list[float] = []
    out_current: list[float] = []
    out_heard: list[bool] = []
    for j in range(k, end):
        tj = ts[j]
        while True:  # the events up to tj, in time order: commands arriving, requests arriving (first at a tie)
            te = tr if tr <= ta else ta
            if te > tj:
                break
            span = te - t_last
            if span > 0:
                acc += target * span + (i_last - target) * tau * -math.expm1(-span / tau)
                i_last, t_last = plant.current_q_a(te), te
            if tr <= ta:
                means[r] = acc / (te - t_mark) if te > t_mark else i_last
                if from_reply:  # (a query changes nothing in the plant: skipped when not needed)
                    positions[r] = plant.motor_angle_rad(te) + (0.0 if gap is None else gap.angle(te))
                acc, t_mark = 0.0, te
                r += 1
                tr = reqs[r] if r < n_req else math.inf
            else:
                target = targets[c]
                plant.set_current_command(amps_of[c] if gap is None
                                          else target * gap.share(te, target, plant.output_accel_rad_s2(te)), te)
                c += 1
                ta = arrivals[c] if c < n_cmd else math.inf
        th = plant.output_angle_rad(tj)
        out_th.append(th)
        # through serial mode the encoder angle is a reply's position (one reply older than the current's), taken when
        # its request reached the motor; on the virtual bench the encoder reads the plant at the sample's time (the
        # reply's position is the rotor's, the motor's encoder being on it: over the whole ratio it is the output plus
        # the rotor's place in the backlash, docs/plant.md)
        rotor = positions.get(reply_of[j]) if from_reply else None
        out_angle.append(th if rotor is None else rotor / ratio)
        got = means.get(req_of[j])
        # None: its request reached the motor before this window, or has not yet in the simulation
        out_current.append(measured[j] if got is None else got)
        out_heard.append(got is not None)
    return np.array(out_th), np.array(out_angle), np.array(out_current), np.array(out_heard, dtype=bool)
