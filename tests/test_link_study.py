"""`pafp bench link-study`: CAN rows beside the UART's, limits where the wire-time bounds put them."""

from __future__ import annotations

import pytest

from host_tools.benchtests import link_study


def test_can_wire_bounds():
    assert round(link_study.can_bound_hz("can-mit")) == 3704  # 2 x 135 bit-times per period at 1 Mbit/s
    assert round(link_study.can_bound_hz("can-servo")) == 7667  # 120-bit command, 500 Hz of 160-bit status
    with pytest.raises(ValueError, match="not a CAN link"):
        link_study.can_bound_hz("uart")


def test_link_study_mit_limit_sits_at_its_bound_and_rows_sit_side_by_side():
    r = link_study.run(links=("uart", "can-mit"), candidates=(4000, 2000))
    assert r.parameters["achievable"] == {"uart": None, "can-mit": 2000}  # 4 kHz is above MIT's 3.7 kHz bound
    rows = list(zip(r.columns["link"], r.columns["control_hz"], r.columns["passed"], strict=True))
    assert ("can-mit", 4000, 0) in rows and ("can-mit", 2000, 1) in rows and ("uart", 1000, 1) in rows
    figures = {f.name: f.emulated_value for f in r.figures}
    assert figures["can-mit: worst feedback age"] <= 0.6  # answered within the 0.5 ms period
    assert figures["uart at 1000 Hz: worst feedback age"] >= 1.9  # the full GET_VALUES reply spans two periods
    assert 0.4 < figures["can-mit: link load"] / 100 < 0.6
