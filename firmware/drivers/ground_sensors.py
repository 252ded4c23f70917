"""The ground sensors' driver: the pylon load cell and the heel/toe FSRs, read from the ADC's DMA buffer.

The load cell's two amplifier outputs become the axial force and the sagittal moment through the part's
calibration matrix (its certificate; ``calibration`` below, N and N m per volt) after subtracting the
zero-load outputs, which the driver measures itself: averaged over ``tare_s`` after boot (the foot is off
the ground while the firmware starts) and then followed slowly in swing (time constant ``rezero_tau_s``)
to take out the bridge's drift. The FSR dividers are read as voltages; the detector
(firmware/control/ground_events.py) compares them with its thresholds. Parameters: profiles/firmware.toml,
``[ground_sensors]`` (ground_sensor_config.py). Compiled (setup.py): it runs every control period.
"""

from __future__ import annotations

import math

from firmware.drivers.ground_sensor_config import GroundSensorConfig
from hal.interfaces import Adc

__all__ = ["GroundSensorConfig", "GroundSensorDriver"]


class GroundSensorDriver:
    """Reads the four channels each control period: force (N), moment (N m), heel and toe FSR volts."""

    def __init__(self, adc: Adc, cfg: GroundSensorConfig, ts_s: float) -> None:
        """Find the channels on the ADC (ValueError naming the ADC's channels if one is missing)."""
        self.adc = adc
        self.cfg = cfg
        self.ts_s = ts_s
        self._k = (adc.index(cfg.force_channel), adc.index(cfg.moment_channel), adc.index(cfg.heel_channel),
                   adc.index(cfg.toe_channel))
        self._rail_lo = cfg.rail_margin_v
        self._rail_hi = adc.vref_v - cfg.rail_margin_v
        self._rezero_alpha = 1.0 - math.exp(-ts_s / cfg.rezero_tau_s)
        self.zero_v = [0.0, 0.0]
        self._tare_sum = [0.0, 0.0]
        self._tare_n = 0
        self.tared = False
        self.force_v = 0.0
        self.moment_v = 0.0
        self.force_n = 0.0
        self.moment_nm = 0.0
        self.heel_v = 0.0
        self.toe_v = 0.0
        self.at_rail = False  # a load-cell channel at an amplifier rail (saturated or broken)

    def sample(self, now_s: float) -> None:
        """Read the DMA buffer and convert; while taring, accumulate the zero-load outputs."""
        codes = self.adc.read()
        volts = self.adc.volts
        kf, km, kh, kt = self._k
        vf, vm = volts(codes[kf]), volts(codes[km])
        self.force_v, self.moment_v = vf, vm
        self.heel_v, self.toe_v = volts(codes[kh]), volts(codes[kt])
        self.at_rail = not (self._rail_lo < vf < self._rail_hi and self._rail_lo < vm < self._rail_hi)
        if not self.tared:
            if codes[kf] or codes[km]:  # skip the DMA buffer's zeros before the first scan
                self._tare_sum[0] += vf
                self._tare_sum[1] += vm
                self._tare_n += 1
            if now_s >= self.cfg.tare_s and self._tare_n:
                self.zero_v = [self._tare_sum[0] / self._tare_n, self._tare_sum[1] / self._tare_n]
                self.tared = True
        (a, b), (c, d) = self.cfg.calibration
        df, dm = vf - self.zero_v[0], vm - self.zero_v[1]
        self.force_n = a * df + b * dm
        self.moment_nm = c * df + d * dm

    def rezero(self) -> None:
        """Follow the zero-load outputs (call while the foot is in the air)."""
        if self.tared:
            alpha = self._rezero_alpha
            self.zero_v[0] += alpha * (self.force_v - self.zero_v[0])
            self.zero_v[1] += alpha * (self.moment_v - self.zero_v[1])
