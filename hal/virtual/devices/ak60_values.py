"""The GET_VALUES fields of the AK60-6 model, computed on request from the driver's state at that instant.

Each field has a getter; a reply asks only for the fields it carries, so an average is read (and
reset) only by a request that includes it, as in VESC's ``commands.c``. Values are SI as the codec
expects (angles in radians); integer fields wrap or clamp as the firmware's C casts would keep them
inside their wire types: tachometers wrap modulo 2**32 (int32), ``pid_pos`` is clamped to the int32 range
of degrees x 1e6 (+-2147.48 deg). CubeMars reports the three MOSFET temperatures and ``avg_vd`` as 0
(manual p.41 capture); so does this model. Bit 21 ``status``: bit 0 = command timeout active.
"""

from __future__ import annotations

import math
import struct
from collections.abc import Iterable, Sequence
from typing import Final, Protocol

from hal.virtual.devices.ak60_config import Ak60Config
from hal.virtual.devices.ak60_loops import radians
from hal.virtual.devices.ak60_meter import Ak60Meter
from protocol.vesc_message import CommandId, WireField
from protocol.vesc_values import selective_layout

__all__ = ["DriverState", "ValueSource", "wrap_int32"]


class DriverState(Protocol):
    """What the values read of the driver besides its meter (the AK60-6 model, ``hal.virtual.devices.ak60``)."""

    fault: int
    timed_out: bool

    def pid_pos_deg(self) -> float:
        """The output angle in degrees at the last sample, minus the origin."""
        ...

_PID_POS_LIMIT_DEG: Final = (2**31 - 1) / 1e6
_MAX_LAYOUTS: Final = 256  # selective reply layouts kept
_VALUES_MASK: Final = (1 << 21) - 1  # bits 0..20: the fields of the 73-byte GET_VALUES reply


def wrap_int32(value: int) -> int:
    """Wrap an integer into int32 as a two's-complement register would.

    >>> wrap_int32(2**31), wrap_int32(-5)
    (-2147483648, -5)
    """
    return (value + 2**31) % 2**32 - 2**31


class ValueSource:
    """The GET_VALUES fields of one driver: ``value(name)``, ``read(fields)`` and the reply payloads."""

    def __init__(self, dev: DriverState, meter: Ak60Meter, pole_pairs: int, config: Ak60Config) -> None:
        """Read the fields from the driver dev (fault, position, timeout), its meter and configuration."""
        self._dev = dev
        self._meter = meter
        self._rpm_to_erpm = 60.0 / math.tau * pole_pairs
        self._controller_id = config.controller_id
        self._mask_echo = config.selective_mask_echo
        self._layouts: dict[int, _Layout] = {}  # by selective mask
        packer, fields = selective_layout(_VALUES_MASK)  # GET_VALUES carries the fields of bits 0..20
        self._values_layout = _Layout(bytes((int(CommandId.GET_VALUES),)), packer, fields)

    def value(self, name: str) -> float:
        """The SI value of the field called name now (reading an average resets it); KeyError if unknown."""
        m = self._meter
        match name:
            case "temp_fet_c":
                return m.temp_fet_c
            case "temp_motor_c":
                return m.temp_motor_c
            case "avg_motor_current_a":
                return m.read_reset("current")
            case "avg_input_current_a":
                return m.read_reset("input_current")
            case "avg_iq_a":
                return m.read_reset("iq")
            case "duty":
                return m.duty
            case "erpm":
                return int(m.motor_velocity_rad_s * self._rpm_to_erpm)
            case "v_in_v":
                return m.v_in_v
            case "amp_hours":
                return m.amp_seconds / 3600.0
            case "amp_hours_charged":
                return m.amp_seconds_charged / 3600.0
            case "watt_hours":
                return m.watt_seconds / 3600.0
            case "watt_hours_charged":
                return m.watt_seconds_charged / 3600.0
            case "tachometer":
                return wrap_int32(m.tachometer)
            case "tachometer_abs":
                return wrap_int32(m.tachometer_abs)
            case "fault":
                return self._dev.fault
            case "pid_pos_rad":  # clamped to the wire range
                deg = self._dev.pid_pos_deg()
                return radians(max(-_PID_POS_LIMIT_DEG, min(_PID_POS_LIMIT_DEG, deg)))
            case "controller_id":
                return self._controller_id
            case "avg_id_a" | "temp_mos1_c" | "temp_mos2_c" | "temp_mos3_c" | "avg_vd_v":
                return 0.0  # fields CubeMars reports as 0
            case "avg_vq_v":
                return m.read_reset("vq")
            case "status":
                return int(self._dev.timed_out)
        raise KeyError(name)

    def read(self, fields: Iterable[WireField]) -> dict[str, float]:
        """The values of fields now (reading an average resets it)."""
        return {f.name: self.value(f.name) for f in fields}

    def values_payload(self) -> bytes:
        """The GET_VALUES reply payload (same bytes as ``Values(**read(VALUES_FIELDS)).payload()``)."""
        return self._payload(self._values_layout)

    def selective_payload(self, mask: int) -> bytes:
        """The GET_VALUES_SELECTIVE reply payload for mask (same bytes as ``ValuesSelective.payload``).

        The layout for each mask is compiled once: the codec's ``selective_layout`` (one ``struct`` for
        the fields present, bits > 21 ignored); the mask is echoed as the driver's configuration says.
        """
        layout = self._layouts.get(mask)
        if layout is None:
            if len(self._layouts) >= _MAX_LAYOUTS:  # masks come off the wire: keep the cache bounded
                self._layouts.clear()
            packer, present = selective_layout(mask & 0x3FFFFF)
            cid = int(CommandId.GET_VALUES_SELECTIVE)
            head = struct.pack(">BI", cid, mask) if self._mask_echo else bytes((cid,))
            layout = self._layouts[mask] = _Layout(head, packer, present)
        return self._payload(layout)

    def _payload(self, layout: _Layout) -> bytes:
        """The payload of layout now: its head, then its fields read in order, scaled and packed."""
        return layout.head + layout.pack(*[f.to_raw(self.value(f.name)) for f in layout.fields])


class _Layout:
    """A reply payload layout: fixed head bytes, then the fields packed by one ``struct``."""

    def __init__(self, head: bytes, packer: struct.Struct, fields: Sequence[WireField]) -> None:
        """Pack fields with packer after head."""
        self.head = head
        self.pack = packer.pack
        self.fields = fields
