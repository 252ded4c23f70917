"""pafp fit's timing models: the encoder angle a serial run takes from the motor's reply (the position when its
request reached the motor) and the command delay (`command_delay_s`), on a hand-built experiment."""

from __future__ import annotations

import json

import numpy as np
import pytest

from hal.virtual.plant import load_plant_params
from host_tools.calibration.fit_data import COMMAND_DELAY_S, WINDOW_S, Experiment, _summary_field
from host_tools.calibration.fit_model import base_values, simulate


def _experiment(from_reply: bool, shift_s: float = 0.0, angle_back: int = 0) -> Experiment:
    """0.5 s at 1 kHz: a current square wave, a request at each ms, each sample carrying the previous one's.

    shift_s moves the samples earlier (not the commands or requests); angle_back > 0 makes the encoder angle
    that many replies older than the current (serial mode's encoder task reads before the motor task)."""
    t = np.arange(500) * 1e-3
    i_cmd = np.where((t // 0.05) % 2 == 0, 1.5, -1.5)
    zeros = np.zeros_like(t)
    req_of = np.arange(len(t)) - 1
    return Experiment(t, i_cmd, t - shift_s, zeros, zeros, zeros, "hand-built", zeros, t, req_of,
                      from_reply, np.maximum(req_of - angle_back, -1) if angle_back else None)


def test_a_reply_angle_is_the_plant_angle_when_its_request_arrived():
    base = load_plant_params()
    # without backlash the reply's position (the rotor's, over the whole ratio) is the output's angle
    v = {**base_values(base), "backlash_deg": 0.0}
    reply, _, _, mask = simulate(base, v, _experiment(True), free_v0=False)
    # each sample carries the reply to the request that reached the motor one period before it: the reply's angle is
    # the plant's then, and a window starts there (its start angle is a reply's too). The same plant read directly
    # at samples one period earlier (same windows, same commands) gives the same angles; the first window's first
    # sample has no reply yet and starts at its own time, so later windows are compared
    earlier, _, _, _ = simulate(base, v, _experiment(False, shift_s=1e-3), free_v0=False)
    plain, _, _, _ = simulate(base, v, _experiment(False), free_v0=False)
    used = np.flatnonzero(mask & (np.arange(len(mask)) > WINDOW_S / 1e-3))
    assert np.ptp(plain) > 0.01  # the foot moves: the comparison can fail
    assert np.allclose(reply[used], earlier[used], atol=1e-12)
    assert not np.allclose(reply[used], plain[used], atol=1e-6)


def test_the_encoder_angle_can_be_an_older_reply_than_the_current():
    """Serial mode: the encoder task opens the period and reads the reply the motor task read a period before."""
    base = load_plant_params()
    v = {**base_values(base), "backlash_deg": 0.0}  # the reply's position is then the output's angle
    older, current_older, _, mask = simulate(base, v, _experiment(True, angle_back=1), free_v0=False)
    earlier, _, _, _ = simulate(base, v, _experiment(False, shift_s=2e-3), free_v0=False)
    same, current_same, _, _ = simulate(base, v, _experiment(True), free_v0=False)
    used = np.flatnonzero(mask & (np.arange(len(mask)) > WINDOW_S / 1e-3))
    assert np.allclose(older[used], earlier[used], atol=1e-12)  # two periods old, window started there
    assert not np.allclose(older[used], same[used], atol=1e-6)
    # the current is the latest reply's in both: only the window's start moved, by one period
    assert np.max(np.abs(current_older - current_same)[used]) < 0.5


def test_the_command_delay_moves_the_simulated_response():
    base = load_plant_params()
    v = base_values(base)
    exp = _experiment(False)
    early, current_early, _, mask = simulate(base, v, exp, free_v0=False)
    late, current_late, _, _ = simulate(base, {**v, "command_delay_s": 0.002}, exp, free_v0=False)
    assert v["command_delay_s"] == COMMAND_DELAY_S
    # a later command: the reversals come later, so the response differs, most right after each reversal
    assert np.max(np.abs(early - late)[mask]) > 1e-4
    assert np.max(np.abs(current_early - current_late)[mask]) > 0.1


def test_the_encoder_source_and_mode_come_from_the_run_summary(tmp_path):
    assert _summary_field(tmp_path, "encoder_source") == ""  # no summary: the virtual bench's encoder
    (tmp_path / "summary.json").write_text(json.dumps({"encoder_source": "motor", "mode": "serial"}))
    assert _summary_field(tmp_path, "encoder_source") == "motor"
    assert _summary_field(tmp_path, "mode") == "serial"
    (tmp_path / "summary.json").write_text("[1, 2")
    with pytest.raises(ValueError, match="summary.json"):
        _summary_field(tmp_path, "mode")


def test_the_command_delay_is_bounded_below_the_reply_round_trip():
    """A delay longer than a period would leave samples whose reply's request has not arrived in the simulation:
    they carry the measured current and cost nothing (the artefact the bound keeps out: docs/calibration.md)."""
    from host_tools.calibration.fit_model import PARAMS

    base = load_plant_params()
    v = base_values(base)
    exp = _experiment(False)  # the measured current is 0 throughout; each sample carries the previous request's
    hi = PARAMS["command_delay_s"].hi
    assert hi < 1e-3
    _, at_bound, _, mask = simulate(base, {**v, "command_delay_s": hi}, exp, free_v0=False)
    _, too_late, _, _ = simulate(base, {**v, "command_delay_s": 1.5e-3}, exp, free_v0=False)
    assert np.all(at_bound[mask] != 0.0)  # every used sample's current is simulated
    assert np.all(too_late[mask] == 0.0)  # past a period every one is the measured current


def test_the_encoder_angle_is_the_reply_read_before_the_periods_encoder_job():
    """The record's job starts: encoder at k ms, motor 20 us later reading the reply of the request sent a period
    before; a sample (the logger's job, 90 us in) carries that reply's current, and the encoder angle of the reply
    read one period earlier."""
    from host_tools.calibration.fit_data import _angle_requests, _reply_requests, _Wire

    k = np.arange(1, 20) * 1e-3
    t_req_job = k + 20e-6  # the motor task sends a command and a request each period
    w = _Wire(t_req_job, np.zeros_like(k), t_req_job + 2e-4, t_req_job, t_req_job[1:], k)  # replies read from 2 ms
    samples = k[3:] + 90e-6
    current_of = _reply_requests(samples, w)
    angle_of = _angle_requests(samples, w)
    assert np.array_equal(current_of, np.arange(3, 19) - 1)  # the reply read this period: last period's request
    assert np.array_equal(angle_of, current_of - 1)


def test_a_swing_up_from_the_stop_is_not_fitted():
    from host_tools.calibration.fit_data import _swing_up

    t = np.arange(1000) * 2e-3
    rest = np.where(t < 0.1, np.radians(30.0) * (t / 0.1 - 1.0), 0.0)  # 30 deg up in 0.1 s, then at rest
    start = _swing_up(t, rest)
    assert 0.1 <= t[start] <= 0.11
    sag = np.where(t < 0.1, np.radians(0.3) * t / 0.1, np.radians(0.3))  # the virtual bench's small sag: kept
    assert _swing_up(t, sag) == 0
    assert _swing_up(t, np.sin(t * 20)) == 0  # never at rest: nothing dropped


def test_replies_answer_their_requests_in_order_even_when_read_late():
    """A request each 1 ms job; the link stalls: replies 5-11 come together at 12 ms, and the reply to request 14 is
    lost. Counting (FIFO) maps each reply to its own request; a lost reply is given up after LOST_AFTER_S."""
    from host_tools.calibration.fit_data import LOST_AFTER_S, _reply_answers

    jobs = np.arange(200) * 1e-3
    t_req_job = jobs.copy()
    answered = [k for k in range(199) if k != 14]
    read_at = np.array([jobs[12] if 5 <= k <= 11 else jobs[k + 1] for k in answered])
    order = np.argsort(read_at, kind="stable")
    t_reply, truth = read_at[order], np.array(answered)[order]
    got = _reply_answers(t_reply, t_req_job)
    last_before = np.searchsorted(t_req_job, t_reply, side="left") - 1
    stalled = (truth >= 5) & (truth <= 10)
    assert not np.array_equal(last_before[stalled], truth[stalled])  # the old rule is wrong there: the test can fail
    assert np.array_equal(got[truth < 14], truth[truth < 14])
    # after the lost reply each is matched one request early until the gap is given up
    assert got[truth == 15][0] == 14
    recovered = t_reply > t_reply[truth == 15][0] + LOST_AFTER_S + 2e-3
    assert np.array_equal(got[recovered], truth[recovered])


def test_wire_truth_refuses_bad_input_in_one_line(tmp_path, capsys):
    from host_tools.calibration.wire_truth import main

    assert main([str(tmp_path / "no_run"), str(tmp_path / "no_capture")]) == 2
    assert main([str(tmp_path), str(tmp_path), "0"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 2 and "no_run" in err[0] and "BAUD 0" in err[1], err
    from host_tools.calibration.wire_truth import emulator_link

    with pytest.raises(ValueError, match="no_capture: not an emulator's capture"):
        emulator_link(tmp_path / "no_capture")


def test_wire_truth_dates_each_message_at_its_last_bytes_arrival(tmp_path):
    """A chunk read at 10 ms holding a command and a request: the request's last byte ended at 10 ms, the
    command's one request frame earlier (the bytes back to back at the link's baud)."""
    from hal.serial.sim_port import NS_PER_S
    from host_tools.calibration.wire_truth import emulator_link
    from protocol import vesc

    command, request = vesc.SetCurrent(1.5).encode(), vesc.GetValuesSelective(1).encode()
    (tmp_path / "motor.rx.bin").write_bytes(command + request)
    (tmp_path / "motor.tx.bin").write_bytes(b"")
    (tmp_path / "index.csv").write_text(f"t_s,file,offset,bytes\n0.010000000,motor.rx.bin,0,{len(command + request)}\n")
    link = emulator_link(tmp_path, baud=115200)
    byte_s = 10.0 / 115200
    assert link.i_cmd.tolist() == [1.5]
    assert link.t_req.tolist() == [pytest.approx(0.010, abs=1.5 / NS_PER_S)]
    assert link.t_cmd[0] == pytest.approx(0.010 - len(request) * byte_s, abs=1.5 / NS_PER_S)


def _late_wire(read_at: dict[int, float], n: int = 20, long: int = -1):
    """A command and a request each 1 ms motor job from 0; each reply (23 bytes; 78 for request `long`) read by the
    next job, except those in read_at (request -> the job that read it)."""
    from host_tools.calibration.fit_data import COMMAND_DELAY_S, _Wire

    jobs = np.arange(n + 5) * 1e-3
    t_job = jobs[:n]
    frame = 10.0 * 10 / 921600  # a request's frame after its command's
    reads = np.array([read_at.get(k, t_job[k] + 1e-3) for k in range(n)])
    size = np.where(np.arange(n) == long, 78, 23)
    return _Wire(t_job, np.zeros(n), t_job + COMMAND_DELAY_S + frame, t_job, reads, jobs, jobs, size, np.arange(n),
                 921600.0)


def test_a_reply_read_a_job_late_dates_its_write_later():
    """Request 5's reply skipped the 6 and 7 ms jobs (reply 4 read at 5 ms: the motor's UART was free): it had not
    ended by 7 ms less LINK_READ_LATENCY_S, so the write arrived no sooner than 7 ms less that and the reply's wire
    time; the next write waits behind it (the link keeps the bytes' order); the others keep COMMAND_DELAY_S."""
    from host_tools.calibration.fit_data import COMMAND_DELAY_S, LINK_READ_LATENCY_S, _late_commands

    w = _late_wire({5: 8e-3})
    late = _late_commands(w)
    request_arrival = 7e-3 - 10.0 * 23 / 921600 - LINK_READ_LATENCY_S
    assert late[5] == pytest.approx(request_arrival - w.t_req[5], abs=1e-9)
    assert late[5] > 0.5e-3  # the test can fail: a reply read on time dates nothing
    assert late[6] == pytest.approx(request_arrival + 10.0 * 10 / 921600 - (6e-3 + COMMAND_DELAY_S), abs=1e-9)
    assert np.all(late[np.r_[0:5, 7:20]] == 0.0)
    assert np.all(_late_commands(_late_wire({})) == 0.0)


def test_a_reply_that_waited_behind_the_one_before_dates_nothing():
    """Replies 4 (a long one, 78 bytes) and 5 read together at 10 ms: reply 5 may have waited behind reply 4 on the
    motor's UART, so its own lateness tells nothing of when request 5 arrived; it is dated by the link's order
    behind request 4's write only (its request frame, then command 5's)."""
    from host_tools.calibration.fit_data import COMMAND_DELAY_S, LINK_READ_LATENCY_S, _late_commands

    late = _late_commands(_late_wire({4: 10e-3, 5: 10e-3}, long=4))
    frame = 10.0 * 10 / 921600
    assert late[4] == pytest.approx(9e-3 - 10.0 * 78 / 921600 - LINK_READ_LATENCY_S - (4e-3 + COMMAND_DELAY_S + frame),
                                    abs=1e-9)
    behind = late[4] + 2 * frame - 1e-3
    own = 9e-3 - 10.0 * 23 / 921600 - LINK_READ_LATENCY_S - (5e-3 + COMMAND_DELAY_S + frame)
    assert own > behind + 1e-4  # had its own late reply dated it, the test would fail
    assert late[5] == pytest.approx(behind, abs=1e-9)


def test_the_record_bounds_each_writes_arrival():
    """A reply read by the next job bounds its write's arrival to that job less the reply's wire time; the writes
    keep their order, so a write is bounded by the next one's bound too; a dated write may have come as early as
    its job allows (the dating is an inference, not a bound)."""
    from host_tools.calibration.fit_data import _late_commands, arrival_bounds

    w = _late_wire({5: 8e-3})
    late = _late_commands(w)
    b = arrival_bounds(w, late)
    reply = 10.0 * 23 / 921600
    on_time = 1e-3 - reply - COMMAND_DELAY_S  # read by the next job: 0.6 ms
    assert b[0].tolist() == [0.0, pytest.approx(on_time, abs=1e-12)]
    # request 5's reply was read at 8 ms, request 6's at 7 ms: write 5 came no later than write 6's bound
    assert late[5] > 0 and b[5, 0] == -late[5]
    assert b[5, 1] == pytest.approx(7e-3 - reply - (5e-3 + COMMAND_DELAY_S + late[5]), abs=1e-12)
    assert np.all(b[:, 0] <= 0.0) and np.all(b[:, 1] >= 0.0)


def test_a_shifted_experiment_moves_each_write_and_its_request_in_order():
    t = np.arange(5) * 1e-3
    zeros = np.zeros(5)
    exp = Experiment(t, zeros, t, zeros, zeros, zeros, "hand-built", zeros, t + 2e-4, np.arange(5) - 1,
                     req_cmd=np.arange(5))
    moved = exp.shifted(np.array([0.0, 3e-4, 2.5e-3, 0.0, 1e-4]))
    assert moved.t_cmd.tolist() == pytest.approx([0.0, 1.3e-3, 4.5e-3, 4.5e-3, 4.5e-3])  # not before the one before
    assert moved.t_req.tolist() == pytest.approx([2e-4, 1.5e-3, 4.7e-3, 4.7e-3, 4.7e-3])
    assert exp.shifted(np.zeros(5)).t_cmd.tolist() == t.tolist()


def _timing_term(bounds: np.ndarray | None) -> float:
    """The current lag's variance from `fit_consider.timing_term` on the hand-built experiment with these arrival
    bounds."""
    from dataclasses import replace

    from host_tools.calibration.fit_consider import Solution, timing_term
    from host_tools.calibration.fit_model import SIGMA, residuals
    from host_tools.calibration.plant_fit import _secant_jacobian

    base = load_plant_params()
    v = base_values(base)
    exp = replace(_experiment(False), bounds=bounds, req_cmd=np.arange(500))
    names = ("current_time_constant_s",)
    step = np.array([0.02 * v[names[0]]])
    jac, r0 = _secant_jacobian(lambda x: residuals(base, {**v, names[0]: float(x[0])}, exp, SIGMA),
                               np.array([v[names[0]]]), step, np.array([1.0]))
    sol = Solution(names, jac, np.linalg.pinv(jac.T @ jac), r0, np.zeros(1), np.ones(1))
    return float(timing_term(base, v, exp, SIGMA, sol)[0, 0])


def test_the_timing_term_is_zero_when_the_timing_is_exact_and_grows_with_the_window():
    """The virtual bench (no bounds) and a zero window add nothing; through a pty the record leaves ~0.6 ms."""
    assert _timing_term(None) == 0.0
    assert _timing_term(np.zeros((500, 2))) == 0.0
    narrow = _timing_term(np.column_stack([np.zeros(500), np.full(500, 1e-4)]))
    wide = _timing_term(np.column_stack([np.zeros(500), np.full(500, 6e-4)]))
    assert 0.0 < narrow < wide
    assert _timing_term(np.column_stack([np.zeros(500), np.full(500, 6e-4)])) == wide  # its draws are seeded


def test_a_stalls_windows_are_left_out_of_both_parts():
    """A simulation window whose writes' arrival windows are over STALL_BOUND_S wide on average is a stall's: out of
    the fitting and the held-out parts alike; a window with one wide write among narrow ones, and the virtual bench
    (no bounds), keep every sample."""
    from dataclasses import replace

    from host_tools.calibration.fit_data import STALL_BOUND_S

    exp = _experiment(False)  # two windows of WINDOW_S (0.25 s) at 1 kHz
    assert not exp.stalled().any()  # exact timing
    width = np.full(500, 6e-4)
    width[300:] = 2.5 * STALL_BOUND_S  # the second window: every write's arrival unknown by 2.5 ms
    width[100] = 20 * STALL_BOUND_S  # one long write in the first: its mean stays under the bound
    stalled = replace(exp, bounds=np.column_stack([np.zeros(500), width])).stalled()
    assert WINDOW_S == 0.25
    assert not stalled[:250].any() and stalled[250:].all()
    fit, held = replace(exp, bounds=np.column_stack([np.zeros(500), width])).interleave(2, window_s=0.125, drop=stalled)
    assert len(fit.t) == 125 and len(held.t) == 125  # the first window's halves; the second's are in neither
    assert fit.t.max() < 0.125 and 0.125 <= held.t.min() and held.t.max() < 0.25
    fit_all, held_all = exp.interleave(2, window_s=0.125)
    assert len(fit_all.t) == len(held_all.t) == 250


def test_a_late_write_is_dated_within_its_window():
    """Request 5's reply read two jobs late dates its write late (`_late_commands`); the record's latest arrival for
    it is write 6's bound (its reply read on time): `date_within` puts it at the middle of its window when that is
    sooner than the late reply's dating, keeps the writes in order, and gives the bounds about the new dating;
    writes not dated late stay at COMMAND_DELAY_S."""
    from host_tools.calibration.fit_data import _late_commands, arrival_bounds, date_within

    w = _late_wire({5: 8e-3})
    late = _late_commands(w)
    latest = late + arrival_bounds(w, late)[:, 1]
    dated, b = date_within(w, late)
    assert late[5] > 0.5 * latest[5] > 0.0  # the test can fail: the window's middle is sooner
    assert dated[5] == pytest.approx(0.5 * latest[5], abs=1e-12)
    assert np.all(dated <= late + 1e-15) and np.all(np.diff(w.t_cmd + dated) > 0.0)
    assert np.allclose(b[:, 0], -dated) and np.allclose(dated + b[:, 1], latest)
    assert np.all(dated[late == 0.0] == 0.0) and np.all(b[:, 1] >= 0.0)
    assert np.all(date_within(_late_wire({}), np.zeros(20))[0] == 0.0)


def test_a_run_stalled_throughout_is_refused_before_the_fit():
    """Every window a stall's: one line naming the run and the bound, before any simulation."""
    from dataclasses import replace

    from host_tools.calibration.fit_data import STALL_BOUND_S
    from host_tools.calibration.plant_fit import fit_plant

    t = np.arange(4000) * 1e-3
    zeros = np.zeros_like(t)
    exp = Experiment(t, zeros, t, zeros, zeros, zeros, "hand-built", zeros, t, np.arange(4000) - 1,
                     bounds=np.column_stack([zeros, np.full(4000, 2 * STALL_BOUND_S)]), req_cmd=np.arange(4000))
    with pytest.raises(ValueError, match=r"hand-built: the link stalled .* 4000 of 4000 samples .* 1\.5 ms"):
        fit_plant(load_plant_params(), exp)
    assert not replace(exp, bounds=np.column_stack([zeros, np.full(4000, 0.9 * STALL_BOUND_S)])).stalled().any()
