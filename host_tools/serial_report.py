"""The serial-mode part of a run's summary: ports, real-time quality (releases, jitter), link faults."""

from __future__ import annotations

from dataclasses import asdict

from host_tools.serial_run import SerialRunResult

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
                  "uart": asdict(fw.motor.uart.errors) if not fw.motor.link_lost else None},
        "imu": {"frames": fw.imu.frames, "checksum_errors": i.checksum_errors, "junk_bytes": i.dropped_bytes,
                "lost_frames": i.lost_frames},
    }


def serial_extra(r: SerialRunResult) -> tuple[dict, list[str]]:
    """Summary keys added in serial mode, and the lines that end report.md."""
    cfg = r.config
    link = None
    if r.link is not None:
        e = r.link
        # safe state latched this long after the driver saw the error (negative: already SAFE before)
        detection_ms = (None if e.lost_at_s is None or e.detected_at_s is None
                        else round((e.detected_at_s - e.lost_at_s) * 1e3, 3))
        link = {"role": e.role, "port": e.port, "reason": e.reason, "lost_at_s": e.lost_at_s,
                "detected_at_s": e.detected_at_s, "detection_ms": detection_ms, "reconnects": e.reconnects}
    rt = _realtime(r)
    extra = {
        "mode": "serial",
        "ports": {"motor": cfg.motor, "imu": cfg.imu, "telemetry": cfg.telemetry},
        "bauds": {"motor": cfg.baud, "imu": cfg.imu_baud, "telemetry": cfg.telemetry_baud},
        "encoder_source": cfg.encoder,
        "angle_source": r.angle_source,
        "duration_s": cfg.duration_s,
        "started_unix_s": round(r.started_unix_s, 6),
        "interrupted": r.interrupted,
        "startup_bytes": r.startup_bytes,
        "realtime": rt,
        "wire_errors": _errors(r),
        "link_lost": link,
        "telemetry_port_error": r.telemetry_port_error or None,
    }
    j = rt["release_jitter_us"]
    md = ["", "## Serial mode (wall clock)", "",
          f"Ports: motor `{cfg.motor}`, IMU `{cfg.imu}`, telemetry `{cfg.telemetry or 'file only'}`; encoder from "
          f"{cfg.encoder}; tracking error measured on the {r.angle_source}.", "",
          f"Control task released {rt['control_releases']} times (ideal {rt['control_releases_expected']}), "
          f"release jitter p50 {j['p50_us']} µs, p99 {j['p99_us']} µs, max {j['max_us']} µs; host time per "
          f"control tick {rt['host_time_per_tick_us']} µs.", "",
          "| task | jitter p50 µs | p99 µs | max µs | exec p50 µs | p99 µs | max µs |", "|---|---|---|---|---|---|---|"]
    for name, t in rt["tasks"].items():
        a, b = t["release_jitter"], t["execution"]
        md.append(f"| {name} | {a['p50_us']} | {a['p99_us']} | {a['max_us']} | {b['p50_us']} | {b['p99_us']} | "
                  f"{b['max_us']} |")
    if link is not None:
        md += ["", f"**Link lost**: {link['role']} port `{link['port']}` ({link['reason']}) at {link['lost_at_s']} s, "
               f"safe state at {link['detected_at_s']} s ({link['detection_ms']} ms); reconnects {link['reconnects']}."]
    return extra, md
