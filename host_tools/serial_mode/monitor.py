"""Live telemetry monitor: decode a stream, keep the latest values, rates and faults, write CSV incrementally.

The CSV gets the header at once and then one write of whole lines per batch of records, flushed each time,
so a monitor killed at any moment leaves a valid CSV up to its last complete line. Lost records are
counted from sequence gaps (`TelemetryDecoder`).
"""

from __future__ import annotations

import csv
import io
import time
from collections import deque
from dataclasses import dataclass, field
from pathlib import Path
from typing import TextIO

from protocol.telemetry import (
    RECORD_COLUMNS,
    FaultReason,
    SupervisorState,
    TelemetryDecoder,
    TelemetryRecord,
    record_to_row,
)

__all__ = ["CsvSink", "MonitorState", "render"]


class CsvSink:
    """Appends records as CSV rows; every batch is written whole and flushed."""

    def __init__(self, path: Path, extra_names: tuple[str, ...] = ()) -> None:
        """Create (truncate) path and write the header line (base columns, then `extra_names`)."""
        self.path = path
        self.extra_names = extra_names
        self._f: TextIO = path.open("w", newline="", encoding="utf-8")
        self._buf = io.StringIO()
        self._w = csv.DictWriter(self._buf, fieldnames=[*RECORD_COLUMNS, *extra_names], extrasaction="ignore")
        self._w.writeheader()
        self.rows = 0
        self._flush()

    def _flush(self) -> None:
        self._f.write(self._buf.getvalue())
        self._f.flush()
        self._buf.seek(0)
        self._buf.truncate()

    def write(self, records: list[TelemetryRecord]) -> None:
        """Write the rows of records in one go and flush."""
        if not records:
            return
        for rec in records:
            self._w.writerow(record_to_row(rec, self.extra_names))
        self.rows += len(records)
        self._flush()

    def close(self) -> None:
        """Close the file."""
        self._f.close()


@dataclass
class MonitorState:
    """What the view shows: the latest record, arrival rate over the last second, faults seen."""

    decoder: TelemetryDecoder = field(default_factory=TelemetryDecoder)
    latest: TelemetryRecord | None = None
    faults: list[str] = field(default_factory=list)
    _arrivals: deque = field(default_factory=deque)

    def feed(self, data: bytes, now_s: float) -> list[TelemetryRecord]:
        """Decode data received at now_s; return the new records."""
        records = self.decoder.feed(data)
        for rec in records:
            self._arrivals.append(now_s)
            reason = rec.fault_reason
            name = reason.name if isinstance(reason, FaultReason) else f"UNKNOWN_{reason}"
            if reason and (not self.faults or self.faults[-1] != name):
                self.faults.append(name)
        if records:
            self.latest = records[-1]
        while self._arrivals and self._arrivals[0] < now_s - 1.0:
            self._arrivals.popleft()
        return records

    def rate_hz(self) -> int:
        """Records received during the last second."""
        return len(self._arrivals)

    def summary(self) -> str:
        """One line: records, lost, errors, faults."""
        st = self.decoder.stats
        return (f"records {st.records}, lost {st.lost_records} (sequence gaps), crc errors {st.crc_errors}, "
                f"bad frames {st.bad_frames}, junk bytes {st.dropped_bytes}, faults {', '.join(self.faults) or 'none'}")


def render(state: MonitorState, source: str) -> str:
    """The refreshing terminal view: latest values, rate, losses and faults."""
    rec = state.latest
    lines = [f"pafp monitor {source}  {time.strftime('%H:%M:%S')}  rate {state.rate_hz()} rec/s", state.summary()]
    if rec is None:
        lines.append("(no record yet)")
        return "\n".join(lines)
    s = rec.supervisor_state
    lines += [
        f"seq {rec.seq}  time_cycles {rec.time_cycles}",
        f"state {s.name if isinstance(s, SupervisorState) else s}   deadline misses {rec.deadline_misses}",
    ]
    row = record_to_row(rec)
    for col in ("reference_deg", "encoder_angle_deg", "imu_pitch_deg", "fused_angle_deg", "velocity_deg_s",
                "current_cmd_a", "current_meas_a", "torque_est_nm"):
        if col in row:
            lines.append(f"  {col:<20}{float(row[col]):>12.3f}")
    return "\n".join(lines)
