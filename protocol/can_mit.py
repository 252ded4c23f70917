"""AK-series MIT mode ("force control") over CAN: the 8-byte command, the reply, the special frames.

PROTOCOLS.md G (CubeMars AK-series driver manual, CAN chapter, "MIT mode"): the command frame has the
11-bit standard ID ``driver_id`` and packs five fields, each mapped linearly onto an unsigned integer
by :func:`float_to_uint` (``int((clamp(x) - lo) * (2**bits - 1) / (hi - lo))``; out-of-range values
saturate at the limits): position 16 bits, velocity 12, kp 12, kd 12, feed-forward torque 12::

    [p>>8, p&0xFF, v>>4, (v&0xF)<<4 | kp>>8, kp&0xFF, kd>>4, (kd&0xF)<<4 | t>>8, t&0xFF]

The motor evaluates ``torque = kp (p_des - p) + kd (v_des - v) + t_ff`` at its own loop rate and
answers every command with ``[driver_id, p>>8, p&0xFF, v>>4, (v&0xF)<<4 | t>>8, t&0xFF, temperature,
error]`` on the master ID :data:`MASTER_ID` (its fourth field: torque, or q current by firmware
version, in the t range). Three special 8-byte frames: ``FF..FF FC`` enter motor mode, ``FF..FF FD``
exit motor mode (torque off), ``FF..FF FE`` set the present position as zero.
The ranges differ per motor (:class:`MitLimits`; the motor catalogue's ``[can_mit]``): every function takes
them, the AK60-6's as published (:data:`AK60_6`) by default; the firmware's driver takes its profile's
(``[motor] mit_*``, firmware/motor_ratings.py).

No import from the rest of pafp: the codec stands alone (firmware, device models and host tools use it).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Final

__all__ = [
    "AK60_6", "ENTER_MOTOR_MODE", "EXIT_MOTOR_MODE", "MASTER_ID", "SET_ZERO", "MitCommand", "MitLimits", "MitReply",
    "decode_command", "decode_reply", "encode_command", "encode_reply", "float_to_uint", "special_frame",
    "uint_to_float",
]

MASTER_ID: Final = 0
"""Standard ID of the replies (CAN_MASTER 0 of Ben Katz's mini-cheetah firmware, which MIT mode follows)."""
ENTER_MOTOR_MODE: Final = b"\xff" * 7 + b"\xfc"
EXIT_MOTOR_MODE: Final = b"\xff" * 7 + b"\xfd"
SET_ZERO: Final = b"\xff" * 7 + b"\xfe"
_SPECIALS: Final = {ENTER_MOTOR_MODE: "enter", EXIT_MOTOR_MODE: "exit", SET_ZERO: "zero"}


@dataclass(frozen=True)
class MitLimits:
    """The ranges a model maps its fields onto (SI: rad, rad/s, N m, N m/rad, N m s/rad)."""

    p_max: float = 12.5
    v_max: float = 50.0
    t_max: float = 15.0
    kp_max: float = 500.0
    kd_max: float = 5.0


AK60_6: Final = MitLimits()
"""AK60-6: p +-12.5 rad, v +-50 rad/s, t +-15 N m, kp 0..500, kd 0..5 (PROTOCOLS.md G)."""


def float_to_uint(x: float, lo: float, hi: float, bits: int) -> int:
    """x in [lo, hi] (saturated there; NaN reads as lo) onto 0 .. 2**bits - 1, truncating as the manual's C does."""
    if not x >= lo:  # NaN too
        x = lo
    elif x > hi:
        x = hi
    return int((x - lo) * ((1 << bits) - 1) / (hi - lo))


def uint_to_float(u: int, lo: float, hi: float, bits: int) -> float:
    """The inverse of float_to_uint (the value at the bottom of the code's step)."""
    return u * (hi - lo) / ((1 << bits) - 1) + lo


@dataclass(frozen=True)
class MitCommand:
    """One MIT-mode command: desired position and velocity, gains, feed-forward torque (motor side, SI)."""

    p_des: float = 0.0
    v_des: float = 0.0
    kp: float = 0.0
    kd: float = 0.0
    t_ff: float = 0.0


@dataclass(frozen=True)
class MitReply:
    """The motor's answer: its id, position, velocity, torque, temperature (deg C) and error code."""

    driver_id: int
    p: float
    v: float
    t: float
    temperature_c: int = 0
    error: int = 0


def encode_command(cmd: MitCommand, lim: MitLimits = AK60_6) -> bytes:
    """The 8 data bytes of cmd (each field saturated at lim's range)."""
    p = float_to_uint(cmd.p_des, -lim.p_max, lim.p_max, 16)
    v = float_to_uint(cmd.v_des, -lim.v_max, lim.v_max, 12)
    kp = float_to_uint(cmd.kp, 0.0, lim.kp_max, 12)
    kd = float_to_uint(cmd.kd, 0.0, lim.kd_max, 12)
    t = float_to_uint(cmd.t_ff, -lim.t_max, lim.t_max, 12)
    return bytes((p >> 8, p & 0xFF, v >> 4, ((v & 0xF) << 4) | (kp >> 8), kp & 0xFF, kd >> 4,
                  ((kd & 0xF) << 4) | (t >> 8), t & 0xFF))


def special_frame(data: bytes) -> str:
    """'enter', 'exit' or 'zero' for the special frames, '' for anything else."""
    return _SPECIALS.get(bytes(data), "")


def decode_command(data: bytes, lim: MitLimits = AK60_6) -> MitCommand:
    """The command in 8 data bytes (ValueError for another length; check special_frame first)."""
    if len(data) != 8:
        raise ValueError(f"MIT command has {len(data)} data bytes, not 8")
    d = data
    p = (d[0] << 8) | d[1]
    v = (d[2] << 4) | (d[3] >> 4)
    kp = ((d[3] & 0xF) << 8) | d[4]
    kd = (d[5] << 4) | (d[6] >> 4)
    t = ((d[6] & 0xF) << 8) | d[7]
    return MitCommand(uint_to_float(p, -lim.p_max, lim.p_max, 16), uint_to_float(v, -lim.v_max, lim.v_max, 12),
                      uint_to_float(kp, 0.0, lim.kp_max, 12), uint_to_float(kd, 0.0, lim.kd_max, 12),
                      uint_to_float(t, -lim.t_max, lim.t_max, 12))


def encode_reply(reply: MitReply, lim: MitLimits = AK60_6) -> bytes:
    """The motor's 8-byte reply (temperature and error clamped into a byte)."""
    p = float_to_uint(reply.p, -lim.p_max, lim.p_max, 16)
    v = float_to_uint(reply.v, -lim.v_max, lim.v_max, 12)
    t = float_to_uint(reply.t, -lim.t_max, lim.t_max, 12)
    temp = max(-128, min(127, reply.temperature_c)) & 0xFF
    return bytes((reply.driver_id & 0xFF, p >> 8, p & 0xFF, v >> 4, ((v & 0xF) << 4) | (t >> 8), t & 0xFF,
                  temp, max(0, min(255, reply.error))))


def decode_reply(data: bytes, lim: MitLimits = AK60_6) -> MitReply:
    """The reply in 6 or 8 data bytes (ValueError otherwise); a 6-byte reply has no temperature or error."""
    if len(data) not in (6, 8):
        raise ValueError(f"MIT reply has {len(data)} data bytes, not 6 or 8")
    d = data
    p = (d[1] << 8) | d[2]
    v = (d[3] << 4) | (d[4] >> 4)
    t = ((d[4] & 0xF) << 8) | d[5]
    temp = d[6] - 256 if len(d) == 8 and d[6] > 127 else (d[6] if len(d) == 8 else 0)
    return MitReply(d[0], uint_to_float(p, -lim.p_max, lim.p_max, 16), uint_to_float(v, -lim.v_max, lim.v_max, 12),
                    uint_to_float(t, -lim.t_max, lim.t_max, 12), temp, d[7] if len(d) == 8 else 0)
