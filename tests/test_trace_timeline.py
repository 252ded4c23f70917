"""The run's trace (trace.pftrace), read back with the perfetto package's schema alone (tests/trace_reader.py).

One walking run (20 kg, as the shipped fault campaign) with the ground sensors, a battery and a task overrun that
trips the supervisor: its interrupt slices add up to the scheduler's interference, its counters are the telemetry
records, and it has one instant per fault trip, safe command on the wire, gait event and injector act.
"""

from __future__ import annotations

import logging
import math

import pytest

from firmware.config import load_firmware_config
from hal.virtual.faults import make_injector
from hal.virtual.faults.observer import Observer
from host_tools.commands.run import controller_for
from host_tools.reports.report import TRACE_FILE, write_outputs
from host_tools.reports.timeline import COUNTERS
from host_tools.runner import RunConfig, run_virtual
from protocol.telemetry import TelemetryDecoder
from tests.trace_reader import read_trace

ONSET_S = 1.4


def _walk(**kw):
    logging.getLogger("firmware.safety").setLevel(logging.ERROR)
    fw = load_firmware_config().with_changes(controller="impedance", controller_params={})
    fault = make_injector("task_overrun", ONSET_S, 0.05, seed=3, factor=100.0, task="control")
    obs = Observer(sample=False)  # the campaign's instrument: every command the motor received
    cfg = RunConfig(strides=1, seed=0, scenario="walk", body_mass_kg=20.0, firmware=fw,
                    controller=controller_for(fw, "walk", 20.0),
                    faults=(obs, fault), duration_s=1.8, battery="molicel_p42a_6s1p", **kw)
    return run_virtual(cfg), fault, obs


@pytest.fixture(scope="module")
def walked(tmp_path_factory):
    r, fault, obs = _walk()
    out = tmp_path_factory.mktemp("walk")
    summary = write_outputs(r, out, plot=False)
    return r, fault, obs, summary, read_trace(out / TRACE_FILE), out


def _cycles(ns: int, f: int) -> int:
    return round(ns * f / 1e9)


def test_interrupt_slices_add_up_to_the_interference_the_scheduler_counted(walked):
    r, _, _, _, tr, _ = walked
    f = r.firmware.f_cpu_hz
    stats = {s.name: s for s in r.scheduler.interrupt_stats()}
    jobs = [s for s in tr.slices if tr.tracks[s.track].name in r.scheduler.stats]
    isrs = [s for s in tr.slices if tr.tracks[s.track].name.startswith("ISR ")]
    assert isrs and {tr.tracks[s.track].name for s in isrs} <= {f"ISR {n}" for n in stats}
    for name, st in stats.items():  # every firing inside a job is a slice of the source's cycles
        mine = [s for s in isrs if tr.tracks[s.track].name == f"ISR {name}"]
        assert len(mine) == st.in_jobs
        assert all(_cycles(s.dur, f) == st.cost_cycles for s in mine)
    jobs.sort(key=lambda s: s.ts)
    starts = [s.ts for s in jobs]
    inside: dict[int, int] = {}
    import bisect
    for s in isrs:  # each ISR slice lies within one job's slice
        k = bisect.bisect_right(starts, s.ts) - 1
        job = jobs[k]
        assert job.ts <= s.ts and s.ts + s.dur <= job.ts + job.dur
        inside[k] = inside.get(k, 0) + _cycles(s.dur, f)
    for k, job in enumerate(jobs):
        assert inside.get(k, 0) == job.args.get("interference_cycles", 0)
    for task, st in r.scheduler.stats.items():  # a task's job time less the ISR time in it: the statistics' own time
        if task == "bench_probe":
            continue
        mine = [k for k, j in enumerate(jobs) if tr.tracks[j.track].name == task]
        assert len(mine) == st.jobs
        assert sum(_cycles(jobs[k].dur, f) - inside.get(k, 0) for k in mine) == st.busy_cycles


def test_no_slice_overlaps_another_on_its_track(walked):
    tr = walked[4]
    by_track: dict[int, list] = {}
    for s in tr.slices:
        by_track.setdefault(s.track, []).append(s)
    for slices in by_track.values():
        slices.sort(key=lambda s: s.ts)
        assert all(s.depth == 0 for s in slices)
        assert all(a.ts + a.dur <= b.ts for a, b in zip(slices, slices[1:], strict=False))


def test_counters_are_the_telemetry_records_at_their_instants(walked):
    r, _, _, _, tr, out = walked
    f = r.firmware.f_cpu_hz
    records = TelemetryDecoder().feed((out / "telemetry.bin").read_bytes())
    assert len(records) > 100
    counters = [t for t in tr.tracks.values() if t.counter]
    assert len(counters) >= 6 + 3  # the telemetry's six, the state, the reported temperature, the bus voltage, CPU
    for field, name, unit in COUNTERS:
        got = tr.counter(name)
        want = [(r_.time_cycles * 10**9 // f,
                 math.degrees(getattr(r_, field)) if unit == "deg" else getattr(r_, field)) for r_ in records]
        assert got == want, name
    states = tr.counter("supervisor state (0 INIT, 1 RUN, 2 SAFE)")
    assert [v for _, v in states] == [0.0, 1.0, 2.0]
    for name in ("motor-reported winding temperature", "bus voltage (firmware)", "CPU utilisation"):
        values = [v for _, v in tr.counter(name)]
        assert values and all(math.isfinite(v) for v in values), name
    cpu = [v for _, v in tr.counter("CPU utilisation")]
    assert 0.0 < min(cpu) and max(cpu) <= 100.0


def test_one_instant_per_trip_safe_command_gait_event_and_injector_act(walked):
    r, fault, obs, summary, tr, _ = walked
    fw = r.firmware
    trips = [i for i in tr.instants_on("safety") if i.name.startswith("fault trip")]
    assert [(i.args["reason"], i.ts) for i in trips] == [(why, round(t * 1e9)) for t, why, _ in fw.supervisor.trips]
    assert summary["faults"] == ["DEADLINE_MISSES"] and trips[0].args["measured"] == fw.supervisor.detail
    safe = [i for i in tr.instants_on("safety") if i.name == "safe command on the wire"]
    assert len(safe) == len(trips) == 1
    assert safe[0].ts == round(obs.safe_on_wire_s(fw.supervisor.tripped_at_s) * 1e9)  # the campaign's own reading
    misses = [i for i in tr.instants_on("kernel") if i.name == "deadline miss"]
    assert len(misses) == sum(s.deadline_misses for t, s in r.scheduler.stats.items() if t != "bench_probe") > 0
    kicks = [i for i in tr.instants_on("kernel") if i.name == "watchdog kick"]
    assert len(kicks) == sum(w.kicks for w in r.scheduler._watchdogs) > 0
    ground = tr.instants_on("gait (ground sensors)")
    gs = summary["gait_events"]["ground_sensors"]
    names = [i.name for i in ground]
    assert names.count("foot flat") == gs["foot_flats"] and names.count("heel off") == gs["heel_offs"]
    assert names.count("heel strike") == len(fw.ground_events.heel_strike_s) >= 1
    assert names.count("toe off") == len(fw.ground_events.toe_off_s)
    motor = [i.name for i in tr.instants_on("gait (motor load)")]
    assert (motor.count("heel strike"), motor.count("toe off")) == (fw.load_detector.heel_strikes,
                                                                    fw.load_detector.toe_offs)
    acts = tr.instants_on("fault injector")
    assert len(acts) == fault.record.count > 0 and acts[0].ts == round(fault.record.first_s * 1e9)
    for track, detector, lists in (("gait (ground sensors)", fw.ground_events, ("heel_strike_s", "foot_flat_s",
                                                                               "heel_off_s", "toe_off_s")),
                                   ("gait (motor load)", fw.load_detector, ("heel_strike_s", "toe_off_s"))):
        got = sorted((i.ts, i.name) for i in tr.instants_on(track))  # each at the time its detector saw it
        want = sorted((round(t * 1e9), attr[:-2].replace("_", " ")) for attr in lists for t in getattr(detector, attr))
        assert got == want, track


def test_a_watchdog_reset_is_an_instant_at_the_reset(tmp_path):
    """Two higher-priority tasks overrunning together starve the control task and the watchdog's kicks: the IWDG
    resets the MCU every 50 ms; each reset the firmware counted is a kernel instant at the scheduler's time."""
    logging.getLogger("firmware.safety").setLevel(logging.ERROR)
    faults = tuple(make_injector("task_overrun", 0.3, 0.15, seed=0, factor=1000.0, task=task)
                   for task in ("encoder", "supervisor"))
    r = run_virtual(RunConfig(strides=1, seed=0, duration_s=0.6, faults=faults))
    write_outputs(r, tmp_path, plot=False)
    tr = read_trace(tmp_path / TRACE_FILE)
    f = r.firmware.f_cpu_hz
    resets = [i for i in tr.instants_on("kernel") if i.name == "watchdog reset"]
    times = [e.time for e in r.scheduler.trace.events() if e.kind == "watchdog_reset"]
    assert len(resets) == r.firmware.watchdog_resets == len(times) >= 2
    assert [i.ts for i in resets] == [t * 10**9 // f for t in times]
    assert all(0.3e9 < i.ts < (0.3 + 0.15 + 0.05) * 1e9 for i in resets)  # while starved, and its 50 ms timeout
    acts = tr.instants_on("fault injector")
    assert {a.args["fault"] for a in acts} == {x.describe() for x in faults} and len(acts) == sum(
        x.record.count for x in faults)


def test_the_trace_leaves_the_run_unchanged(walked):
    plain = _walk(trace_capacity=0)[0]
    assert (walked[5] / "telemetry.bin").read_bytes() == plain.telemetry and plain.telemetry


def test_a_window_keeps_the_last_seconds_only(tmp_path):
    r, _, _ = _walk(trace_window_s=0.3)
    write_outputs(r, tmp_path, plot=False)
    tr = read_trace(tmp_path / TRACE_FILE)
    end_ns = r.scheduler.now * 10**9 // r.firmware.f_cpu_hz
    times = [s.ts for s in tr.slices] + [s.ts for s in tr.instants] + [t for c in tr.counters.values() for t, _ in c]
    assert min(times) >= end_ns - 0.3e9 - 1 and min(times) < end_ns - 0.29e9
    assert len(r.scheduler.trace) < 0.35 * sum(s.jobs for s in r.scheduler.stats.values())  # pruned as it ran


def test_the_figure_draws_every_track_of_a_trace(walked, tmp_path):
    from host_tools.reports.trace_figure import draw, read_view

    r, _, _, _, tr, out = walked
    view = read_view(out / TRACE_FILE)
    assert {view.tracks[u][0] for u in view.rows()} == {tr.tracks[u].name for u in
                                                         {s.track for s in tr.slices + tr.instants} | set(tr.counters)}
    trip = r.firmware.supervisor.tripped_at_s
    draw(view, tmp_path / "t.png", (0.5, 1.6), (trip - 0.005, trip + 0.004))
    assert (tmp_path / "t.png").stat().st_size > 20_000
