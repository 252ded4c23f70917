"""The results of a sweep on disk: a row journal appended as points finish, and results.parquet / results.csv.

Every finished point is appended at once to `rows.jsonl` (one JSON object a line, written whole or not at all: a
write that fails, a full disk, cuts the journal back to its last whole row): a sweep that is killed keeps every
finished row, and `--resume` reads them back. `results.parquet` and `results.csv`
are rewritten from the journal (rows sorted by point) at most every `FLUSH_S` seconds while the sweep
runs and at its end, each through a temporary file and a rename, so a reader never sees half a file.
`sweep.json` records the spec's digest: `--resume` refuses a directory written by another spec.
"""

from __future__ import annotations

import json
import math
import os
import time
from pathlib import Path
from typing import Any

from host_tools.outdir import naming

__all__ = ["JOURNAL", "ResultsTable", "TIMING_COLUMNS", "check_out", "kept_rows", "read_rows", "status_counts"]

JOURNAL = "rows.jsonl"
FLUSH_S = 1.0
#: Columns measured on the host (they differ from run to run); every other column depends on the spec only.
TIMING_COLUMNS = ("wall_time_s", "realtime_factor")


def _jsonable(v: Any) -> Any:
    return None if isinstance(v, float) and not math.isfinite(v) else v


def kept_rows(out: Path) -> str:
    """What a study that failed or stopped keeps: the end of its one-line error."""
    return f"every row finished before it is in {out / JOURNAL} (--resume runs the rest)"


def read_rows(out: Path) -> list[dict[str, Any]]:
    """The rows of the journal in `out`, sorted by point (a torn last line from a kill is ignored)."""
    path = out / JOURNAL
    if not path.exists():
        return []
    rows: dict[int, dict[str, Any]] = {}
    for line in path.read_text(encoding="utf-8").splitlines():
        try:
            row = json.loads(line)
        except json.JSONDecodeError:
            continue
        rows[int(row["point"])] = {k: math.nan if v is None and k not in ("sample", "plant_seed") else v
                                   for k, v in row.items()}
    return [rows[k] for k in sorted(rows)]


def status_counts(rows: list[dict[str, Any]]) -> str:
    """The rows' statuses counted, in name order: "fault 2, ok 14" (the reports' first line)."""
    status: dict[str, int] = {}
    for r in rows:
        status[r["status"]] = status.get(r["status"], 0) + 1
    return ", ".join(f"{k} {v}" for k, v in sorted(status.items()))


def _atomic(path: Path, write: Any) -> None:
    """write(tmp) then rename tmp to path; a write that fails leaves no tmp behind and names path."""
    tmp = path.with_name(f".{path.name}.tmp")
    try:
        with naming(path):
            write(tmp)
            os.replace(tmp, path)
    except BaseException:
        tmp.unlink(missing_ok=True)
        raise


def check_out(out: Path, digest: str, resume: bool) -> dict[int, dict[str, Any]]:
    """The finished rows in `out` by point; ValueError if `out` is no directory, holds another sweep, or holds
    rows and `resume` is False."""
    if out.exists() and not out.is_dir():
        raise ValueError(f"--out {out} is a file: a directory is needed")
    meta = out / "sweep.json"
    if meta.exists():
        old = json.loads(meta.read_text(encoding="utf-8"))
        if old.get("digest") != digest:
            raise ValueError(f"--out {out} holds the results of another spec or profile (sweep.json digest "
                             f"{str(old.get('digest'))[:12]}, this spec {digest[:12]}): choose another --out")
    rows = {int(r["point"]): r for r in read_rows(out)}
    if rows and not resume:
        raise ValueError(f"--out {out} already holds {len(rows)} finished points: pass --resume to finish "
                         "the missing ones, or choose another --out")
    return rows


class ResultsTable:
    """Appends rows as points finish and keeps results.parquet / results.csv in step."""

    def __init__(self, out: Path, columns: list[str], digest: str, n_points: int, resume: bool) -> None:
        """Open `out` for a sweep with `digest`; ValueError if it holds another sweep, or any rows without resume."""
        self.out, self.columns = out, columns
        self.rows = check_out(out, digest, resume)
        meta = out / "sweep.json"
        out.mkdir(parents=True, exist_ok=True)
        _atomic(meta, lambda p: p.write_text(json.dumps({"digest": digest, "points": n_points, "columns": columns},
                                                        indent=2) + "\n", encoding="utf-8"))
        with naming(out / JOURNAL):
            self._journal = os.open(out / JOURNAL, os.O_RDWR | os.O_APPEND | os.O_CREAT, 0o666)
            _cut_torn_line(self._journal)
        self._last_flush = 0.0

    def add(self, row: dict[str, Any]) -> None:
        """Record a finished point: journal now (the whole line or, if the write fails, nothing: the journal is cut
        back to its last whole row before the OSError goes on), tables at most every FLUSH_S."""
        line = (json.dumps({k: _jsonable(v) for k, v in row.items()}, allow_nan=False) + "\n").encode()
        with naming(self.out / JOURNAL):
            size = os.fstat(self._journal).st_size
            try:
                view = memoryview(line)
                while view:
                    view = view[os.write(self._journal, view):]
            except BaseException:
                os.ftruncate(self._journal, size)
                raise
        self.rows[int(row["point"])] = row
        if time.monotonic() - self._last_flush >= FLUSH_S:
            self.flush()

    def sorted_rows(self) -> list[dict[str, Any]]:
        """The rows so far, sorted by point."""
        return [self.rows[k] for k in sorted(self.rows)]

    def flush(self) -> None:
        """Rewrite results.parquet and results.csv from the rows so far."""
        import pyarrow as pa
        import pyarrow.csv as pacsv
        import pyarrow.parquet as pq

        rows = self.sorted_rows()
        table = pa.table({c: pa.array([r.get(c) for r in rows], from_pandas=True) for c in self.columns})
        _atomic(self.out / "results.parquet", lambda p: pq.write_table(table, p))
        _atomic(self.out / "results.csv", lambda p: pacsv.write_csv(table, p))
        self._last_flush = time.monotonic()

    def close(self) -> None:
        """Write the tables a last time and close the journal (closed even when the tables cannot be written)."""
        try:
            self.flush()
        finally:
            os.close(self._journal)


def _cut_torn_line(fd: int) -> None:
    """Cut a journal opened for appending back to its last whole line (a kill can leave half a row, which the
    next row would otherwise be glued to)."""
    size = os.fstat(fd).st_size
    tail = os.pread(fd, min(size, 1 << 16), max(0, size - (1 << 16)))
    if tail and not tail.endswith(b"\n"):
        keep = tail.rfind(b"\n") + 1  # 0: no whole line in the tail
        if keep or len(tail) == size:
            os.ftruncate(fd, size - len(tail) + keep)
