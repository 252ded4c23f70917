"""The serial-mode part of a run's summary: ports, stop, real-time quality (releases, jitter), link faults."""

from __future__ import annotations

from dataclasses import asdict

from host_tools.serial_mode.serial_run import SerialRunResult

__all__ = ["CONTROL_TASKS", "serial_extra"]

CONTROL_TASKS = ("encoder", "supervisor", "control", "motor")  # one control tick, in release order


def _realtime(r: SerialRunResult) -> dict:
    """Releases of the control task against the ideal count, jitter and host time per tick."""
    sched, f_cpu = r.scheduler, r.firmware.f_cpu_hz
    ctl = sched.stats["control"]
    period = next(t.period for t in sched.tasks if t.name == "control")
    elapsed = min(sched.now, round(r.config.duration_s * f_cpu))
    releases = sched.releases("control", before=elapsed)  # the same span as the expected count
    timings = r.timings.as_dict()
    tick_us = [r.timings.execution[n].mean_us() for n in CONTROL_TASKS]
    return {
        "late_releases": sum(r.timings.late_releases.values()),
        "overruns": sum(r.timings.overruns.values()),
        "skipped_releases": sum(sched.stats[n].skipped for n in r.timings.jitter),
        "control_releases": releases,
        "control_releases_expected": -(-elapsed // period),  # releases at 0, T, 2T, ... before the end
        "control_jobs": ctl.jobs,
        "control_skipped": ctl.skipped,
        "release_jitter_us": timings["control"]["release_jitter"],
        "host_time_per_tick_us": None if None in tick_us else round(sum(tick_us), 2),  # type: ignore[arg-type]
        "tasks": timings,
        "elapsed_s": round(elapsed / f_cpu, 6),
    }


def _errors(r: SerialRunResult) -> dict:
    """What went wrong on the wires and was survived: junk, CRC errors, lost frames."""
    fw = r.firmware
    m, i = fw.motor.decoder.stats, fw.imu.decoder.stats
    return {
        "motor": {"crc_errors": m.crc_errors, "junk_bytes": m.dropped_bytes, "bad_end_bytes": m.bad_end_bytes,
                  "missing_replies": fw.motor.stats.missing_replies, "stale_replies": fw.motor.stats.stale_replies,
                  "uart": asdict(fw.motor.uart.errors) if hasattr(fw.motor, "uart") and not fw.motor.link_lost
                  else None},
        "imu": {"frames": fw.imu.frames, "checksum_errors": i.checksum_errors,
                "out_of_range_frames": i.range_errors, "junk_bytes": i.dropped_bytes,
                "lost_frames": i.lost_frames},
    }


def serial_extra(r: SerialRunResult) -> tuple[dict, list[str]]:
    """Summary keys added in serial mode, and the lines that end report.md."""
    cfg = r.config
    link = None
    if r.link is not None:
        e = r.link
        # from the first failed read or write to the supervisor's first look at the lost link (never negative)
        detection_ms = (None if e.lost_at_s is None or e.detected_at_s is None
                        else round((e.detected_at_s - e.lost_at_s) * 1e3, 3))
        link = {"role": e.role, "port": e.port, "reason": e.reason, "lost_at_s": e.lost_at_s,
                "detected_at_s": e.detected_at_s, "detection_ms": detection_ms, "reconnects": e.reconnects}
    rt = _realtime(r)
    stop = r.stop.as_dict()
    sup = r.firmware.supervisor
    warnings = {"deadline_miss_streaks": sup.miss_streak_warnings, "watchdog_expiries": r.warnings.watchdog_expiries,
                "first_watchdog_s": r.warnings.first_watchdog_s}
    extra = {
        "mode": "serial",
        "ports": {"motor": cfg.motor, "imu": cfg.imu, "telemetry": cfg.telemetry},
        "bauds": {"motor": cfg.baud, "imu": cfg.imu_baud, "telemetry": cfg.telemetry_baud},
        "encoder_source": cfg.encoder,
        "angle_source": r.angle_source,
        "duration_s": cfg.duration_s,
        "started_unix_s": round(r.started_unix_s, 6),
        "interrupted": r.interrupted,
        "stop": stop,
        "time_in_run_s": round(r.time_in_run_s, 6),
        "exit_code": r.exit_code,
        "host_warnings": warnings,
        "fault": None if sup.tripped_at_s is None else {"reason": sup.reason.name, "at_s": round(sup.tripped_at_s, 6),
                                                       "detail": sup.detail or None},
        "realtime_settings": r.realtime_granted,
        "startup_bytes": r.startup_bytes,
        "realtime": rt,
        "wire_errors": _errors(r),
        "link_lost": link,
        "host_watchdog": r.host_watchdog.as_dict() if r.host_watchdog is not None else None,
        "telemetry_port_error": r.telemetry_port_error or None,
    }
    j = rt["release_jitter_us"]
    safe = ", ".join(stop["safe_frames"]) or "none"
    md = ["", "## Serial mode (wall clock)", "",
          f"Stopped by {stop['reason']}{' ' + stop['signal'] if stop['signal'] else ''} at {stop['at_s']} s; "
          f"stop path: {safe}, {'on the wire' if stop['safe_on_wire'] else 'NOT all on the wire'} "
          f"{stop['latency_ms']} ms after the stop began (goal {stop['goal_ms']} ms)."
          + (f" The host watchdog fired: {stop['error']}, task `{stop['task']}` running."
             if stop["reason"] == "watchdog"
             else f" Task `{stop['task']}` raised {stop['error']}." if stop["error"] else ""), "",
          f"Host stalls (warnings, not faults): {warnings['deadline_miss_streaks']} deadline-miss streaks, "
          f"{warnings['watchdog_expiries']} watchdog expiries; {rt['late_releases']} late releases, "
          f"{rt['overruns']} overruns, {rt['skipped_releases']} skipped releases. Real-time settings: "
          + "; ".join(f"{k} {v}" for k, v in r.realtime_granted.items() if k != "requested") + ".", "",
          f"Ports: motor `{cfg.motor}`, IMU `{cfg.imu}`, telemetry `{cfg.telemetry or 'file only'}`; encoder from "
          f"{cfg.encoder}; tracking error measured on the {r.angle_source}.", "",
          f"Control task released {rt['control_releases']} times (ideal {rt['control_releases_expected']}), "
          f"release jitter p50 {j['p50_us']} µs, p99 {j['p99_us']} µs, max {j['max_us']} µs; host time per "
          f"control tick {rt['host_time_per_tick_us']} µs.", "",
          "| task | jitter p50 µs | p99 µs | max µs | exec p50 µs | p99 µs | max µs | late releases | overruns |",
          "|---|---|---|---|---|---|---|---|---|"]
    for name, t in rt["tasks"].items():
        a, b = t["release_jitter"], t["execution"]
        md.append(f"| {name} | {a['p50_us']} | {a['p99_us']} | {a['max_us']} | {b['p50_us']} | {b['p99_us']} | "
                  f"{b['max_us']} | {t['late_releases']} | {t['overruns']} |")
    hw = extra["host_watchdog"]
    if hw is not None:
        md += ["", f"Host watchdog ({hw['timeout_ms']} ms): {hw['handle']}"
               + (f"; fired at {hw['fired_at_s']} s, {hw['silent_ms']} ms after the last kick (task `{hw['task']}` "
                  f"running), {hw['sends']} sends of the safe frames." if hw["fired"] else "; did not fire.")]
    if link is not None:
        md += ["", f"**Link lost**: {link['role']} port `{link['port']}` ({link['reason']}) at {link['lost_at_s']} s, "
               f"safe state at {link['detected_at_s']} s ({link['detection_ms']} ms); reconnects {link['reconnects']}."]
    return extra, md
