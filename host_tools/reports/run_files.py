"""The files a virtual run writes as it goes, so that its memory does not grow with its length.

:func:`host_tools.runner.run_virtual` runs the scheduler in segments of simulated time and, after each,
hands what the segment produced to a :class:`RunFiles`: the telemetry UART's bytes are appended to
``telemetry.bin`` and decoded into ``telemetry.csv`` (its decoder's counters go to the summary), and the
bench probe's samples feed a :class:`~host_tools.reports.tracking_stream.TrackingStream` (the tracking figures).
The trace is not streamed: it is a ring buffer of the last jobs (``RunConfig.trace_capacity``), written at
the end.

A run's summary.json holds the SHA-256 of its ``record.bin`` and ``telemetry.csv`` (:func:`file_digests`); a
tool that reads both back (`pafp fit`) checks that they are still the same run's (:func:`check_same_run`).
"""

from __future__ import annotations

import hashlib
import json
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

__all__ = ["DIGESTED", "RunFiles", "check_same_run", "file_digests", "take_samples"]

DIGESTED = ("record.bin", "telemetry.csv")
"""The files of a run whose SHA-256 its summary.json holds (``files_sha256``)."""


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


def _sha256(path: Path) -> str:
    h = hashlib.sha256()
    with path.open("rb") as f:
        while chunk := f.read(1 << 20):
            h.update(chunk)
    return h.hexdigest()


def file_digests(directory: Path) -> dict[str, str]:
    """{name: SHA-256} of the files of DIGESTED present in directory (summary.json's ``files_sha256``)."""
    return {name: _sha256(directory / name) for name in DIGESTED if (directory / name).is_file()}


def check_same_run(directory: Path) -> None:
    """ValueError (one line naming the file) when a file of DIGESTED in directory is not the one its summary.json
    names: files of two runs put together. A directory without a summary or without digests is not checked."""
    summary = directory / "summary.json"
    try:
        digests = json.loads(summary.read_text(encoding="utf-8")).get("files_sha256") if summary.is_file() else None
    except (ValueError, AttributeError, OSError):
        raise ValueError(f"{summary}: not a run summary (not a JSON object)") from None
    if not isinstance(digests, dict):
        return
    for name, digest in digests.items():
        path = directory / str(name)
        if path.is_file() and _sha256(path) != digest:
            raise ValueError(f"{path} is not the file the run of {summary} wrote (its SHA-256 differs from "
                             f"files_sha256 {str(digest)[:12]}...): the directory mixes the files of two runs, or the "
                             "file was changed since; use a run directory as pafp wrote it")
