"""Virtual devices on the wall clock: a motor, an IMU and/or the ground sensors' Firmata board on one plant,
ticks = nanoseconds since start.

Used by the pyserial ``sim://`` URL handler (:mod:`hal.serial.protocol_sim`) and by ``pafp emulate``.
The device models (by name, from ``hal.virtual.devices.registry.DEVICES``: the AK60-6, the BNO08x, or any
model registered there) and the plant are the very ones of the virtual bench; only the clock differs: a
:class:`~hal.virtual.uart.VirtualUart` on ``time.perf_counter_ns`` (``f_hz = 10**9``) stands for the
far end of the link, so byte timing is kept (a read returns only the bytes whose stop bit has ended by
now) and the world runs lazily whenever the port is used.
"""

from __future__ import annotations

import time
from collections.abc import Callable, Iterable, Mapping
from dataclasses import dataclass, field
from typing import Any
from urllib.parse import parse_qs, urlsplit

from hal.virtual.bench import fixture_by_name
from hal.virtual.devices.bno08x import Bno08xConfig
from hal.virtual.devices.registry import device_model
from hal.virtual.devices.world import World
from hal.virtual.plant import Fixture, Plant, PlantParams
from hal.virtual.uart import VirtualUart

__all__ = ["NS_PER_S", "SimUrl", "WallDevices", "arrival_end_times", "parse_sim_url"]

NS_PER_S = 1_000_000_000
_OPTIONS = ("baud", "fixture", "seed")


@dataclass(frozen=True)
class SimUrl:
    """A parsed ``sim://device[?baud=N&fixture=NAME&seed=S]`` URL (baud None: not given)."""

    role: str
    device: str = ""  # the device model's name in hal.virtual.devices.registry.DEVICES ('' = the role's default)
    baud: int | None = None
    fixture: str = "suspended"
    seed: int = 0
    options: dict[str, str] = field(default_factory=dict)


def parse_sim_url(url: str) -> SimUrl:
    """Parse a sim:// URL; ValueError naming the bad part and the allowed values.

    >>> parse_sim_url("sim://ak60-6?baud=921600")
    SimUrl(role='motor', device='ak60-6', baud=921600, fixture='suspended', seed=0, options={'baud': '921600'})
    """
    parts = urlsplit(url)
    if parts.scheme.lower() != "sim":
        raise ValueError(f"URL {url!r} must start with sim://")
    name = (parts.netloc + parts.path).strip("/").lower()
    role = _uart_model(name).role
    options: dict[str, str] = {}
    for key, values in parse_qs(parts.query, keep_blank_values=True).items():
        if key not in _OPTIONS:
            raise ValueError(f"sim:// option {key!r} unknown: one of {list(_OPTIONS)}")
        options[key] = values[-1]
    baud = _int_option(options, "baud", 1, 20_000_000)
    seed = _int_option(options, "seed", 0, 2**63 - 1)
    fixture = options.get("fixture", "suspended")
    fixture_by_name(fixture)  # validates the name
    return SimUrl(role, name, baud, fixture, 0 if seed is None else seed, options)


def _uart_model(name: str) -> Any:
    """The device model registered as name, if it sits on a UART (an ADC sensor is on sim://ground-sensors)."""
    model = device_model(name, "sim:// device")  # ValueError naming the registered devices
    if model.kind != "uart":
        raise ValueError(f"sim:// device {name!r} is a sensor on the {model.kind}: sim://ground-sensors serves "
                         "every registered ADC sensor")
    return model


def _int_option(options: Mapping[str, str], key: str, lo: int, hi: int) -> int | None:
    if key not in options:
        return None
    try:
        value = int(options[key])
    except ValueError:
        raise ValueError(f"sim:// option {key}={options[key]!r} is not an integer in {lo}..{hi}") from None
    if not lo <= value <= hi:
        raise ValueError(f"sim:// option {key}={value} out of range {lo}..{hi}")
    return value


def arrival_end_times(n_bytes: int, arrival_ns: int, byte_ns: float, after_ns: int) -> list[int]:
    """Stop-bit end times of n bytes that have just arrived together: back to back, the last at arrival.

    Each is kept strictly after ``after_ns`` (the previous byte's end or the device's present time).

    >>> arrival_end_times(3, 1000, 100.0, 0), arrival_end_times(3, 1000, 100.0, 850)
    ([800, 900, 1000], [851, 900, 1000])
    """
    ends = []
    last = after_ns
    for k in range(n_bytes):
        end = max(last + 1, arrival_ns - round((n_bytes - 1 - k) * byte_ns))
        ends.append(end)
        last = end
    return ends


class WallDevices:
    """One plant and the requested devices, each behind a VirtualUart on the wall clock (ns).

    ``devices`` are names of ``hal.virtual.devices.registry.DEVICES`` (``motor`` and ``imu`` name the
    default device of each role); at most one per role. ``bauds`` is by role; a role without one runs at
    its device model's default baud.
    """

    def __init__(
        self,
        devices: Iterable[str],
        *,
        bauds: Mapping[str, int] | None = None,
        fixture: Fixture | str | None = None,
        seed: int = 0,
        clock_ns: Callable[[], int] | None = None,
        rx_buffer_size: int = 65_536,
        tx_queue_size: int = 65_536,
        plant_params: PlantParams | None = None,
        imu_config: Bno08xConfig | None = None,
        initial_angle_rad: float = 0.0,
        backlash_rad: float = 0.0,
    ) -> None:
        """Start the plant and the devices now; clock_ns (default: perf_counter_ns since now) gives ticks.

        plant_params (default: the packaged profile), imu_config, initial_angle_rad and backlash_rad as
        for the virtual bench (`hal.virtual.bench.VirtualBench`): the real bench's imperfections.
        """
        if clock_ns is None:
            t0 = time.perf_counter_ns()
            clock_ns = lambda: time.perf_counter_ns() - t0  # noqa: E731
        self.now: Callable[[], int] = clock_ns
        fx = fixture_by_name(fixture) if isinstance(fixture, str) else fixture
        self.world = World(Plant(plant_params, fx, initial_angle_rad=initial_angle_rad, backlash_rad=backlash_rad),
                           NS_PER_S)
        self.uarts: dict[str, VirtualUart] = {}
        self.motor: Any = None
        """The device playing the motor (the AK60-6 unless another model was named), None if not served."""
        self.imu: Any = None
        """The device playing the IMU (the BNO08x unless another model was named), None if not served."""
        self.ground: Any = None
        """The ground sensors' acquisition board (unloaded: no ground here), None if not served."""
        bauds = dict(bauds or {})
        for name in dict.fromkeys(devices):
            model = _uart_model(name)
            role = model.role
            if role in self.uarts:
                raise ValueError(f"sim:// device {name!r}: the {role} is already served by another device")
            baud = bauds.get(role, model.baud)
            uart = VirtualUart(self.now, NS_PER_S, baud, rx_buffer_size, tx_queue_size, name=role)
            device = model.build(self.world, uart, seed=seed, config=imu_config if role == "imu" else None)
            setattr(self, role, device)
            uart.connect(device)
            self.uarts[role] = uart

    def device(self, role: str) -> Any:
        """The device model playing role."""
        dev = {"motor": self.motor, "imu": self.imu, "ground": self.ground}.get(role)
        if dev is None:
            raise ValueError(f"no device plays role {role!r}; served: {sorted(self.uarts)}")
        return dev

    def byte_ns(self, role: str) -> float:
        """Duration of one 8N1 byte on role's link, in ns (its UART's clock is NS_PER_S)."""
        return self.uarts[role].byte_cycles

    def next_event_ns(self) -> int:
        """The earliest scheduled device event (a time to wake up for)."""
        return min(d.next_event for d in (self.motor, self.imu, self.ground) if d is not None)

    def close(self) -> None:
        """Close the UARTs."""
        for uart in self.uarts.values():
            uart.close()
