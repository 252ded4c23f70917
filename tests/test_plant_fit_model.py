"""pafp fit's measurement models and weights on hand-built experiments: the IMU's 100 Hz frames, the samples whose
current has no simulated counterpart, and the noise scales the three signals are weighed by."""

from __future__ import annotations

import math
from dataclasses import replace

import numpy as np
import pytest

from hal.virtual.plant import load_plant_params
from host_tools.calibration.fit_data import Experiment
from host_tools.calibration.fit_model import (
    IMU_FRAME_AGE_S,
    SIGMA,
    base_values,
    fit_percentages,
    noise_scales,
    residuals,
    simulate,
)


def _experiment(imu: np.ndarray | None = None, req_of: np.ndarray | None = None) -> Experiment:
    """0.5 s at 1 kHz: a current square wave, a request at each sample, each sample carrying the previous one's."""
    t = np.arange(500) * 1e-3
    i_cmd = np.where((t // 0.05) % 2 == 0, 1.5, -1.5)
    zeros = np.zeros_like(t)
    req = np.arange(len(t)) - 1 if req_of is None else req_of
    return Experiment(t, i_cmd, t, zeros, zeros if imu is None else imu, zeros, "hand-built", zeros, t, req)


def test_the_imu_sample_is_its_frames_lagged_pitch_held():
    """A telemetry sample carries the last 100 Hz frame the firmware read: the lagged pitch when that frame left the
    sensor (IMU_FRAME_AGE_S before the first sample that shows it), held until the next frame."""
    base = load_plant_params()
    v = {**base_values(base), "imu_lag_s": 0.0195}
    frames = np.repeat(np.arange(50) * 0.01, 10)  # a new value every 10 samples: the frames as the data show them
    held, _, imu, mask = simulate(base, v, _experiment(imu=frames), free_v0=False)
    assert np.ptp(held) > 0.01  # the foot moves: the lagged pitch changes from sample to sample
    used = np.flatnonzero(mask)
    steps = np.flatnonzero(np.diff(imu[used]) != 0.0)
    assert len(steps) > 10
    frame_starts = np.flatnonzero(np.diff(frames) != 0.0) + 1
    # the simulated IMU changes only where a frame starts (within the used samples)
    assert set(used[steps + 1]) <= set(frame_starts)
    # and within a frame it is constant: the same simulation with a frame at every sample is not
    _, _, every, _ = simulate(base, v, _experiment(imu=np.arange(500) * 1e-3), free_v0=False)
    assert np.count_nonzero(np.diff(every[used]) != 0.0) > 5 * len(steps)
    assert 1e-3 < IMU_FRAME_AGE_S < 0.01


def test_samples_without_a_simulated_current_are_left_out_of_the_current_errors():
    base = load_plant_params()
    v = base_values(base)
    req_of = np.arange(500) - 1
    req_of[200:260] = 10_000  # a request the simulation never reaches: no simulated current
    exp = _experiment(req_of=req_of)
    r = residuals(base, v, exp)
    current = np.split(r, 3)[1]
    _, c, _, mask = simulate(base, v, exp, free_v0=True)
    unheard = mask.copy()
    unheard[:200] = unheard[260:] = False
    assert unheard.sum() > 40
    assert np.all(current[unheard[mask]] == 0.0)  # no error where nothing was simulated
    assert np.all(c[unheard] == exp.current[unheard])  # (they carry the measured current)
    assert np.count_nonzero(current[~unheard[mask]]) > 0.9 * np.count_nonzero(~unheard[mask])
    pct, count = fit_percentages(base, v, exp)
    assert count == int(unheard.sum())
    _, count_all_heard = fit_percentages(base, v, _experiment())
    assert count_all_heard == 0
    assert set(pct) == {"angle", "current", "imu"}


def test_noise_scales_are_each_signals_residual_rms():
    rng = np.random.default_rng(3)
    n = 4000
    angle, current, imu = 0.5 * rng.standard_normal(n), 2.0 * rng.standard_normal(n), rng.standard_normal(n)
    current[:1000] = 0.0  # left out (samples without a simulated current): not counted
    s = noise_scales(np.concatenate([angle, current, imu]), SIGMA)
    assert math.isclose(s["angle"] / SIGMA["angle"], 0.5, rel_tol=0.05)
    assert math.isclose(s["current"] / SIGMA["current"], 2.0, rel_tol=0.05)
    assert math.isclose(s["imu"] / SIGMA["imu"], 1.0, rel_tol=0.05)


def test_rotor_side_spread_is_the_tolerances_rms_about_the_base(tmp_path):
    """Kt's and J_m's RMS deviations from the base (a range not centred on it counts its offset), in quadrature."""
    from host_tools.calibration.fit_model import rotor_side_sd

    base = load_plant_params()
    j = base.rotor_inertia_kg_m2
    (tmp_path / "tol.toml").write_text(f"[kt_nm_per_a]\nrel = 0.1\n[rotor_inertia_kg_m2]\n"
                                       f"range = [{j!r}, {1.2 * j!r}]\n")
    # uniform in +-10 %: 0.1 / sqrt 3; uniform in [1, 1.2] J_m: variance 0.2^2 / 12 plus its mean's 0.1^2
    expected = math.sqrt(0.01 / 3 + 0.04 / 12 + 0.01)
    assert rotor_side_sd(base, tmp_path / "tol.toml") == pytest.approx(expected, rel=1e-9)
    (tmp_path / "none.toml").write_text('[foot_mass_kg]\nrel = 0.03\n')
    assert rotor_side_sd(base, tmp_path / "none.toml") == 0.0
    # the packaged table: Kt in 0.068..0.080 about 0.078 (its mean 5 % below), J_m +-5 %
    kt = math.sqrt(0.012 ** 2 / 12 + 0.004 ** 2) / 0.078
    assert rotor_side_sd(base) == pytest.approx(math.hypot(kt, 0.05 / math.sqrt(3)), rel=1e-6)


def test_the_rotor_side_acts_only_through_the_backlash_crossing():
    """rotor_accel_scale moves the rotor's Kt/J_m and nothing the output sees: the output inertia and torque per
    ampere stay; with a backlash the simulated current at each reversal changes, without one nothing does."""
    from host_tools.calibration.fit_model import plant_with

    base = load_plant_params()
    v = base_values(base)
    p0, p1 = plant_with(base, v), plant_with(base, {**v, "rotor_accel_scale": 1.1})
    assert p1.output_inertia_kg_m2 == pytest.approx(p0.output_inertia_kg_m2, rel=1e-12)
    assert p1.output_torque_per_amp_nm == pytest.approx(p0.output_torque_per_amp_nm, rel=1e-12)
    assert (p1.kt_nm_per_a / p1.rotor_inertia_kg_m2) / (p0.kt_nm_per_a / p0.rotor_inertia_kg_m2) == pytest.approx(1.1)
    exp = _experiment()
    for backlash, moves in ((1.0, True), (0.0, False)):
        w = {**v, "backlash_deg": backlash}
        a = residuals(base, w, exp)
        b = residuals(base, {**w, "rotor_accel_scale": 1.1}, exp)
        assert bool(np.max(np.abs(a - b)) > 1e-3) is moves, backlash



def test_a_window_at_rest_starts_sliding_only_where_its_encoder_moves():
    """Below REST_RAD_S the encoder cannot tell rest from the turn of a slide: a window starts sliding the way the
    encoder moves within SLIDE_LOOK_S (at its velocity when that has the same sign, else barely), stuck otherwise."""
    from host_tools.calibration.fit_model import SLIDE_CREEP_RAD_S, SLIDE_LOOK_S, _slow_start

    exp = _experiment()
    t = exp.t
    down = np.where(t < 0.006, 0.0, -math.radians(0.09) * np.floor((t - 0.006) / 0.004 + 1))
    late = np.where(t < SLIDE_LOOK_S + 0.01, 0.0, math.radians(0.09))
    at = {"down": replace(exp, angle=down), "late": replace(exp, angle=late)}
    assert _slow_start(at["down"], 0, 0.0) == -SLIDE_CREEP_RAD_S
    assert _slow_start(at["down"], 0, 0.01) == -SLIDE_CREEP_RAD_S  # the velocity the other way: barely
    assert _slow_start(at["down"], 0, -0.02) == -0.02
    assert _slow_start(at["late"], 0, 0.0) == 0.0  # no motion within the look: stuck
    assert _slow_start(exp, 0, 0.02) == 0.0


def test_stuck_starts_and_the_encoders_count():
    """The windows that start stuck are those whose encoder is at rest and does not move within SLIDE_LOOK_S (not
    those that move, nor a fast one); the readings' resolution is their smallest step; a start shift moves that
    window's simulated start by exactly that much, and nothing else."""
    from host_tools.calibration.fit_model import base_values, encoder_step, simulate, stuck_starts, windows

    exp = _experiment()
    q = 2 * math.pi / 4000
    starts = [k for k, _ in windows(exp)]
    assert encoder_step(exp) == 0.0
    assert list(stuck_starts(exp)) == starts  # never moves, never fast: every window starts stuck
    # the foot moves one count in the first window's first 10 ms, and three counts later
    angle = np.where(exp.t < 0.005, 0.0, q) + np.where(exp.t < 0.3, 0.0, 3 * q)
    moving = replace(exp, angle=angle, vel=np.where(exp.t < 0.01, 0.5, 0.0))
    assert encoder_step(moving) == pytest.approx(q, rel=1e-12)
    assert 0 not in stuck_starts(moving) and set(stuck_starts(moving)) == set(starts) - {0}
    base = load_plant_params()
    v = base_values(base)
    k = int(stuck_starts(moving)[0])
    shift = np.zeros(len(exp.t))
    shift[k] = q / 3
    a0 = simulate(base, v, moving)[0]
    a1 = simulate(base, v, replace(moving, start_shift=shift))[0]
    end = dict(windows(moving))[k]
    assert a1[k] - a0[k] == pytest.approx(q / 3, abs=1e-12)
    assert not np.allclose(a1[k:end], a0[k:end])
    assert np.array_equal(np.delete(a1, np.arange(k, end)), np.delete(a0, np.arange(k, end)))


def test_a_windows_imu_offset_and_lag_transient_leave_no_imu_error():
    """The IMU's offset and its lag's start state are each window's own: a recorded pitch that differs from the
    simulated one by a constant and a term decaying as e^(-t/lag) from the window's start has no IMU error."""
    from host_tools.calibration.fit_model import IMU_FRAME_AGE_S

    base = load_plant_params()
    lag = 0.0195
    v = {**base_values(base), "imu_lag_s": lag}
    exp = _experiment(imu=np.arange(500) * 1e-6)  # a frame at every sample
    _, _, first, mask = simulate(base, v, exp, window_s=1.0, free_v0=False)
    frames = np.maximum(exp.t - IMU_FRAME_AGE_S, exp.t[0])
    shifted = first + 0.01 + 0.004 * np.exp(-(frames - exp.t[0]) / lag)
    assert np.all(np.diff(shifted[2:]) != 0.0)  # still a frame at every sample (the first three's time is the start)
    _, _, again, mask = simulate(base, v, replace(exp, imu=shifted), window_s=1.0, free_v0=False)
    assert np.max(np.abs((again - shifted)[mask])) < 1e-9
    # a transient of another time constant is not taken out
    other = first + 0.004 * np.exp(-(frames - exp.t[0]) / (4 * lag))
    _, _, third, mask = simulate(base, v, replace(exp, imu=other), window_s=1.0, free_v0=False)
    assert np.max(np.abs((third - other)[mask])) > 1e-4


def test_the_backlash_valley_is_found_from_its_wall(monkeypatch):
    """The backlash's cost valley is a few hundredths of a degree wide, in steps: from a value on its wall (as the
    least squares' 0.1 deg secant leaves it) the coarse-to-fine search ends at its floor."""
    import host_tools.calibration.fit_profiles as pf

    floor = 0.437

    def stepped(base, v, part, scales):  # the cost moves in 0.005 deg steps, doubling 0.03 deg from the floor
        b = 0.005 * round(v["backlash_deg"] / 0.005)
        return np.array([1.0 + ((b - floor) / 0.03) ** 2, 1.0])

    monkeypatch.setattr(pf, "residuals", stepped)
    base = load_plant_params()
    for wall in (0.55, 0.33, 0.45):
        best = pf.backlash_valley(base, {**base_values(base), "backlash_deg": wall}, None, SIGMA)
        assert abs(best - floor) <= 0.006, (wall, best)
    assert pf.backlash_valley(base, {**base_values(base), "backlash_deg": 0.9}, None, SIGMA) > 0.5  # a local search


def test_a_sliding_starts_velocity_is_projected_along_the_simulations_own_response():
    """A window that starts sliding (below REST_RAD_S, the encoder moving its way) has its start velocity's error
    projected out along the simulation's response to it: the difference of two plain runs, at its start velocity and
    SLOW_STEP_RAD_S faster. The faster run is not itself projected (its start is above REST_RAD_S, where a moving
    window's analytic projection applies): projected, it would carry most of the response away."""
    from host_tools.calibration.fit_model import REST_RAD_S, SLOW_STEP_RAD_S, _slow_start

    exp = _experiment()
    t = exp.t
    down = np.where(t < 0.006, 0.0, -math.radians(0.09) * np.floor((t - 0.006) / 0.004 + 1))
    v0 = -0.02
    sliding = replace(exp, angle=down, vel=np.full(len(t), v0))
    assert _slow_start(sliding, 0, v0) == v0 and abs(v0 - SLOW_STEP_RAD_S) >= REST_RAD_S
    base = load_plant_params()
    v = base_values(base)
    plain, _, _, mask = simulate(base, v, sliding, window_s=1.0, free_v0=False)
    faster, _, _, _ = simulate(base, v, replace(sliding, vel=np.full(len(t), v0 - SLOW_STEP_RAD_S)), window_s=1.0,
                               free_v0=False)
    sens = (faster - plain) / SLOW_STEP_RAD_S
    basis = np.column_stack([sens, np.ones(len(t))])  # with the angle's level within its count (`_project_along`)
    coef = np.linalg.lstsq(basis[mask], (down - plain)[mask], rcond=None)[0]
    projected, _, _, _ = simulate(base, v, sliding, window_s=1.0)
    assert np.abs(sens).max() > 1e-3  # the response is there to project along
    np.testing.assert_allclose(projected, plain + basis @ coef, rtol=0, atol=1e-12)


def test_a_moving_windows_level_within_its_count_is_projected_out():
    """A moving window starts at its reading, known to its count: the encoder's readings after its start moved by a
    fraction of a count leave the window's angle residual as it was (the level is projected out with the start
    velocity), and a window that starts stuck keeps its reading as its start (its count is a consider term)."""
    from host_tools.calibration.fit_model import SLIDE_LOOK_S, stuck_starts, windows

    exp = _experiment()
    q = 2 * math.pi / 4000
    moving = replace(exp, vel=np.full(len(exp.t), 0.5), angle=0.5 * exp.t)
    base = load_plant_params()
    v = base_values(base)
    k, end = windows(moving, 0.25)[0]
    lifted = moving.angle.copy()
    lifted[k + 1:end] += q / 3  # the start's reading stays
    before, _, _, mask = simulate(base, v, moving, window_s=0.25)
    after, _, _, _ = simulate(base, v, replace(moving, angle=lifted), window_s=0.25)
    w = slice(k, end)
    np.testing.assert_allclose((after - lifted)[w][mask[w]], (before - moving.angle)[w][mask[w]], rtol=0, atol=1e-12)
    # a stuck start (the encoder still within SLIDE_LOOK_S): the same lift moves its residual by as much
    stuck = replace(exp, angle=np.where((exp.t > SLIDE_LOOK_S + 0.01) & (exp.t < 0.25), q / 3, 0.0))
    assert 0 in stuck_starts(stuck, 0.25)
    held, _, _, held_mask = simulate(base, v, exp, window_s=0.25)
    lifted_stuck, _, _, _ = simulate(base, v, stuck, window_s=0.25)
    moved = ((lifted_stuck - stuck.angle) - (held - exp.angle))[w][held_mask[w]]
    assert np.allclose(moved[stuck.t[w][held_mask[w]] > SLIDE_LOOK_S + 0.01], -q / 3, atol=1e-9)
