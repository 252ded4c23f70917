"""Controllers that track like docs/controllers.md's PD example for MISBEHAVE_AFTER_S of RUN, then leave `update` badly.

Used by tests/test_controller_exit.py as ``--controller tests/misbehaving_controllers.py:CLASS``: one calls
``sys.exit(0)``, one raises ``KeyboardInterrupt``, one ``GeneratorExit``, one a ``BaseException`` of its
own, and one blocks in ``update`` for BLOCK_S (then goes on as if nothing happened).
"""

import math
import sys
import time

MISBEHAVE_AFTER_S = 0.3  # of RUN (the first update), then the controller misbehaves
BLOCK_S = 2.0


class Tracks:
    """PD on the ankle angle plus the foot's weight (docs/controllers.md)."""

    def __init__(self, params):
        self.nm_per_a = 0.078 * 28.0 * 0.855
        self.first_s = None

    def update(self, obs):
        if self.first_s is None:
            self.first_s = obs.t_s
        if obs.t_s - self.first_s >= MISBEHAVE_AFTER_S:
            self.misbehave()
        error = obs.reference_rad - obs.angle_rad
        gravity_nm = 1.176 * 9.8 * 0.150 * math.cos(obs.reference_rad)
        torque_nm = 60.0 * error + 1.5 * (obs.reference_velocity_rad_s - obs.velocity_rad_s) + gravity_nm
        return torque_nm / self.nm_per_a

    def misbehave(self):
        """Nothing: this one keeps tracking."""


class Exits(Tracks):
    def misbehave(self):
        sys.exit(0)


class Interrupts(Tracks):
    def misbehave(self):
        raise KeyboardInterrupt


class ClosesGenerator(Tracks):
    def misbehave(self):
        raise GeneratorExit


class Escape(BaseException):
    """A BaseException of the controller's own."""


class RaisesBase(Tracks):
    def misbehave(self):
        raise Escape("out of here")


class Blocks(Tracks):
    blocked = False

    def misbehave(self):
        if not self.blocked:
            self.blocked = True
            time.sleep(BLOCK_S)

    def reset(self):
        """Also called when the supervisor enters SAFE: a fault that latched first does not spare the block."""
        if self.first_s is not None:
            self.misbehave()
