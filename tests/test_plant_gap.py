"""The gearbox's backlash (`hal.virtual.plant.gap.Gap`): contact, a reversal's crossing in t_x = sqrt(2 gap / a)
with the output still (docs/plant.md, "Backlash"), engagement at the far end, no crossing on a zero command."""

from __future__ import annotations

import math

import pytest

from hal.virtual.plant.gap import Gap

HALF = 0.0288  # the packaged backlash at the rotor: 0.55 deg x 6 / 2
KT_OVER_JM = 0.078 / 2.435e-5


def test_a_reversal_crosses_the_gap_in_the_time_its_acceleration_takes():
    gap = Gap(HALF, 0.0, KT_OVER_JM, 28.0)
    assert gap.motion(0.0) == (0.0, 0.0)  # no side known before the first command
    assert gap.command(0.0, 1) is False and gap.contact == 1
    assert gap.command(0.001, 1) is False and gap.motion(0.002) == (HALF, 0.0)  # pushing the side in contact
    assert gap.command(0.002, -1) is True and gap.crossings == 1 and gap.contact == 0
    gap.free_under(-1.0, 0.0)  # 1 A the other way, the output not accelerating
    t_x = math.sqrt(2 * 2 * HALF / KT_OVER_JM)  # 6 ms at 1 A (docs/plant.md)
    assert 0.005 < t_x < 0.007
    phi, w = gap.motion(0.002 + 0.5 * t_x)
    assert phi == pytest.approx(HALF - 0.25 * 2 * HALF) and w == pytest.approx(-KT_OVER_JM * 0.5 * t_x)
    assert gap.motion(0.002 + 0.999 * t_x)[0] > -HALF
    assert gap.motion(0.002 + 1.001 * t_x) == (-HALF, 0.0)  # stopped at the far end
    # a command inside the crossing moves the rotor on; one after its end finds it engaged on the far side
    assert gap.command(0.002 + 0.5 * t_x, -1) is True
    gap.free_under(-1.0, 0.0)
    assert gap.command(0.002 + 1.2 * t_x, -1) is False and gap.contact == -1 and gap.crossings == 1
    assert gap.motion(0.1) == (-HALF, 0.0)


def test_the_outputs_acceleration_slows_the_relative_motion():
    gap = Gap(HALF, 0.0, KT_OVER_JM, 28.0)
    gap.command(0.0, 1)
    gap.command(0.001, -1)
    gap.free_under(-1.0, -KT_OVER_JM / 28.0)  # the output accelerating as the rotor would: no relative motion
    assert gap.motion(0.05) == (HALF, 0.0)


def test_zero_commands_never_free_the_rotor():
    gap = Gap(HALF, 0.0, KT_OVER_JM, 28.0)
    gap.command(0.0, 1)
    assert gap.command(0.001, 0) is False and gap.command(0.002, 1) is False and gap.crossings == 0
