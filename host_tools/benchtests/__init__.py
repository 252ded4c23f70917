"""Plant-level reproductions of the report's bench-top tests (`pafp bench`)."""

from __future__ import annotations

from hal.registry import Registry

TESTS = Registry("bench test", {
    "uncontrolled": "host_tools.benchtests.uncontrolled",
    "backdrive": "host_tools.benchtests.backdrive",
    "fast-response": "host_tools.benchtests.fast_response",
    "loading": "host_tools.benchtests.loading",
    "tracking": "host_tools.benchtests.tracking",
    "baud-study": "host_tools.benchtests.baud_study",
    "spring-calibration": "host_tools.benchtests.spring_calibration",
    "design-point": "host_tools.benchtests.design_point",
    "link-study": "host_tools.benchtests.link_study",
    "motor-tf": "host_tools.benchtests.motor_tf",
    "open-loop": "host_tools.benchtests.open_loop",
    "root-locus": "host_tools.benchtests.root_locus",
    "kinematics": "host_tools.benchtests.kinematics",
}, group="pafp.benchtests")
"""Test name -> its module (each has run(seed=..., quick=...) -> BenchResult), in `pafp bench all` order."""
