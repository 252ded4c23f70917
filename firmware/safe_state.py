"""What the motor is told in the safe state: the profile's ``[safety] safe_state`` as a drive command each period.

The behaviours are the drive's own (docs/devices.md, "Safe behaviours"); which one, when, is this policy:

* ``release``: zero current (the foot is free);
* ``brake``: zero current for ``brake_delay_s``, then the regenerative brake at ``brake_current_a``;
* ``short``: duty 0, the phases shorted: a damper whose torque grows with speed (UART, CAN servo);
* ``handbrake``: the open-loop current vector at ``brake_current_a``, a position hold (UART only);
* ``damping``: MIT mode's kp = 0, kd = ``damping_kd`` (CAN MIT only);
* ``hold``: the drive's own position loop (SET_POS) at the position the drive last reported, taken when the
  hold begins (UART, CAN servo): it holds the ankle with up to the drive's current limit, on the drive's own
  rotor sensor; on CAN MIT the MIT law about that position (kp = ``hold_kp``, kd = ``damping_kd``, v = t_ff = 0), a
  spring and damper on the drive's own sensor clamped to the MIT torque range; while no fresh report is at hand
  (older than ``motor_timeout_s``: a target that old would move the foot back), and for ``brake_delay_s`` after
  the trip (the current a fault wound up, a jam's at its limit, decays through the damper first), the link's
  damper stands in (the short; MIT: ``damping``);
* ``graded``: while the foot is loaded (stance: the ground sensors when healthy, else the load the motor
  current shows) the link's strongest hold: ``hold`` on UART and CAN servo (the short, the strongest damper
  the winding makes, yields under the stance moment of a light design: 18 deg at 20 kg on the AK60-6), on MIT
  its damper (``damping`` at ``damping_kd``: the MIT hold is the firmware's gains, not the drive's tuned position
  loop, and the campaign has not judged it in graded); once the hold has taken the loaded foot it keeps it
  through swing (let go at toe-off, a parallel spring wound in late stance throws the foot back: 20-34 deg on
  the adult design at push-off, 8-10 deg held); a foot the safe state meets unloaded (swing) gets one
  that lets it go gently (on MIT ``damping_kd`` / 4; on UART and CAN servo the short still: under the
  swing foot's own weight it lets it sink at a few degrees per second, and a brake capped at
  ``brake_current_a`` would hide the load the next heel strike puts on it from the load detector); and
  ``release`` once the drive reports its own fault (it has released the motor and ignores commands; releasing
  keeps a faulted drive from being asked to drive again when its fault clears).

A link offers what its protocol carries (``SAFE_BEHAVIOURS`` of each driver); a profile asking for one the link
lacks is refused before the run (:func:`check_offered`).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any, Final

__all__ = ["BEHAVIOURS", "SAFE_STATES", "SWING_KD_SHARE", "SafeCommand", "SafePolicy", "check_offered"]

BEHAVIOURS: Final = ("release", "brake", "short", "handbrake", "damping", "hold")
"""The drive commands a safe state is made of."""
SAFE_STATES: Final = (*BEHAVIOURS, "graded")
"""The values of ``[safety] safe_state``."""
SWING_KD_SHARE: Final = 0.25
"""[I] graded on MIT: the swing's kd as a share of ``damping_kd`` (a quarter: lets the unloaded foot go)."""


@dataclass(frozen=True)
class SafeCommand:
    """One drive command of the safe state: the behaviour, its current (brake, handbrake), its kd (damping, the MIT
    hold), its target (hold: the drive's reported position, rad) and the MIT hold's kp."""

    behaviour: str
    current_a: float = 0.0
    kd: float = 0.0
    position_rad: float = 0.0
    kp: float = 0.0

    @property
    def brake(self) -> bool:
        """True for the regenerative brake (the command the controllers' MotorCommand also offers)."""
        return self.behaviour == "brake"


RELEASE: Final = SafeCommand("release")
SHORT: Final = SafeCommand("short")
_HOLD: Final = SafeCommand("hold")  # marks the fixed safe state hold (its target is taken in SAFE)


def check_offered(safe_state: str, offered: tuple[str, ...], link: str) -> None:
    """ValueError naming safe_state, the link and what it offers when the link cannot carry the safe state."""
    if safe_state not in SAFE_STATES:
        raise ValueError(f"[safety] safe_state = {safe_state!r} is not allowed: one of {', '.join(SAFE_STATES)}")
    if safe_state == "graded":  # release, and a damper: MIT's kd or the short
        ok = "release" in offered and ("damping" in offered or "short" in offered)
    elif safe_state == "hold":  # a damper stands in while no fresh position is at hand
        ok = "hold" in offered and ("short" in offered or "damping" in offered)
    else:
        ok = safe_state in offered
    if not ok:
        raise ValueError(f"[safety] safe_state = {safe_state!r} is not offered by the {link} link: it offers "
                         f"{', '.join(offered)} (docs/devices.md, 'Safe behaviours')")


class SafePolicy:
    """The profile's safe state on one link: ``command`` gives the drive command of each period in SAFE."""

    def __init__(self, safe_state: str, offered: tuple[str, ...], link: str, *, brake_current_a: float,
                 brake_delay_s: float, damping_kd: float, hold_kp: float = 0.0) -> None:
        """Check the link offers the safe state; keep the currents, the brake's delay, the damper's kd and the MIT
        hold's kp (used on MIT only)."""
        check_offered(safe_state, offered, link)
        self.safe_state = safe_state
        self.brake_delay_s = brake_delay_s
        self._brake = SafeCommand("brake", brake_current_a)
        mit = "damping" in offered
        self._fixed = {"release": RELEASE, "brake": self._brake, "short": SHORT,
                       "handbrake": SafeCommand("handbrake", brake_current_a),
                       "damping": SafeCommand("damping", kd=damping_kd), "hold": _HOLD}.get(safe_state)
        self._hold = "hold" in offered and not mit  # graded's stance hold: the drive's own position loop
        self._hold_gains = (hold_kp, damping_kd) if mit else (0.0, 0.0)  # the MIT law's; the others' loop has its own
        self._damper = SafeCommand("damping", kd=damping_kd) if mit else SHORT
        self._swing = SafeCommand("damping", kd=damping_kd * SWING_KD_SHARE) if mit else SHORT
        self.last = self._damper if self._fixed is None or self._fixed is _HOLD else self._fixed

    @classmethod
    def of(cls, limits: Any, offered: tuple[str, ...], link: str) -> SafePolicy:
        """The policy of a profile's [safety] limits (firmware.safety_limits.SafetyLimits) on a link offering these."""
        return cls(limits.safe_state, offered, link, brake_current_a=limits.brake_current_a,
                   brake_delay_s=limits.brake_delay_s, damping_kd=limits.damping_kd, hold_kp=limits.hold_kp)

    def command(self, now_s: float, tripped_at_s: float | None, *, loaded: bool, drive_fault: bool,
                position_rad: float | None = None) -> SafeCommand:
        """The drive command now, tripped_at_s after the trip (None: now), the foot loaded or not, the drive faulted;
        position_rad: the drive's last reported position while fresh (None: none fresh)."""
        fixed = self._fixed
        tripped = now_s if tripped_at_s is None else tripped_at_s
        settled = now_s - tripped >= self.brake_delay_s
        if fixed is None:  # graded
            if drive_fault:
                cmd = RELEASE
            elif not loaded and self.last.behaviour != "hold":  # a hold taken in stance stays through swing
                cmd = self._swing
            else:
                cmd = self._held(position_rad, settled) if self._hold else self._damper
        elif fixed is _HOLD:  # a faulted drive ignores commands: the hold is taken afresh once it is back
            cmd = self._damper if drive_fault else self._held(position_rad, settled)
        elif fixed is self._brake:
            cmd = fixed if settled else RELEASE
        else:
            cmd = fixed
        self.last = cmd
        return cmd

    def _held(self, position_rad: float | None, settled: bool) -> SafeCommand:
        """The hold at the target taken when it began; a new one at position_rad; the link's damper while none is
        known and for ``brake_delay_s`` after the trip (so the hold does not start from a current the fault wound up:
        the drive's loop may enter at the present current, and a jam leaves it at its limit)."""
        last = self.last
        if last.behaviour == "hold":
            return last
        if position_rad is None or not settled:
            return self._damper
        kp, kd = self._hold_gains
        return SafeCommand("hold", kd=kd, position_rad=position_rad, kp=kp)

    def stop_command(self) -> SafeCommand:
        """What the stop path leaves on the wire: the safe state's own behaviour (graded, hold: the last one chosen;
        before any, the stance damper)."""
        return self.last
