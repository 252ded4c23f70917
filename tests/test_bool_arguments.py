"""A bool is not a count, a rate or a cost: every checked int argument refuses it, in the compiled build too.

Compiled code turns a bool given for an ``int`` parameter into 0 or 1 before the body runs, so these
parameters are typed ``object`` and checked by ``hal.virtual.checks.check_int`` (or the RTOS's own check).
"""

from __future__ import annotations

from collections.abc import Callable

import pytest

from hal.virtual.devices.ak60 import Ak60
from hal.virtual.devices.world import World
from hal.virtual.irq import EventTimesInterrupt
from hal.virtual.line import ByteLine
from hal.virtual.plant import Plant
from hal.virtual.timer import SysTick, VirtualEncoderTimer
from hal.virtual.uart import VirtualUart
from rtos import Scheduler, Task
from rtos.interrupts import PeriodicInterrupt, TimestampedInterrupt

F_CPU = 168_000_000


def _uart(**kw: object) -> VirtualUart:
    args: dict[str, object] = {"f_cpu_hz": F_CPU, "baud": 921_600, **kw}
    return VirtualUart(lambda: 0, **args)  # type: ignore[arg-type]


CASES: dict[str, Callable[[], object]] = {
    "World f_hz": lambda: World(Plant(), True),
    "ByteLine baud": lambda: ByteLine(F_CPU, True),
    "ByteLine bits_per_byte": lambda: ByteLine(F_CPU, 9600, True),
    "VirtualUart f_cpu_hz": lambda: _uart(f_cpu_hz=True),
    "VirtualUart baud": lambda: _uart(baud=True),
    "VirtualUart rx_buffer_size": lambda: _uart(rx_buffer_size=True),
    "VirtualUart tx_queue_size": lambda: _uart(tx_queue_size=True),
    "VirtualUart.drop_next": lambda: _uart().drop_next(True),
    "VirtualUart.rx_interrupt cost": lambda: _uart().rx_interrupt(True),
    "EventTimesInterrupt cost": lambda: EventTimesInterrupt("rx", True),
    "SysTick tick_hz": lambda: SysTick(F_CPU, True),
    "VirtualEncoderTimer counts_per_rev": lambda: VirtualEncoderTimer(lambda: 0, lambda t: 0.0, counts_per_rev=True),
    "VirtualEncoderTimer arr": lambda: VirtualEncoderTimer(lambda: 0, lambda t: 0.0, arr=True),
    "PeriodicInterrupt period": lambda: PeriodicInterrupt("systick", True, 80),
    "PeriodicInterrupt cost": lambda: PeriodicInterrupt("systick", 1000, True),
    "PeriodicInterrupt offset": lambda: PeriodicInterrupt("systick", 1000, 80, offset=True),
    "TimestampedInterrupt cost": lambda: TimestampedInterrupt("rx", True, []),
    "Scheduler.run_until t_end": lambda: Scheduler([Task("a", 1, period=10, cost=1)]).run_until(True),
}


@pytest.mark.parametrize("case", sorted(CASES))
def test_bool_refused_with_a_message_naming_it(case: str) -> None:
    with pytest.raises(ValueError, match="True"):
        CASES[case]()


def test_ak60_fault_code_refuses_a_bool() -> None:
    world = World(Plant(), F_CPU)
    with pytest.raises(ValueError, match="fault code True"):
        Ak60(world).inject_fault(True, 0.1)  # type: ignore[arg-type]


def test_controller_and_safety_parameters_refuse_a_bool() -> None:
    from firmware.control.pid import FeedforwardParams, PidGains
    from firmware.safety import SafetyLimits

    with pytest.raises(ValueError, match="kp = True"):
        PidGains(True)
    with pytest.raises(ValueError, match="inertia_kg_m2 = True"):
        FeedforwardParams(True, 1.0, 0.1, 0.1, 6.0, 0.9)
    with pytest.raises(ValueError, match="current_limit_a = True"):
        SafetyLimits(current_limit_a=True)
