"""Gait events from the ground sensors: heel strike, foot flat, heel off and toe off, with sensor checks.

Each control period (after `GroundSensorDriver.sample`): an FSR is on above ``fsr_on_v`` and off below
``fsr_off_v``; the foot is in contact when an FSR is on or the load cell's axial force is above
``contact_on_n``, and in the air when both FSRs are off and the force is below ``contact_off_n``.
Heel strike is swing -> contact, toe off contact -> swing (each state held at least ``min_swing_s`` /
``min_stance_s``); in stance, foot flat is the first period with both FSRs on and heel off the heel
FSR going off after foot flat with the toe still on (Au, Weber, Herr 2009: the stance sub-phases of a
powered ankle). In swing the driver re-zeros the load cell.

Checks (a fault latches; the firmware then falls back to its motor-load detector, gait_events.py; it
also uses that one until the load cell is tared): no load-cell code ``NO_DATA_S`` after the tare window
(a silent acquisition board); a load-cell channel at an amplifier rail for ``fault_samples`` periods;
an FSR above ``fsr_short_v`` (shorted: the divider at the supply) for ``fault_samples`` periods; at the
end of a stance in which the load cell carried the body (above ``contact_on_n``), an FSR that never came
on (open: a broken lead); at the end of a stance the FSRs saw but the load cell did not (a dead load cell).
"""

from __future__ import annotations

from firmware.drivers.ground_sensors import GroundSensorDriver

__all__ = ["GroundEvents"]

NO_DATA_S = 0.5
"""How long after the tare window a board that has sent nothing is a fault."""
SWING, LOADING, FLAT, PUSH = 0, 1, 2, 3
"""Sub-phases: in the air; heel strike to foot flat; foot flat to heel off; heel off to toe off."""


class GroundEvents:
    """The detector over a `GroundSensorDriver` (module docstring)."""

    def __init__(self, driver: GroundSensorDriver) -> None:
        """Start in swing, no fault."""
        self.driver = driver
        cfg = driver.cfg
        self.fsr_on_v, self.fsr_off_v, self.fsr_short_v = cfg.fsr_on_v, cfg.fsr_off_v, cfg.fsr_short_v
        self.on_n, self.off_n = cfg.contact_on_n, cfg.contact_off_n
        self.min_stance_s, self.min_swing_s = cfg.min_stance_s, cfg.min_swing_s
        self.fault_samples = cfg.fault_samples
        self.stance = False
        self.phase = SWING
        self.heel_on = False
        self.toe_on = False
        self.changed_s = -1e9
        self.fault = ""  # what failed, once a check fired ("" while healthy)
        self.fault_s = -1.0
        self.heel_strike_s: list[float] = []
        self.toe_off_s: list[float] = []
        self.foot_flats = 0
        self.heel_offs = 0
        self.foot_flat_s: list[float] = []  # when each foot flat and heel off was detected (for the trace)
        self.heel_off_s: list[float] = []
        self._rail_run = 0
        self._short_run = [0, 0]
        self._stance_max_n = 0.0
        self._stance_heel = False
        self._stance_toe = False

    @property
    def healthy(self) -> bool:
        """True once the load cell is tared and while no check has fired."""
        return not self.fault and self.driver.tared

    def _latch(self, what: str, now_s: float) -> None:
        if not self.fault:
            self.fault = what
            self.fault_s = now_s

    def update(self, now_s: float) -> bool:
        """Sample the sensors, run the checks and the events; return True while in stance."""
        d = self.driver
        d.sample(now_s)
        if not d.tared:
            if now_s > d.cfg.tare_s + NO_DATA_S:
                self._latch("no load-cell data since boot", now_s)
            return False
        heel_v, toe_v, force = d.heel_v, d.toe_v, d.force_n
        self.heel_on = heel_v > (self.fsr_off_v if self.heel_on else self.fsr_on_v)
        self.toe_on = toe_v > (self.fsr_off_v if self.toe_on else self.fsr_on_v)
        self._checks(now_s, heel_v, toe_v)
        held_s = now_s - self.changed_s
        if self.stance:
            self._stance_max_n = max(self._stance_max_n, force)
            self._stance_heel = self._stance_heel or self.heel_on
            self._stance_toe = self._stance_toe or self.toe_on
            if self.phase == LOADING and self.heel_on and self.toe_on:
                self.phase = FLAT
                self.foot_flats += 1
                self.foot_flat_s.append(now_s)
            elif self.phase == FLAT and not self.heel_on and self.toe_on:
                self.phase = PUSH
                self.heel_offs += 1
                self.heel_off_s.append(now_s)
            if not self.heel_on and not self.toe_on and force < self.off_n and held_s >= self.min_stance_s:
                self._end_of_stance(now_s)
                self.stance = False
                self.phase = SWING
                self.changed_s = now_s
                self.toe_off_s.append(now_s)
        else:
            if (self.heel_on or self.toe_on or force > self.on_n) and held_s >= self.min_swing_s:
                self.stance = True
                self.phase = LOADING
                self.changed_s = now_s
                self.heel_strike_s.append(now_s)
                self._stance_max_n = force
                self._stance_heel, self._stance_toe = self.heel_on, self.toe_on
            elif held_s >= self.min_swing_s:
                d.rezero()
        return self.stance

    def _checks(self, now_s: float, heel_v: float, toe_v: float) -> None:
        self._rail_run = self._rail_run + 1 if self.driver.at_rail else 0
        if self._rail_run >= self.fault_samples:
            self._latch("load cell at an amplifier rail", now_s)
        for k, (name, v) in enumerate((("heel", heel_v), ("toe", toe_v))):
            self._short_run[k] = self._short_run[k] + 1 if v > self.fsr_short_v else 0
            if self._short_run[k] >= self.fault_samples:
                self._latch(f"{name} FSR shorted", now_s)

    def _end_of_stance(self, now_s: float) -> None:
        if self._stance_max_n > self.on_n:
            if not self._stance_heel:
                self._latch("heel FSR never on in a loaded stance", now_s)
            if not self._stance_toe:
                self._latch("toe FSR never on in a loaded stance", now_s)
        elif self._stance_heel or self._stance_toe:
            self._latch("load cell unloaded through a stance the FSRs saw", now_s)
