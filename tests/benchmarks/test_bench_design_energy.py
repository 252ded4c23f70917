"""Issue 38's regeneration bound on the shipped adult design over 20 strides at free and fast speed (--benchmark-only):
the energy ledger of host_tools/studies/design_energy.py, and docs/design.md's table of it kept current.

tests/test_energy_direction.py asserts the same on 3 strides; these 20 reach the walk's steady state (the
regeneration per stride settles after about the 10th stride), and the bound is asserted on the second half alone too.
"""

from __future__ import annotations

from host_tools.studies.design_docs import block
from host_tools.studies.design_energy import (
    ADULT_PROFILE,
    SPEEDS,
    TABLE_STRIDES,
    StrideEnergy,
    WalkEnergy,
    walk_energy,
    walk_tables,
)
from profiles import profile_path


def _mean(strides: list[StrideEnergy], name: str) -> float:
    return sum(getattr(s, name) for s in strides) / len(strides)


def test_bench_adult_design_regeneration_bound(benchmark) -> None:
    walks: dict[str, WalkEnergy] = {}

    def run() -> None:
        walks.update({s: walk_energy(profile_path(ADULT_PROFILE), s, TABLE_STRIDES) for s in SPEEDS})

    benchmark.pedantic(run, rounds=1, iterations=1)
    for speed, walk in walks.items():
        assert not walk.faults and walk.complete and len(walk.strides) == TABLE_STRIDES, speed
        for stride in walk.strides:
            assert 0.0 < stride.regenerated_j <= stride.rotor_absorbed_j <= walk.eta_back * stride.actuator_absorbed_j \
                * 1.02, (speed, stride)
        steady = walk.strides[TABLE_STRIDES // 2:]
        for strides in (walk.strides, steady):
            assert _mean(strides, "regenerated_j") <= walk.eta_back * _mean(strides, "joint_negative_j"), speed
        # why the curve's negative work is not this walk's bound: the ankle yields past the curve's angle in stance
        assert walk.mean("joint_negative_j") > 2.0 * walk.curve_negative_j, speed
        benchmark.extra_info[speed] = {k: round(v, 3) for k, v in walk.means().items()}
    table = walk_tables(walks)
    assert block("design_energy") == table, (
        "docs/design.md's design_energy table is stale: python -m host_tools.studies.design_docs energy\n" + table)
