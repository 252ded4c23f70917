"""The files a virtual run writes as it goes, so that its memory does not grow with its length.

:func:`host_tools.runner.run_virtual` runs the scheduler in segments of simulated time and, after each,
hands what the segment produced to a :class:`RunFiles`: the telemetry UART's bytes are appended to
``telemetry.bin`` and decoded into ``telemetry.csv`` (its decoder's counters go to the summary), and the
bench probe's samples feed a :class:`~host_tools.reports.tracking_stream.TrackingStream` (the tracking figures).
The trace is not streamed: it is a ring buffer of the last jobs (``RunConfig.trace_capacity``), written at
the end.
"""

from __future__ import annotations

from dataclasses import asdict, fields
from pathlib import Path

import numpy as np

from firmware.app import Firmware
from hal.virtual.bench import VirtualBench
from host_tools.outdir import naming
from host_tools.probe import Probe
from host_tools.reports.telemetry_csv import TelemetryCsv
from host_tools.reports.tracking_stream import TrackingResult, TrackingStream, feed_probe
from protocol.telemetry import TelemetryDecoder

__all__ = ["RunFiles", "take_samples"]


def take_samples(probe: Probe) -> dict[str, np.ndarray]:
    """The probe's samples as arrays by field name; the probe starts empty again."""
    out = {}
    for f in fields(probe):
        out[f.name] = np.asarray(getattr(probe, f.name), dtype=float)
        setattr(probe, f.name, [])
    return out


class RunFiles:
    """telemetry.bin and telemetry.csv in ``directory``, and the tracking figures, fed segment by segment."""

    def __init__(self, directory: Path, tracking: TrackingStream, f_cpu_hz: int,
                 extra_names: tuple[str, ...] = ()) -> None:
        """Create (truncate) the two telemetry files in directory (times in cycles of f_cpu_hz; extra_names: the
        controller's published values, last columns of the CSV)."""
        self.directory = directory
        self.tracking = tracking
        self.decoder = TelemetryDecoder(len(extra_names))
        self.telemetry_bytes = 0
        self._bin = (directory / "telemetry.bin").open("wb")
        self._csv_file = (directory / "telemetry.csv").open("w", encoding="utf-8", newline="")
        self._csv = TelemetryCsv(self._csv_file, f_cpu_hz, extra_names)
        self._result: TrackingResult | None = None

    def drain(self, bench: VirtualBench, probe: Probe, fw: Firmware) -> None:
        """Move what the last segment produced out of the bench and the probe into the files and figures."""
        data = bench.telemetry.take()
        if data:
            with naming(self.directory / "telemetry.bin"):
                self._bin.write(data)
            self.telemetry_bytes += len(data)
            with naming(self.directory / "telemetry.csv"):
                self._csv.write(self.decoder.feed_values(data))
        self.tracking.set_start(fw.gait_start_s)
        feed_probe(self.tracking, take_samples(probe))

    def close(self) -> TrackingResult:
        """Close the files; return the tracking figures (once; later calls return the same)."""
        if self._result is None:
            with naming(self.directory / "telemetry.bin"):
                self._bin.close()
            with naming(self.directory / "telemetry.csv"):
                self._csv_file.close()
            self._result = self.tracking.finish()
        return self._result

    def decoder_stats(self) -> dict:
        """The telemetry decoder's counters (for summary.json)."""
        return asdict(self.decoder.stats)
