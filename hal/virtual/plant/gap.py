"""The gearbox's backlash: the rotor's place in the free play and its motion while it crosses (docs/plant.md).

Angles and speeds are the rotor's, relative to N x the output's (N the total ratio): the rotor rests at +-half the
gap on the side the teeth are in contact, and while free moves with the relative acceleration Kt i_cmd / J_m -
N alpha_out held from the command that freed it. `Plant` owns one and tells it each current command (`command`,
then `free_under` when it frees the rotor); its rotor queries read `motion`.
"""

from __future__ import annotations


class Gap:
    """The rotor in the gearbox's free play: its angle, speed and acceleration in it since the last command.

    >>> gap = Gap(half_rad=0.03, start_time_s=0.0, kt_over_jm=3200.0, ratio=36.0)
    >>> gap.command(0.0, 1), gap.motion(0.0)  # the first command: the teeth rest on its side
    (False, (0.03, 0.0))
    >>> gap.command(0.001, -1)  # a reversal frees the rotor
    True
    >>> gap.free_under(-2.0, 0.0)  # pushed by -2 A, the output not accelerating
    >>> gap.motion(0.006)  # crossed in 4.3 ms (0.06 rad at 6400 rad/s^2): stopped at the other end
    (-0.03, 0.0)
    """

    def __init__(self, half_rad: float, start_time_s: float, kt_over_jm: float, ratio: float) -> None:
        """A gap of +-half_rad at the rotor (0: none), the rotor's Kt/J_m and the ratio N, from start_time_s."""
        self.half = half_rad
        self.kt_over_jm = kt_over_jm
        self.ratio = ratio
        self.phi = 0.0  # the rotor's angle in the gap at the last command
        self.w = 0.0  # its speed there
        self.t = start_time_s  # the last command's time
        self.a = 0.0  # the relative acceleration while free over the interval since
        self.free = False
        self.contact = 0  # +1/-1: the side of the gap the teeth rest on; 0: free or not yet known
        self.crossings = 0  # reversals that freed the rotor

    def command(self, t_s: float, side: int) -> bool:
        """Move the rotor to t_s (the last command's motion, stopped at either end: contact, the impact's momentum
        not passed on), then take a current command of sign `side` (+1, -1, 0): whether the rotor is free after it.

        The teeth stay engaged while the command pushes towards the side in contact; a command of the other sign
        frees the rotor (a crossing: `free_under` must then give its acceleration)."""
        half = self.half
        if self.free:  # move the rotor through the gap over the interval since the last command
            dt = t_s - self.t
            a = self.a
            phi = self.phi + self.w * dt + 0.5 * a * dt * dt
            w = self.w + a * dt
            if phi >= half or phi <= -half:
                self.contact = 1 if phi > 0.0 else -1
                phi = half * self.contact
                w = 0.0
                self.free = False
            self.phi, self.w = phi, w
        elif self.contact == 0 and side != 0:  # the first command: the teeth rest on its side
            self.contact = side
            self.phi = half * side
        if not self.free and side != 0 and side != self.contact and self.contact != 0:
            self.free = True  # a reversal: the rotor leaves contact
            self.contact = 0
            self.crossings += 1
        self.t = t_s
        return self.free

    def free_under(self, command_a: float, output_accel_rad_s2: float) -> None:
        """While free: the relative acceleration the command (A) gives the rotor against the output's (held until
        the next command: commands come every control period)."""
        self.a = self.kt_over_jm * command_a - self.ratio * output_accel_rad_s2

    def motion(self, t_s: float) -> tuple[float, float]:
        """(angle [rad], speed [rad/s]) of the rotor in the gap at t_s (not before the last command).

        In contact it rests at +-half the gap; while free it moves as `command` integrates it, stopped at either
        end (the next command finds it there)."""
        if not self.free:
            return self.phi, 0.0
        dt = t_s - self.t
        a = self.a
        phi = self.phi + (self.w + 0.5 * a * dt) * dt
        half = self.half
        if phi >= half:
            return half, 0.0
        if phi <= -half:
            return -half, 0.0
        return phi, self.w + a * dt
