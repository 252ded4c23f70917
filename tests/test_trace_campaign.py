"""A fault campaign's worst-point trace (plots/trace_point_N.pftrace): the injector's acts and the safe command."""

from __future__ import annotations

from host_tools.studies.fault_report import _trace
from host_tools.studies.fault_spec import load_fault_spec
from tests.test_fault_campaign import spec_file
from tests.trace_reader import read_trace


def test_a_worst_point_trace_carries_the_injector_and_the_safe_command(tmp_path):
    from host_tools.studies.fault_point import faulted_run

    spec = load_fault_spec(spec_file(tmp_path))
    index = 0  # motor_replies_lost at the stride's start: MOTOR_TIMEOUT, then the safe command
    _trace(tmp_path / "trace_point_0.png", spec, index)
    tr = read_trace(tmp_path / "trace_point_0.pftrace")
    r, fault, obs, _onset = faulted_run(spec.points()[index])  # the same point again, untraced: the reference
    acts = tr.instants_on("fault injector")
    assert len(acts) == fault.record.count > 0
    assert [a.ts for a in acts] == [round(t * 1e9) for t in fault.record.times_s]
    assert {a.args["fault"] for a in acts} == {fault.describe()}
    sup = r.firmware.supervisor
    trips = [i for i in tr.instants_on("safety") if i.name.startswith("fault trip")]
    assert [i.args["reason"] for i in trips] == [sup.reason.name] == ["MOTOR_TIMEOUT"]
    safe = [i for i in tr.instants_on("safety") if i.name == "safe command on the wire"]
    assert [i.ts for i in safe] == [round(obs.safe_on_wire_s(sup.tripped_at_s) * 1e9)]
    assert (tmp_path / "trace_point_0.png").stat().st_size > 1000
