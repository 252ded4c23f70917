"""What the ground sensors cost a walking run (--benchmark-only): the same 2-stride walk with and without them.

Figures (best of ROUNDS, wall time of ``run_virtual`` on this machine and build, see ``build``):
``walk_s_with_sensors``, ``walk_s_without``, their ratio, and ``us_per_read``: the extra wall time per
control period, which pays for the virtual ADC's conversions, the load cell and FSR models and the
ground reaction (the bench's side), and the firmware's driver and event detector. Recorded, not asserted:
the figure depends on the machine and on the build (the new modules are interpreted, setup.py).
"""

from __future__ import annotations

import time

from firmware.config import load_firmware_config
from firmware.control.registry import build_controller
from host_tools.build_info import describe
from host_tools.runner import RunConfig, run_virtual

ROUNDS = 3
STRIDES = 2


def _walk_s(sensors: bool) -> tuple[float, int]:
    cfg = load_firmware_config()
    ctl = build_controller("impedance", cfg, {"body_mass_kg": 20.0})
    t0 = time.perf_counter()
    r = run_virtual(RunConfig(strides=STRIDES, firmware=cfg, controller=ctl, scenario="walk", body_mass_kg=20.0,
                              trace_capacity=0, ground_sensors=sensors))
    return time.perf_counter() - t0, r.scheduler.stats["control"].jobs


def test_ground_sensor_cost_in_a_walking_run(benchmark):
    def measure() -> dict[str, float]:
        with_s = min(_walk_s(True)[0] for _ in range(ROUNDS))
        without_s, periods = min(_walk_s(False) for _ in range(ROUNDS))
        return {"walk_s_with_sensors": round(with_s, 3), "walk_s_without": round(without_s, 3),
                "ratio": round(with_s / without_s, 2), "us_per_read": round((with_s - without_s) / periods * 1e6, 1)}

    figures = benchmark.pedantic(measure, rounds=1, iterations=1)
    benchmark.extra_info.update(figures)
    benchmark.extra_info["build"] = describe()
    assert figures["walk_s_with_sensors"] > 0 and figures["walk_s_without"] > 0
