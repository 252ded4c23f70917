"""Settings of the AK60-6 driver model: link behaviour, inner-loop gains, supply, thermal model, limits.

Values marked [I] are our assumptions (CubeMars publishes none of them); the others cite their source.
See docs/devices.md for the reasoning behind each number.
"""

from __future__ import annotations

from dataclasses import dataclass

from hal.virtual.checks import check_field_ranges

__all__ = ["Ak60Config"]

# field -> (lowest, highest) allowed; checked in __post_init__
_RANGES: dict[str, tuple[float, float]] = {
    "reply_latency_s": (0.0, 0.1),
    "timeout_s": (0.0, 3600.0),
    "timeout_brake_current_a": (0.0, 100.0),
    "winding_period_s": (1e-6, 1e-3),
    "rotor_position_scale": (1.0, 1e7),
    "stream_period_s": (1e-4, 10.0),
    "controller_id": (0, 255),
    "fw_major": (0, 255),
    "fw_minor": (0, 255),
    "inner_loop_period_s": (1e-5, 0.1),
    "speed_kp_a_s_per_rad": (0.0, 100.0),
    "speed_ki_a_per_rad": (0.0, 1e4),
    "position_kp_per_s": (0.0, 1e4),
    "pos_speed_erpm": (1.0, 1e6),
    "pos_accel_erpm_per_s": (1.0, 1e8),
    "max_duty": (0.0, 1.0),
    "source_resistance_ohm": (0.0, 10.0),
    "min_input_voltage_v": (0.0, 100.0),
    "max_input_voltage_ratio": (1.0, 10.0),
    "abs_max_current_a": (0.1, 1000.0),
    "fault_stop_time_s": (0.0, 60.0),
    "ambient_c": (-40.0, 100.0),
    "winding_heat_capacity_j_per_k": (0.01, 1e5),
    "winding_thermal_resistance_k_per_w": (0.01, 1e3),
    "fet_heat_capacity_j_per_k": (0.01, 1e5),
    "fet_thermal_resistance_k_per_w": (0.01, 1e3),
    "fet_resistance_ohm": (0.0, 1.0),
    "temp_fet_max_c": (0.0, 300.0),
    "temp_motor_max_c": (0.0, 300.0),
}


@dataclass(frozen=True)
class Ak60Config:
    """Everything about the AK60-6 driver model that is not plant physics (SI units, degC)."""

    reply_latency_s: float = 50e-6
    """[I] from the stop bit of a request's last byte to the start bit of the reply's first byte."""
    timeout_s: float = 1.0
    """Command timeout: VESC ``APPCONF_TIMEOUT_MSEC`` 1000 (0: none); then the timeout brake (or release)."""
    timeout_brake_current_a: float = 0.0
    """Brake current after the command timeout (VESC ``APPCONF_TIMEOUT_BRAKE_CURRENT``, default 0.0: release);
    a value > 0 is the regenerative brake (capped by the short-circuit current). Set in the drive's app
    configuration with the maker's tool: none of the AK's command sets (UART servo, CAN servo, MIT) carries it."""
    rotor_position_scale: float = 1e4
    """ROTOR_POSITION wire scale (degrees x 1e4, the CubeMars manual capture; VESC uses 1e5)."""
    stream_period_s: float = 0.010
    """Period of the unsolicited ROTOR_POSITION frames after SET_DETECT 4 (manual p.41, VESC main.c)."""
    selective_mask_echo: bool = True
    """GET_VALUES_SELECTIVE reply repeats the mask (VESC); False = the manual example's form."""
    controller_id: int = 0x7E
    """Reported in GET_VALUES byte 58 (0x7E in the manual's p.41 capture)."""
    fw_major: int = 3
    """[I] FW_VERSION reply (CubeMars values are undocumented; a short 3.x-style reply)."""
    fw_minor: int = 65
    """[I] FW_VERSION minor."""
    hw_name: str = "AK60-6"
    """[I] FW_VERSION hardware name."""
    uuid: bytes = b"pafp-ak60-6\x00"
    """[I] FW_VERSION 12-byte UUID."""
    inner_loop_period_s: float = 1e-3
    """[I] period of the driver's own duty/speed/position loops (they produce the current command)."""
    speed_kp_a_s_per_rad: float = 0.1
    """[I] speed PI: amperes per rad/s of motor-side speed error (about 20 Hz bandwidth on the bench)."""
    speed_ki_a_per_rad: float = 2.5
    """[I] speed PI: amperes per rad of integrated motor-side speed error."""
    position_kp_per_s: float = 30.0
    """[I] position P: motor-side speed reference (rad/s) per rad of motor-side position error."""
    pos_speed_erpm: float = 12000.0
    """Default position-mode speed limit (manual p.32: 12000 ERPM)."""
    pos_accel_erpm_per_s: float = 40000.0
    """Default position-mode acceleration limit (manual p.32: 40000 ERPM/s)."""
    winding_period_s: float = 1e-4
    """[I] how often the winding's laws (duty, brake, handbrake: ak60_winding) are evaluated at the rotor's angle
    and speed: 10 kHz, the plant's step, well inside VESC's 20-30 kHz FOC loop and 10x faster than the
    mechanical time constant of the phase short (about 2 ms at the ankle), so the sampling adds no lag of note."""
    max_duty: float = 0.95
    """Largest duty cycle (VESC ``l_max_duty`` 0.95)."""
    source_resistance_ohm: float = 0.05
    """[I] supply and wiring resistance: v_in sags by R_src x input current."""
    min_input_voltage_v: float = 8.0
    """UNDER_VOLTAGE below this input voltage (VESC ``l_min_vin`` 8 V)."""
    max_input_voltage_ratio: float = 1.25
    """[I] OVER_VOLTAGE above this multiple of the motor's rated supply voltage (the VESC trips
    FAULT_CODE_OVER_VOLTAGE when the input voltage exceeds ``l_max_vin``, mc_interface.c). CubeMars rates the
    AK60-6 at 24 V and publishes no maximum in the sources held here: 1.25 x 24 V = 30 V, above a full 6S Li-ion
    pack's 25.2 V (and 60 V for the 48 V motors, above a full 12S pack's 50.4 V); see :meth:`over_voltage_v`."""
    abs_max_current_a: float = 30.0
    """[I] ABS_OVER_CURRENT above this |i_q| (the plant clamps at 22.7 A, so only injection trips it)."""
    fault_stop_time_s: float = 0.5
    """A fault holds this long, commands ignored, motor released (VESC ``MCCONF_M_FAULT_STOP_TIME`` 500 ms)."""
    ambient_c: float = 25.0
    """[I] ambient and initial temperature."""
    winding_heat_capacity_j_per_k: float = 25.0
    """[I] winding node: ~65 g of copper x 385 J/(kg K)."""
    winding_thermal_resistance_k_per_w: float = 7.6
    """[I] winding to ambient (the single-node estimate without the two-node model): 49 K rise at the rated 6.5 A
    (6.4 W, the q-axis copper loss 0.75 x 0.202 ohm x 6.5^2; set for 65 K at the DC loss 0.202 x 6.5^2); tau = 190 s."""
    fet_heat_capacity_j_per_k: float = 2.0
    """[I] MOSFETs and their copper pour."""
    fet_thermal_resistance_k_per_w: float = 10.0
    """[I] MOSFETs to ambient (tau = 20 s)."""
    fet_resistance_ohm: float = 0.01
    """[I] conduction resistance of the bridge in the current path (two 5 mOhm switches); the meter charges
    0.75 x this x i_q^2, as the copper (ak60_meter.py)."""
    temp_fet_max_c: float = 100.0
    """OVER_TEMP_FET above this (VESC ``l_temp_fet_end`` 100 degC; VESC derates from 85, not modelled)."""
    temp_motor_max_c: float = 100.0
    """OVER_TEMP_MOTOR above this (VESC ``l_temp_motor_end`` 100 degC)."""

    def __post_init__(self) -> None:
        """Check every number against its allowed range."""
        check_field_ranges(self, _RANGES)
        if len(self.uuid) != 12:
            raise ValueError(f"Ak60Config.uuid must be exactly 12 bytes, got {len(self.uuid)}")
        if "\0" in self.hw_name or not self.hw_name.isprintable():
            raise ValueError(f"Ak60Config.hw_name = {self.hw_name!r} must be printable text without NUL")

    def over_voltage_v(self, rated_supply_v: float) -> float:
        """The input voltage above which the driver of a motor rated for ``rated_supply_v`` trips OVER_VOLTAGE."""
        return self.max_input_voltage_ratio * rated_supply_v

    def check_supply(self, full_v: float, rated_supply_v: float, what: str) -> None:
        """ValueError (one line) when a supply of ``full_v`` (``what``: the pack's name) would trip the driver of a
        motor rated for ``rated_supply_v`` at once: a pack of the wrong voltage for the motor.

        >>> Ak60Config().check_supply(126.0, 24.0, "battery x")
        Traceback (most recent call last):
        ...
        ValueError: battery x: 126 V full is above the driver's over-voltage trip of 30 V (1.25 x the motor's \
rated 24 V): choose a pack for the motor's supply voltage
        """
        limit = self.over_voltage_v(rated_supply_v)
        if full_v > limit:
            raise ValueError(f"{what}: {full_v:.4g} V full is above the driver's over-voltage trip of {limit:.4g} V "
                             f"({self.max_input_voltage_ratio:g} x the motor's rated {rated_supply_v:g} V): choose "
                             "a pack for the motor's supply voltage")

    @property
    def thermal_time_constants_s(self) -> tuple[float, float]:
        """(winding, FET) first-order time constants, C x R_th."""
        return (self.winding_heat_capacity_j_per_k * self.winding_thermal_resistance_k_per_w,
                self.fet_heat_capacity_j_per_k * self.fet_thermal_resistance_k_per_w)
