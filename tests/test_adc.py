"""The ADC peripheral: the interface's checks, the virtual STM32 ADC's timing, quantisation, saturation, noise."""

from __future__ import annotations

import math
import statistics

import pytest

from hal.errors import HalError
from hal.interfaces import Adc
from hal.virtual.adc import NOISE_BLOCK, AdcTiming, VirtualAdc, noise_block

F_CPU = 168_000_000


def _adc(sources, t, **kw):
    return VirtualAdc(lambda: t[0], F_CPU, [f"ch{k}" for k in range(len(sources))], sources, **kw)


def test_conversion_time_is_sampling_plus_12_adc_cycles_and_the_scan_must_fit():
    timing = AdcTiming(F_CPU, 4, 1000.0, 21e6, 84.0, 12.0)
    assert timing.conversion_s == pytest.approx(96 / 21e6)  # RM0090 13.5: 84 + 12 cycles at 21 MHz = 4.57 us
    assert timing.ready_cycles(3, 0) == pytest.approx(4 * 96 / 21e6 * F_CPU)
    with pytest.raises(ValueError, match="longer than the 10.0 us trigger period"):
        AdcTiming(F_CPU, 4, 100_000.0, 21e6, 480.0)
    with pytest.raises(ValueError, match="adc_clock_hz 40000000.0 out of range"):
        AdcTiming(F_CPU, 1, 1000.0, 40e6, 84.0)


def test_a_code_appears_only_once_its_conversion_has_ended():
    t = [0]
    adc = _adc([lambda c: 1.0, lambda c: 2.0], t)
    conv = adc.timing.conv_cycles
    t[0] = int(conv) - 1
    assert adc.read() == [0, 0]  # nothing converted yet: the DMA buffer's initial zeros
    t[0] = int(conv) + 1
    assert adc.read()[0] == math.floor(1.0 / 3.3 * 4096 + 0.5) and adc.read()[1] == 0
    t[0] = int(2 * conv) + 1
    assert adc.read() == [1241, 2482]


def test_the_held_value_is_the_inputs_at_the_end_of_its_sampling_window():
    t = [0]
    seen = []
    adc = _adc([lambda c: seen.append(c) or 1.0], t, sample_rate_hz=1000.0)
    t[0] = 5 * F_CPU // 1000 + 10_000  # after the sixth trigger's conversion
    adc.read()
    assert seen == [int(5 * F_CPU / 1000 + 84 / 21e6 * F_CPU)]


@pytest.mark.parametrize("volts, code", [(0.0, 0), (3.3 / 4096 * 0.49, 0), (3.3 / 4096 * 0.51, 1), (1.65, 2048),
                                         (3.3 * 4095 / 4096, 4095), (3.3, 4095), (5.0, 4095), (-1.0, 0)])
def test_quantisation_rounds_to_the_nearest_lsb_and_saturates_at_the_ends(volts, code):
    t = [F_CPU]
    assert _adc([lambda c: volts], t).read() == [code]


def test_volts_is_the_inverse_within_one_lsb():
    t = [F_CPU]
    adc = _adc([lambda c: 1.234], t)
    assert abs(adc.volts(adc.read()[0]) - 1.234) <= adc.vref_v / 4096


def test_noise_has_its_rms_and_is_the_same_whenever_the_firmware_looks():
    t = [0]
    a = _adc([lambda c: 1.65], t, noise_lsb_rms=2.0, seed=7)
    b = _adc([lambda c: 1.65], t, noise_lsb_rms=2.0, seed=7)
    period = F_CPU // 1000
    codes_a, codes_b = [], []
    for n in range(1, 2001):
        t[0] = n * period + 5000
        codes_a.append(a.read()[0])
        if n % 2 == 0:  # b looks half as often: the codes it sees are the same as a's
            codes_b.append(b.read()[0])
    assert codes_b == codes_a[1::2]
    assert statistics.pstdev(codes_a) == pytest.approx(2.0, rel=0.1)
    other = _adc([lambda c: 1.65], [t[0]], noise_lsb_rms=2.0, seed=8)
    assert [other.convert(0, n) for n in range(1, 51)] != codes_a[:50]  # another seed, other noise
    assert a.noise(0, NOISE_BLOCK + 3) == noise_block(7, 0, 1)[3]  # the second block, by its own seed


def test_interface_checks_and_the_backend_contract():
    with pytest.raises(ValueError, match="distinct non-empty names"):
        VirtualAdc(lambda: 0, F_CPU, ["a", "a"], [lambda c: 0.0] * 2)
    with pytest.raises(ValueError, match="bits 20 out of range"):
        VirtualAdc(lambda: 0, F_CPU, ["a"], [lambda c: 0.0], bits=20)
    with pytest.raises(ValueError, match="1 sources for 2 ADC channels"):
        VirtualAdc(lambda: 0, F_CPU, ["a", "b"], [lambda c: 0.0])

    class Short(Adc):
        def _dma_buffer(self):
            return [1]

    with pytest.raises(HalError, match="1 codes for 2 channels"):
        Short(["a", "b"]).read()
    assert Short(["a"]).index("a") == 0 and Short(["a"], bits=10).full_scale == 1023
    with pytest.raises(ValueError, match="ADC channel 'b' unknown"):
        Short(["a"]).index("b")
