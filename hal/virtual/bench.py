"""The virtual bench: the virtual MCU's peripherals wired to one shared plant and the device models.

``VirtualBench`` is what the firmware runs against in virtual mode. It builds, on one cycle clock:
the motor UART with the AK60-6 driver model (wired by the motor link's entry of ``hal.virtual.wiring``), the
IMU UART with the device model ``imu_model`` names (``hal.virtual.devices.registry``; the BNO08x in UART-RVC
by default), the telemetry
UART with a recording sink (the laptop), the encoder timer reading the ankle through the encoder mount,
the e-stop input, the status LED and the watchdog; all devices share one :class:`Plant` on a fixture
and are advanced in time order by one :class:`~hal.virtual.devices.world.World`. It hands the
firmware a :class:`~hal.interfaces.Board`, the scheduler its interrupt sources, and tests their
fault-injection handles (``motor_uart.inject_garbage``, ``imu.silence``, ``motor.inject_fault``,
``estop.set_at``, ``ground_sensors.set_fault``). With ``ground_sensors`` the board also has the ADC with the
pylon load cell and the heel/toe FSRs under ``ground`` (default: no ground, the sensors unloaded). It also
serves as the ``SimContext`` of ``hal.binding`` for ``sim://`` bindings.
"""

from __future__ import annotations

import logging
from collections.abc import Callable, Mapping
from typing import TYPE_CHECKING, Any

from hal.interfaces import Board, DigitalIn, DigitalOut, EncoderTimer, Uart
from hal.registry import Registry
from hal.virtual.can import VirtualBxCan
from hal.virtual.can_bus import VirtualCanBus
from hal.virtual.devices.ak60 import Ak60
from hal.virtual.devices.ak60_config import Ak60Config
from hal.virtual.devices.bno08x import Bno08xConfig
from hal.virtual.devices.encoder import EncoderMount
from hal.virtual.devices.plant_view import PlantView
from hal.virtual.devices.registry import DEVICES, device_model, device_model_for
from hal.virtual.devices.sink import ByteSink
from hal.virtual.devices.world import World
from hal.virtual.irq import InterruptSourceBase
from hal.virtual.mcu import VirtualMcu
from hal.virtual.plant import Fixture, Plant, PlantParams, backdrive, spring_bench, suspended
from hal.virtual.plant.battery import Battery, BatteryParams
from hal.virtual.plant.ground import NoGround
from hal.virtual.plant.thermal import ThermalParams, WindingThermal
from hal.virtual.wiring import MOTOR_WIRING

if TYPE_CHECKING:  # imported when fitted (numpy and the sensor models): a bench without them starts quicker
    from hal.virtual.ground_sensors import AdcSettings, GroundSensors

__all__ = ["FIXTURES", "VirtualBench", "fixture_by_name"]

log = logging.getLogger(__name__)

FIXTURES = Registry("fixture", {
    "suspended": suspended,
    "spring_bench": spring_bench,
    "spring_bench_1.08kg": lambda: spring_bench(1.08),
    "spring_bench_1.48kg": lambda: spring_bench(1.48),
    "unpowered": lambda: backdrive([(0.0, 0.0)]),
}, group="pafp.fixtures")
"""Fixtures that need no arguments, by name (``--fixture`` on the command line): name -> () -> Fixture."""

CAN_RX_CYCLES = 150
"""Cycles of the CAN RX interrupt (HAL_CAN_IRQHandler + FIFO read) when the board profile names none."""


def fixture_by_name(name: str) -> Fixture:
    """The fixture called name (see FIXTURES); ValueError naming the choices otherwise."""
    made: Fixture = FIXTURES.load(name)()
    return made


class VirtualBench:
    """Virtual MCU + one shared plant + AK60-6 + BNO08x + encoder + telemetry sink, e-stop, LED, watchdog.

    ``clock_now()`` gives the present CPU cycle (the scheduler's ``now``); it is not called while the
    bench is built. Times on the bench are integer cycles of ``f_cpu_hz``.
    """

    def __init__(
        self,
        clock_now: Callable[[], int],
        f_cpu_hz: int,
        *,
        fixture: Fixture | str | None = None,
        motor_baud: int = 921_600,
        imu_baud: int = 115_200,
        telemetry_baud: int = 921_600,
        seed: int = 0,
        plant_params: PlantParams | None = None,
        initial_angle_rad: float = 0.0,
        backlash_rad: float = 0.0,
        motor_config: Ak60Config | None = None,
        imu_config: Bno08xConfig | None = None,
        imu_model: str = "bno08x",
        encoder_offset_rad: float = 0.0,
        encoder_counts_per_rev: int = 4000,
        encoder_bits: int = 16,
        encoder_arr: int | None = None,
        encoder_polarity: int = 1,
        systick_hz: int = 1000,
        rx_buffer_size: int = 256,
        tx_queue_size: int = 256,
        estop_initial: bool = False,
        motor_link: str = "uart",
        can_bitrate: int = 1_000_000,
        can_id: int = 1,
        can_options: Mapping[str, Any] | None = None,
        ground_sensors: bool = False,
        ground: Any = None,
        adc: AdcSettings | None = None,
        ground_profile: Any = None,
    ) -> None:
        """Build the bench at cycle 0 (see the class docstring); the plant starts at rest at initial_angle_rad."""
        self.f_cpu_hz = f_cpu_hz
        self.seed = seed
        self.mcu = mcu = VirtualMcu(clock_now, f_cpu_hz, systick_hz)
        fx = fixture_by_name(fixture) if isinstance(fixture, str) else fixture
        raw_plant = Plant(plant_params, fx, initial_angle_rad=initial_angle_rad, backlash_rad=backlash_rad)
        self.world = world = World(raw_plant, f_cpu_hz)
        self.plant = PlantView(world)
        """The shared plant; queries and inputs through it first run the device events before their time."""
        self.motor_uart = mcu.uart("motor", motor_baud, rx_buffer_size, tx_queue_size)
        self.imu_uart = mcu.uart("imu", imu_baud, rx_buffer_size, tx_queue_size)
        self.telemetry_uart = mcu.uart("telemetry", telemetry_baud, rx_buffer_size, tx_queue_size)
        self.motor_link = motor_link
        self.can_bitrate, self.can_id, self.can_options = can_bitrate, can_id, dict(can_options or {})
        self.can: VirtualBxCan | None = None  # the MCU's bxCAN and its bus, on a CAN motor link
        self.can_bus: VirtualCanBus | None = None
        self.motor_device: Any = None  # the device on the motor link (for UART: self.motor)
        wire: Any = MOTOR_WIRING.load(motor_link, "motor_link")
        self.motor: Ak60 = wire(self, motor_config)
        """The AK60-6 model (plant, meter, faults); on a CAN link the core of ``motor_device``."""
        imu = device_model_for("imu", imu_model, "imu_model")
        self.models = {"motor": "ak60-6", "imu": imu_model, "telemetry": ""}
        """The device model (hal.virtual.devices.registry name) on each UART ('' = not a device model)."""
        self.imu: Any = imu.build(world, self.imu_uart, seed=seed, config=imu_config)
        """The IMU model (the BNO08x unless imu_model names another)."""
        self.telemetry = ByteSink()
        self.imu_uart.connect(self.imu)
        self.telemetry_uart.connect(self.telemetry)
        self.encoder_mount = EncoderMount(world, encoder_offset_rad)
        self.encoder = mcu.encoder_timer(self.encoder_mount.angle_rad, "encoder", encoder_counts_per_rev,
                                         encoder_bits, encoder_arr, encoder_polarity)
        self.estop = mcu.digital_in("estop", estop_initial)
        self.led = mcu.digital_out("led")
        self._watchdog_target: Any = None
        self.watchdog = mcu.watchdog(self._forward_kick)
        self.ground: Any = ground if ground is not None else NoGround()
        """What the ground does to the foot (``at(t_s) -> (F_z, F_x, CoP)``); nothing on the suspended bench."""
        self.ground_sensors: GroundSensors | None = None
        if ground_sensors:
            from hal.virtual.ground_sensors import AdcSettings, wire_ground_sensors

            self.ground_sensors = wire_ground_sensors(mcu.now, f_cpu_hz, self.ground, adc or AdcSettings(), seed=seed,
                                                      profile=ground_profile)
        """The load cell and heel/toe FSRs on the ADC, when fitted (hal/virtual/ground_sensors.py; their parameters
        from ``ground_profile``, a ground sensor profile's path, None: profiles/ground_sensors.toml)."""
        self.board: Board = mcu.board(self.motor_uart, self.imu_uart, self.telemetry_uart, self.encoder,
                                      self.estop, self.led, self.watchdog, self.can,
                                      self.ground_sensors.adc if self.ground_sensors else None)
        """The peripherals handed to the firmware."""

    # ------------------------------------------------------------------ wiring
    def attach_watchdog(self, watchdog: Any) -> None:
        """Forward the firmware's watchdog kicks to watchdog.kick() (the RTOS watchdog); None detaches."""
        if watchdog is not None and not callable(getattr(watchdog, "kick", None)):
            raise TypeError(f"watchdog {watchdog!r} has no kick() method")
        self._watchdog_target = watchdog

    def _forward_kick(self) -> None:
        if self._watchdog_target is not None:
            self._watchdog_target.kick()

    def interrupt_sources(self, isr_cycles: Mapping[str, int], *, encoder_wraps: bool = False
                          ) -> list[InterruptSourceBase]:
        """Interrupt sources for the scheduler: one RX source per UART (per byte) and the SysTick.

        isr_cycles is the board profile's ``[isr_cycles]`` table: ``uart_rx_byte`` and ``systick`` are
        required. With ``encoder_wraps`` the encoder timer's update interrupt (``timer_update`` cycles)
        is added, first in the list: it reads the angle at its window start, before a UART source moves
        the world on. It costs a plant evaluation per scheduler window (about half the run time of a
        firmware run) for one 60-cycle ISR per CNT wrap, so it is off by default. Call this once.
        """
        missing = [k for k in ("uart_rx_byte", "systick") if k not in isr_cycles]
        if encoder_wraps and "timer_update" not in isr_cycles:
            missing.append("timer_update")
        if missing:
            raise ValueError(f"isr_cycles lacks {missing}: need uart_rx_byte and systick (cycles per ISR), "
                             "and timer_update with encoder_wraps")
        timer = int(isr_cycles["timer_update"]) if encoder_wraps else None
        sources = self.mcu.interrupt_sources(int(isr_cycles["uart_rx_byte"]), int(isr_cycles["systick"]), timer)
        if self.can is not None:  # one CAN RX interrupt per frame received (before the SysTick, as the UARTs)
            sources.insert(len(sources) - 1, self.can.rx_interrupt(int(isr_cycles.get("can_rx_frame", CAN_RX_CYCLES))))
        return sources

    def attach_thermal(self, params: ThermalParams, ambient_c: float = 25.0) -> WindingThermal:
        """Give the motor's winding the two-node thermal model from ``ambient_c`` on; its status replies report it.

        The driver's MOSFET node starts at and relaxes to the same ambient.
        """
        winding = WindingThermal(params, ambient_c)
        meter = self.motor.meter
        meter.ambient_c = ambient_c
        meter.temp_fet_c = ambient_c
        meter.attach_thermal(winding)
        return winding

    def attach_battery(self, params: BatteryParams, soc: float = 1.0) -> Battery:
        """Supply the motor from this pack (full by default): the bus sags, the back-EMF limit follows it."""
        battery = Battery(params, soc)
        self.motor.meter.attach_battery(battery)
        return battery

    # -------------------------------------------------------------------- time
    def advance_to(self, t_cycles: int) -> None:
        """Run every device event up to t_cycles (reads of the peripherals do this by themselves)."""
        self.world.advance_to(t_cycles)

    def telemetry_bytes(self) -> bytes:
        """Every byte the firmware wrote to the telemetry UART (for telemetry.bin)."""
        return self.telemetry.received()

    # ------------------------------------------------- SimContext of hal.binding
    def virtual_uart(self, role: str, model: str, baud: int) -> Uart:
        """The bench UART of role (motor/imu/telemetry) if model and baud match how it was built."""
        uarts = self.mcu.uarts
        if role not in uarts:
            raise ValueError(f"role {role!r} has no UART on the bench: one of {sorted(uarts)}")
        built = self.models[role]
        same = model == built or (model in DEVICES and built in DEVICES
                                  and device_model(model) is device_model(built))  # an alias
        if model and not same:
            raise ValueError(f"{role} UART serves {built or 'the telemetry sink'!r}, not {model!r}")
        uart = uarts[role]
        if baud != uart.baud:
            raise ValueError(f"{role} UART was built at {uart.baud} baud, not {baud}: pass {role}_baud to "
                             "VirtualBench")
        return uart

    def virtual_encoder(self, role: str, model: str) -> EncoderTimer:
        """The encoder timer on the output pulley."""
        return self.encoder

    def virtual_digital_in(self, role: str, model: str) -> DigitalIn:
        """The e-stop input."""
        return self.estop

    def virtual_digital_out(self, role: str, model: str) -> DigitalOut:
        """The status LED."""
        return self.led
