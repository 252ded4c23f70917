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
from collections.abc import Callable, Iterable
from typing import TYPE_CHECKING

from firmware.protocol.vesc import CommandId, WireField
from firmware.protocol.vesc_values import selective_layout

if TYPE_CHECKING:
    from hal.virtual.devices.ak60 import Ak60

__all__ = ["ValueSource", "wrap_int32"]

_PID_POS_LIMIT_DEG = (2**31 - 1) / 1e6


def wrap_int32(value: int) -> int:
    """Wrap an integer into int32 as a two's-complement register would.

    >>> wrap_int32(2**31), wrap_int32(-5)
    (-2147483648, -5)
    """
    return (value + 2**31) % 2**32 - 2**31


class ValueSource:
    """Field getters of one driver: ``read(fields)`` returns {field name: SI value}."""

    def __init__(self, dev: Ak60) -> None:
        """Bind the getters to the driver dev (its meter, fault, position and configuration)."""
        self._dev = dev
        self._layouts: dict[tuple[int, bool], tuple[tuple[WireField, ...], bytes, Callable[..., bytes]]] = {}
        m = dev.meter
        rpm_to_erpm = 60.0 / math.tau * dev.params.pole_pairs
        controller_id = dev.config.controller_id

        def zero() -> float:
            """A field CubeMars reports as 0."""
            return 0.0

        def pid_pos() -> float:
            """pid_pos in radians, clamped to the wire range."""
            deg = dev.pid_pos_deg()
            return math.radians(max(-_PID_POS_LIMIT_DEG, min(_PID_POS_LIMIT_DEG, deg)))

        self._getters: dict[str, Callable[[], float]] = {
            "temp_fet_c": lambda: m.temp_fet_c,
            "temp_motor_c": lambda: m.temp_motor_c,
            "avg_motor_current_a": lambda: m.read_reset("current"),
            "avg_input_current_a": lambda: m.read_reset("input_current"),
            "avg_id_a": zero,
            "avg_iq_a": lambda: m.read_reset("iq"),
            "duty": lambda: m.duty,
            "erpm": lambda: int(m.motor_velocity_rad_s * rpm_to_erpm),
            "v_in_v": lambda: m.v_in_v,
            "amp_hours": lambda: m.amp_seconds / 3600.0,
            "amp_hours_charged": lambda: m.amp_seconds_charged / 3600.0,
            "watt_hours": lambda: m.watt_seconds / 3600.0,
            "watt_hours_charged": lambda: m.watt_seconds_charged / 3600.0,
            "tachometer": lambda: wrap_int32(m.tachometer),
            "tachometer_abs": lambda: wrap_int32(m.tachometer_abs),
            "fault": lambda: dev.fault,
            "pid_pos_rad": pid_pos,
            "controller_id": lambda: controller_id,
            "temp_mos1_c": zero,
            "temp_mos2_c": zero,
            "temp_mos3_c": zero,
            "avg_vd_v": zero,
            "avg_vq_v": lambda: m.read_reset("vq"),
            "status": lambda: int(dev.timed_out),
        }

    def read(self, fields: Iterable[WireField]) -> dict[str, float]:
        """The values of fields now (reading an average resets it)."""
        getters = self._getters
        return {f.name: getters[f.name]() for f in fields}

    def selective_payload(self, mask: int, mask_echo: bool = True) -> bytes:
        """The GET_VALUES_SELECTIVE reply payload for mask (same bytes as ``ValuesSelective.payload``).

        The layout for each mask is compiled once: the codec's ``selective_layout`` (one ``struct`` for
        the fields present, bits > 21 ignored) and its ``WireField.to_raw`` scaling.
        """
        entry = self._layouts.get((mask, mask_echo))
        if entry is None:
            packer, present = selective_layout(mask & 0x3FFFFF)
            cid = int(CommandId.GET_VALUES_SELECTIVE)
            head = struct.pack(">BI", cid, mask) if mask_echo else bytes((cid,))
            entry = (present, head, packer.pack)
            self._layouts[(mask, mask_echo)] = entry
        present, head, pack = entry
        getters = self._getters
        return head + pack(*[f.to_raw(getters[f.name]()) for f in present])
