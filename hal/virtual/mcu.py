"""The virtual STM32: one cycle clock shared by its UARTs, encoder timer, SysTick, pins and watchdog.

`VirtualMcu` is a convenience for whoever wires the virtual bench: it creates the peripherals
on one clock, remembers them by name, and lists their interrupt sources for the scheduler.
The peripherals themselves live in uart.py, timer.py and gpio.py and can be used alone.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping

from hal.can import CanPort
from hal.interfaces import Adc, Board, DigitalIn, DigitalOut, EncoderTimer, Uart, Watchdog
from hal.virtual.gpio import VirtualDigitalIn, VirtualDigitalOut, VirtualWatchdog
from hal.virtual.irq import InterruptSourceBase
from hal.virtual.timer import SysTick, VirtualEncoderTimer
from hal.virtual.uart import VirtualUart

__all__ = ["VirtualMcu"]


class VirtualMcu:
    """Factory and registry of the virtual peripherals of one MCU on the clock ``now``.

    >>> mcu = VirtualMcu(lambda: 0, 168_000_000)
    >>> mcu.uart("motor", 921_600).baud, mcu.systick.load
    (921600, 167999)
    """

    def __init__(self, now: Callable[[], int], f_cpu_hz: int, systick_hz: int = 1000) -> None:
        """Create an MCU with a SysTick and no other peripherals yet."""
        self.now = now
        self.systick = SysTick(f_cpu_hz, systick_hz)
        self.f_cpu_hz = f_cpu_hz
        self.uarts: dict[str, VirtualUart] = {}
        self.encoders: dict[str, VirtualEncoderTimer] = {}
        self.inputs: dict[str, VirtualDigitalIn] = {}
        self.outputs: dict[str, VirtualDigitalOut] = {}

    @staticmethod
    def _claim(table: Mapping[str, object], name: str) -> None:
        if name in table:
            raise ValueError(f"peripheral name {name!r} already used; taken: {sorted(table)}")

    def uart(self, name: str, baud: int, rx_buffer_size: int = 256, tx_queue_size: int = 256) -> VirtualUart:
        """Create the UART called name at baud."""
        self._claim(self.uarts, name)
        uart = VirtualUart(self.now, self.f_cpu_hz, baud, rx_buffer_size, tx_queue_size, name=name)
        self.uarts[name] = uart
        return uart

    def encoder_timer(
        self,
        angle_rad: Callable[[int], float],
        name: str = "encoder",
        counts_per_rev: int = 4000,
        bits: int = 16,
        arr: int | None = None,
        polarity: int = 1,
    ) -> VirtualEncoderTimer:
        """Create a timer in encoder mode reading the shaft angle angle_rad(t_cycles)."""
        self._claim(self.encoders, name)
        timer = VirtualEncoderTimer(self.now, angle_rad, counts_per_rev, bits, arr, polarity)
        self.encoders[name] = timer
        return timer

    def digital_in(self, name: str, initial: bool = False) -> VirtualDigitalIn:
        """Create an input pin (set its level from tests with set_at)."""
        self._claim(self.inputs, name)
        pin = VirtualDigitalIn(self.now, initial)
        self.inputs[name] = pin
        return pin

    def digital_out(self, name: str, initial: bool = False) -> VirtualDigitalOut:
        """Create an output pin that records its changes."""
        self._claim(self.outputs, name)
        pin = VirtualDigitalOut(self.now, initial)
        self.outputs[name] = pin
        return pin

    def watchdog(self, on_kick: Callable[[], None]) -> VirtualWatchdog:
        """Create the watchdog peripheral forwarding kicks to on_kick."""
        return VirtualWatchdog(on_kick)

    def interrupt_sources(
        self, uart_rx_cycles: int, systick_cycles: int, timer_update_cycles: int | None = None
    ) -> list[InterruptSourceBase]:
        """Each encoder's wraps (if a cost is given), one RX interrupt source per UART, the SysTick.

        The encoder sources come first: they read the angle at their window start, before a UART source
        moves the world on.
        """
        sources: list[InterruptSourceBase] = []
        if timer_update_cycles is not None:
            sources += [
                e.update_interrupt(timer_update_cycles, name=f"{n}_update") for n, e in self.encoders.items()
            ]
        sources += [u.rx_interrupt(uart_rx_cycles) for u in self.uarts.values()]
        sources.append(self.systick.interrupt(systick_cycles))
        return sources

    def board(
        self,
        motor_uart: Uart,
        imu_uart: Uart,
        telemetry_uart: Uart,
        encoder: EncoderTimer,
        estop: DigitalIn,
        led: DigitalOut,
        watchdog: Watchdog,
        can: CanPort | None = None,
        adc: Adc | None = None,
    ) -> Board:
        """Bundle peripherals with this MCU's clock into the Board handed to the firmware."""
        return Board(
            motor_uart, imu_uart, telemetry_uart, encoder, estop, led, watchdog, self.now, self.f_cpu_hz, can, adc
        )
