"""Plant-level reproductions of the report's bench-top tests (`pafp bench`)."""

from __future__ import annotations

#: Test name -> module under host_tools.benchtests (each has run(seed=..., quick=...) -> BenchResult).
TESTS: dict[str, str] = {
    "uncontrolled": "uncontrolled",
    "backdrive": "backdrive",
    "fast-response": "fast_response",
    "loading": "loading",
    "tracking": "tracking",
    "baud-study": "baud_study",
    "spring-calibration": "spring_calibration",
    "design-point": "design_point",
    "link-study": "link_study",
    "motor-tf": "motor_tf",
    "open-loop": "open_loop",
    "root-locus": "root_locus",
    "kinematics": "kinematics",
}
