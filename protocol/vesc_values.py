"""COMM_GET_VALUES (4) and COMM_GET_VALUES_SELECTIVE (50) replies, their shared field table, fault codes.

The layout is written once, in :data:`FIELDS` (PROTOCOLS.md B.3, vedderb/bldc ``commands.c``): bit number
(the mask bit of id 50), attribute name, struct code, scale (value = raw / scale, angles degrees on the wire
and radians in the API). :class:`Values` is the CubeMars 73-byte reply (bits 0..20); bit 21 (``status``,
VESC >= 5.03 only) exists only in the selective reply.
"""

from __future__ import annotations

import struct
from collections.abc import Callable
from dataclasses import dataclass, field
from enum import IntEnum
from functools import lru_cache
from typing import ClassVar, Self

from protocol.vesc_codec import SelectiveCodec
from protocol.vesc_message import CommandId, Message, WireField, field_setter

__all__ = ["FIELDS", "VALUES_FIELDS", "FaultCode", "Values", "ValuesSelective", "selective_layout"]


class FaultCode(IntEnum):
    """``mc_fault_code`` values reported by the CubeMars driver (0..18, PROTOCOLS.md B.7)."""

    NONE = 0
    OVER_VOLTAGE = 1
    UNDER_VOLTAGE = 2
    DRV = 3
    ABS_OVER_CURRENT = 4
    OVER_TEMP_FET = 5
    OVER_TEMP_MOTOR = 6
    GATE_DRIVER_OVER_VOLTAGE = 7
    GATE_DRIVER_UNDER_VOLTAGE = 8
    MCU_UNDER_VOLTAGE = 9
    BOOTING_FROM_WATCHDOG_RESET = 10
    ENCODER_SPI = 11
    ENCODER_SINCOS_BELOW_MIN_AMPLITUDE = 12
    ENCODER_SINCOS_ABOVE_MAX_AMPLITUDE = 13
    FLASH_CORRUPTION = 14
    HIGH_OFFSET_CURRENT_SENSOR_1 = 15
    HIGH_OFFSET_CURRENT_SENSOR_2 = 16
    HIGH_OFFSET_CURRENT_SENSOR_3 = 17
    UNBALANCED_CURRENTS = 18


FIELDS: tuple[WireField, ...] = (
    WireField("temp_fet_c", "h", 10, bit=0),
    WireField("temp_motor_c", "h", 10, bit=1),
    WireField("avg_motor_current_a", "i", 100, bit=2),
    WireField("avg_input_current_a", "i", 100, bit=3),
    WireField("avg_id_a", "i", 100, bit=4),
    WireField("avg_iq_a", "i", 100, bit=5),
    WireField("duty", "h", 1000, bit=6),
    WireField("erpm", "i", 1, bit=7),
    WireField("v_in_v", "h", 10, bit=8),
    WireField("amp_hours", "i", 10000, bit=9),
    WireField("amp_hours_charged", "i", 10000, bit=10),
    WireField("watt_hours", "i", 10000, bit=11),
    WireField("watt_hours_charged", "i", 10000, bit=12),
    WireField("tachometer", "i", 1, bit=13),
    WireField("tachometer_abs", "i", 1, bit=14),
    WireField("fault", "B", 1, bit=15),
    WireField("pid_pos_rad", "i", 1_000_000, angle=True, bit=16),
    WireField("controller_id", "B", 1, bit=17),
    WireField("temp_mos1_c", "h", 10, bit=18),
    WireField("temp_mos2_c", "h", 10, bit=18),
    WireField("temp_mos3_c", "h", 10, bit=18),
    WireField("avg_vd_v", "i", 1000, bit=19),
    WireField("avg_vq_v", "i", 1000, bit=20),
    WireField("status", "B", 1, bit=21),
)
"""Every GET_VALUES field in wire order: bit (selective mask), name, struct code, scale."""

VALUES_FIELDS: tuple[WireField, ...] = tuple(f for f in FIELDS if f.bit is not None and f.bit <= 20)
"""The fields of the CubeMars 73-byte GET_VALUES reply (bits 0..20)."""


@dataclass(frozen=True, slots=True)
class Values(Message):
    """COMM_GET_VALUES reply (motor -> host), the 73-byte CubeMars layout, in SI units (fault is a code)."""

    COMMAND_ID: ClassVar[int] = CommandId.GET_VALUES
    _WIRE: ClassVar[tuple[WireField, ...]] = VALUES_FIELDS
    temp_fet_c: float = 0.0
    temp_motor_c: float = 0.0
    avg_motor_current_a: float = 0.0
    avg_input_current_a: float = 0.0
    avg_id_a: float = 0.0
    avg_iq_a: float = 0.0
    duty: float = 0.0
    erpm: int = 0
    v_in_v: float = 0.0
    amp_hours: float = 0.0
    amp_hours_charged: float = 0.0
    watt_hours: float = 0.0
    watt_hours_charged: float = 0.0
    tachometer: int = 0
    tachometer_abs: int = 0
    fault: int = 0
    pid_pos_rad: float = 0.0
    controller_id: int = 0
    temp_mos1_c: float = 0.0
    temp_mos2_c: float = 0.0
    temp_mos3_c: float = 0.0
    avg_vd_v: float = 0.0
    avg_vq_v: float = 0.0


@lru_cache(maxsize=256)
def selective_layout(mask: int) -> tuple[struct.Struct, tuple[WireField, ...]]:
    """Return the struct and the fields present in a selective reply for ``mask`` (bits > 21 ignored)."""
    present = tuple(f for f in FIELDS if f.bit is not None and mask >> f.bit & 1)
    return struct.Struct(">" + "".join(f.code for f in present)), present


@dataclass(frozen=True, slots=True)
class ValuesSelective(Message):
    """COMM_GET_VALUES_SELECTIVE reply (CubeMars GET_VALUES_SETUP, motor -> host): fields whose bit is set.

    ``values`` maps field names of :data:`FIELDS` to SI values (not hashable because of the dict). With
    ``mask_echo`` (VESC behaviour) the payload repeats the mask after the id; without it (as the CubeMars
    manual example suggests) the receiver must know the mask it asked for.
    """

    COMMAND_ID: ClassVar[int] = CommandId.GET_VALUES_SELECTIVE
    mask: int
    values: dict[str, float] = field(default_factory=dict)
    mask_echo: bool = True

    def payload(self) -> bytes:
        """Return the payload: id, mask (if echoed), then the selected fields in FIELDS order."""
        if not 0 <= self.mask <= 0xFFFFFFFF:
            raise ValueError(f"mask={self.mask!r} is outside the uint32 range [0, 4294967295]")
        packer, present = selective_layout(self.mask & 0x3FFFFF)
        names = {f.name for f in present}
        missing = [n for n in (f.name for f in present) if n not in self.values]
        extra = sorted(set(self.values) - names)
        if missing or extra:
            raise ValueError(
                f"values for mask 0x{self.mask:08X} must have exactly the fields {sorted(names)}; "
                f"missing {missing}, unexpected {extra}"
            )
        head = struct.pack(">BI", self.COMMAND_ID, self.mask) if self.mask_echo else bytes((self.COMMAND_ID,))
        return head + packer.pack(*[f.to_raw(self.values[f.name]) for f in present])

    @classmethod
    def from_payload(cls, payload: bytes, mask: int | None = None) -> Self:
        """Decode a reply; ``mask=None``: the mask is echoed in the payload, else it is the mask asked for."""
        return _SELECTIVE.decode(payload, mask)  # type: ignore[no-any-return]

    @classmethod
    def payload_decoder(cls) -> Callable[[bytes], Self]:
        """Return the compiled decoder of replies with the mask echoed (for Decoder)."""
        return _SELECTIVE.decode

    @classmethod
    def from_values(cls, values: Values, mask: int, mask_echo: bool = True, status: int = 0) -> Self:
        """Select the fields of ``mask`` from a full :class:`Values` (``status`` supplies bit 21)."""
        if not 0 <= mask <= 0xFFFFFFFF:
            raise ValueError(f"mask={mask!r} is outside the uint32 range [0, 4294967295]")
        _, present = selective_layout(mask & 0x3FFFFF)
        selected = {f.name: status if f.name == "status" else getattr(values, f.name) for f in present}
        return cls(mask, selected, mask_echo)


_SELECTIVE = SelectiveCodec(
    ValuesSelective,
    selective_layout,
    field_setter(ValuesSelective, "mask"),
    field_setter(ValuesSelective, "values"),
    field_setter(ValuesSelective, "mask_echo"),
)
