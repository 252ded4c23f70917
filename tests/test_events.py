"""Event-driven devices: the native base class the world and the UART interrupt horizon read directly."""

from __future__ import annotations

from collections.abc import Sequence

import pytest

from hal.virtual.devices import ByteSink, World
from hal.virtual.events import NEVER, EventDevice, Horizon
from hal.virtual.plant import Plant
from hal.virtual.uart import VirtualUart


class Ticker(EventDevice):
    """A Python test double: an event every ``period`` ticks, recorded."""

    def __init__(self, world: World, period: int, log: list[tuple[str, int]], name: str) -> None:
        super().__init__()
        self.period, self.log, self.name = period, log, name
        self.next_event = period
        world.add(self)

    def run_event(self) -> None:
        self.log.append((self.name, self.next_event))
        self.next_event += self.period


def test_python_subclasses_run_in_time_order_ties_in_order_added() -> None:
    world = World(Plant(initial_angle_rad=0.0), 1000)
    log: list[tuple[str, int]] = []
    Ticker(world, 3, log, "a")
    Ticker(world, 2, log, "b")
    world.advance_to(6)
    assert log == [("b", 2), ("a", 3), ("b", 4), ("a", 6), ("b", 6)]
    assert world.now == 6


def test_world_add_rejects_what_is_not_an_event_device() -> None:
    world = World(Plant(initial_angle_rad=0.0), 1000)

    class Duck:
        next_event = NEVER

        def run_event(self) -> None:
            pass

    with pytest.raises(TypeError, match="lacks next_event and run_event"):
        world.add(object())  # type: ignore[arg-type]
    with pytest.raises(TypeError, match="is not an EventDevice"):
        world.add(Duck())  # type: ignore[arg-type]


def test_base_defaults_never_and_run_event_must_be_overridden() -> None:
    dev = EventDevice()
    assert dev.next_event == NEVER == 1 << 61
    with pytest.raises(NotImplementedError, match="EventDevice must implement run_event"):
        dev.run_event()


def test_uart_horizon_is_a_horizon_peer_only() -> None:
    uart = VirtualUart(lambda: 0, 168_000_000, 115_200)
    source = uart.rx_interrupt(100)
    sink = ByteSink()
    assert isinstance(sink, Horizon) and sink.next_event == NEVER
    uart.connect(sink)
    assert source.horizon is sink

    class Listener:
        next_event = 5

        def on_bytes(self, data: bytes, end_times_cycles: Sequence[int]) -> None:
            pass

        def advance_to(self, t: int) -> None:
            pass

    uart.connect(Listener())
    assert source.horizon is None
