"""Tests of the gait reference (periodic C2 spline of the normative curve) and the minimum-jerk move."""

from __future__ import annotations

import csv
import logging
import math
from pathlib import Path

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st

from firmware.control.reference import GaitReference, MinimumJerk

ROOT = Path(__file__).resolve().parents[1]
PACKAGED = ROOT / "firmware" / "data" / "ankle_normative.csv"
SHARED = Path("/work/shared/data/gait")
STRIDE = 1.1


@pytest.fixture(scope="module")
def ref() -> GaitReference:
    return GaitReference.normative(stride_s=STRIDE)


def read_columns(path: Path) -> tuple[list[float], list[float], list[float]]:
    """Independent reader of the packaged CSV: percent, mean, sd."""
    rows = [ln for ln in path.read_text().splitlines() if not ln.startswith("#")]
    table = list(csv.DictReader(rows))
    return ([float(r["percent_gait"]) for r in table], [float(r["ankle_angle_deg_mean"]) for r in table],
            [float(r["ankle_angle_deg_sd"]) for r in table])


def test_packaged_csv_carries_credit_and_the_shared_numbers() -> None:
    text = PACKAGED.read_text()
    assert "Schwartz" in text.splitlines()[0] and "CC-BY-SA" in text
    if (SHARED / "ankle_normative.csv").exists():
        data_lines = [ln for ln in text.splitlines() if not ln.startswith("#")]
        assert data_lines == (SHARED / "ankle_normative.csv").read_text().splitlines()


def test_spline_passes_corrected_data_points(ref: GaitReference) -> None:
    percent, mean, _ = read_columns(PACKAGED)
    delta = mean[-1] - mean[0]
    assert delta == pytest.approx(-2.32 - -2.0993)
    assert ref.closure_offset_deg == pytest.approx(delta, abs=1e-12)
    for p, y in zip(percent[:-1], mean[:-1], strict=True):
        corrected = y - delta * p / 100.0
        assert math.degrees(ref.sample(p / 100.0 * STRIDE)[0]) == pytest.approx(corrected, abs=1e-9)


@given(st.floats(0.0, 50.0))
def test_periodic(t: float) -> None:
    ref = GaitReference.normative(stride_s=STRIDE)
    a, b = ref.sample(t), ref.sample(t + 3 * STRIDE)
    assert a == pytest.approx(b, abs=1e-7)


@pytest.mark.parametrize("k", [0, 1, 10, 25, 49])
def test_c2_continuity_at_knots_and_stride_boundary(ref: GaitReference, k: int) -> None:
    eps = 1e-9
    t = (k + 1) * 0.02 * STRIDE if k < 49 else STRIDE     # k = 49: the 98 % -> 100 % = 0 % wrap
    left, right = ref.sample(t - eps), ref.sample(t + eps)
    assert left[0] == pytest.approx(right[0], abs=1e-7)
    assert left[1] == pytest.approx(right[1], abs=1e-5)
    assert left[2] == pytest.approx(right[2], abs=1e-3)


def test_derivatives_agree_with_finite_differences(ref: GaitReference) -> None:
    h = 1e-5
    for t in np.linspace(0.01, 3.0, 37):
        ang_m, ang_p = ref.sample(t - h)[0], ref.sample(t + h)[0]
        vel_m, vel_p = ref.sample(t - h)[1], ref.sample(t + h)[1]
        _, vel, acc = ref.sample(t)
        assert vel == pytest.approx((ang_p - ang_m) / (2 * h), abs=1e-4)
        assert acc == pytest.approx((vel_p - vel_m) / (2 * h), abs=1e-2)


def test_sanity_figures_of_the_gait_readme(ref: GaitReference) -> None:
    t = np.linspace(0.0, STRIDE, 11001)[:-1]
    ang = np.degrees([ref.sample(x)[0] for x in t])
    percent = t / STRIDE * 100.0
    assert ang.max() == pytest.approx(11.84, abs=0.2)
    assert percent[ang.argmax()] == pytest.approx(46.0, abs=1.5)
    assert ang.min() == pytest.approx(-19.79, abs=0.2)
    assert percent[ang.argmin()] == pytest.approx(64.0, abs=1.5)
    loading = ang[percent < 20.0]
    # Between the 4 % and 6 % samples (-5.55, -5.59) the spline dips to about -5.79 deg.
    assert loading.min() == pytest.approx(-5.59, abs=0.3)
    assert percent[loading.argmin()] == pytest.approx(5.0, abs=1.0)
    assert ref.clamp_count == 0 and ref.clamped_fraction == 0.0


def test_stride_scales_time_and_derivatives() -> None:
    slow, fast = GaitReference.normative(stride_s=1.5), GaitReference.normative(stride_s=1.0)
    for phase in (0.13, 0.47, 0.61, 0.9):
        s, f = slow.sample(phase * 1.5), fast.sample(phase * 1.0)
        assert s[0] == pytest.approx(f[0], abs=1e-12)
        assert s[1] * 1.5 == pytest.approx(f[1] * 1.0, rel=1e-9)
        assert s[2] * 1.5**2 == pytest.approx(f[2] * 1.0**2, rel=1e-9)
    assert slow.percent_at(0.75) == pytest.approx(50.0)


def test_range_of_motion_clamp_counts(caplog: pytest.LogCaptureFixture) -> None:
    with caplog.at_level(logging.WARNING, logger="firmware.control.reference"):
        ref = GaitReference.normative(rom_deg=(-10.0, 10.0))
    assert "clamped" in caplog.text
    assert 0.1 < ref.clamped_fraction < 0.5
    samples = [ref.sample(k * 0.001) for k in range(1100)]
    assert all(-math.radians(10.0) - 1e-15 <= a <= math.radians(10.0) + 1e-15 for a, _, _ in samples)
    clamped = [s for s in samples if abs(abs(s[0]) - math.radians(10.0)) < 1e-15]
    assert ref.clamp_count == len(clamped) > 0
    assert all(v == 0.0 and a == 0.0 for _, v, a in clamped)


def test_band(ref: GaitReference) -> None:
    _, mean, sd = read_columns(PACKAGED)
    m46, sd46 = ref.band_deg(46.0)
    assert sd46 == pytest.approx(sd[23])
    assert m46 == pytest.approx(mean[23] - ref.closure_offset_deg * 0.46, abs=1e-9)
    assert ref.band_deg(146.0) == pytest.approx(ref.band_deg(46.0))
    assert ref.band_deg(47.0)[1] == pytest.approx((sd[23] + sd[24]) / 2)


def test_from_csv_matches_packaged(ref: GaitReference) -> None:
    other = GaitReference.from_csv(PACKAGED, stride_s=STRIDE)
    for t in (0.0, 0.3, 0.77, 1.05):
        assert other.sample(t) == ref.sample(t)


@pytest.mark.skipif(not SHARED.exists(), reason="shared gait data not present")
def test_from_csv_select_long_format() -> None:
    slow = GaitReference.from_csv(SHARED / "ankle_normative_schwartz2008_all_speeds.csv",
                                  select={"speed_category": "Slow"})
    centre = GaitReference.from_csv(SHARED / "ankle_normative_pinzone2014.csv",
                                    select={"centre": "Centre one"})
    assert len(slow.data_percent) == 51 and len(centre.data_percent) == 51
    assert max(slow.data_angle_deg) > 5.0 and min(centre.data_angle_deg) < -10.0


def test_curve_short_of_100_percent_wraps(tmp_path: Path) -> None:
    path = tmp_path / "short.csv"
    path.write_text("percent_gait,ankle_angle_deg_mean\n0,0\n25,10\n50,0\n75,-10\n")
    ref = GaitReference.from_csv(path, stride_s=1.0)
    assert ref.closure_offset_deg == 0.0
    assert math.isnan(ref.band_deg(10.0)[1])
    assert ref.sample(0.25)[0] == pytest.approx(math.radians(10.0))
    assert ref.sample(1.0 - 1e-9)[0] == pytest.approx(0.0, abs=1e-7)


@pytest.mark.parametrize(("body", "problem"), [
    ("percent_gait,angle\n0,1\n50,2\n75,3\n100,1\n", "missing column 'ankle_angle_deg_mean'"),
    ("percent_gait,ankle_angle_deg_mean\n0,1\n50,2\n40,3\n100,1\n", "not strictly increasing"),
    ("percent_gait,ankle_angle_deg_mean\n0,1\n50,2\n100,1\n", "only 3 rows"),
    ("percent_gait,ankle_angle_deg_mean\n0,1\n50,x\n75,3\n100,1\n", "not a number"),
    ("percent_gait,ankle_angle_deg_mean\n5,1\n50,2\n75,3\n100,1\n", "must start at 0"),
])
def test_from_csv_errors_name_file_and_problem(tmp_path: Path, body: str, problem: str) -> None:
    path = tmp_path / "bad_curve.csv"
    path.write_text(body)
    with pytest.raises(ValueError, match="bad_curve.csv") as info:
        GaitReference.from_csv(path)
    assert problem in str(info.value)


@pytest.mark.parametrize(("kwargs", "name"), [({"stride_s": 0.0}, "stride_s"),
                                              ({"stride_s": 11.0}, "stride_s"),
                                              ({"rom_deg": (10.0, -10.0)}, "rom_deg")])
def test_constructor_validation(kwargs: dict[str, object], name: str) -> None:
    with pytest.raises(ValueError, match=name):
        GaitReference.normative(**kwargs)  # type: ignore[arg-type]


def test_negative_time_rejected(ref: GaitReference) -> None:
    with pytest.raises(ValueError, match="t_s"):
        ref.sample(-0.001)


def test_minimum_jerk_endpoints_and_shape() -> None:
    mj = MinimumJerk(0.1, -0.3, duration_s=0.8, start_time_s=0.5)
    assert mj.sample(0.5) == (0.1, 0.0, 0.0)
    assert mj.sample(0.0) == (0.1, 0.0, 0.0)
    assert mj.sample(1.3) == (-0.3, 0.0, 0.0)
    near_start, near_end = mj.sample(0.5 + 1e-6), mj.sample(1.3 - 1e-6)
    assert abs(near_start[1]) < 1e-9 and abs(near_end[1]) < 1e-9
    assert abs(near_start[2]) < 1e-3 and abs(near_end[2]) < 1e-3
    mid = mj.sample(0.9)
    assert mid[0] == pytest.approx(-0.1) and mid[2] == pytest.approx(0.0, abs=1e-12)
    assert mid[1] == pytest.approx(1.875 * -0.4 / 0.8)       # peak velocity 15/8 D/T
    h = 1e-6
    for t in (0.6, 0.77, 1.1):
        assert mj.velocity_rad_s(t) == pytest.approx((mj.angle_rad(t + h) - mj.angle_rad(t - h)) / (2 * h),
                                                     abs=1e-6)
        assert mj.accel_rad_s2(t) == pytest.approx(
            (mj.velocity_rad_s(t + h) - mj.velocity_rad_s(t - h)) / (2 * h), abs=1e-4)


def test_minimum_jerk_validation() -> None:
    with pytest.raises(ValueError, match="duration_s"):
        MinimumJerk(0.0, 1.0, duration_s=0.0)
    with pytest.raises(ValueError, match="end_angle_rad"):
        MinimumJerk(0.0, math.nan, duration_s=1.0)


def test_the_numpy_spline_is_scipys_periodic_cubic_spline() -> None:
    """The run does without scipy: its spline must be the one scipy fits (to rounding)."""
    import numpy as np
    from scipy.interpolate import CubicSpline

    from firmware.control.spline import evaluate, periodic_cubic_coefficients

    rng = np.random.default_rng(5)
    x = np.cumsum(rng.uniform(0.01, 0.1, 40))
    x -= x[0]
    y = rng.normal(size=40)
    y[-1] = y[0]
    c = periodic_cubic_coefficients(x, y)
    expected = CubicSpline(x, y, bc_type="periodic")
    assert np.allclose(c, expected.c, rtol=1e-12, atol=1e-12 * np.abs(expected.c).max())
    t = np.linspace(0.0, x[-1], 997)
    assert np.allclose(evaluate(x, c, t), expected(t), rtol=0, atol=1e-12)
