"""The one-line errors the `pafp` commands print before exiting: an input that cannot be used, an output that
could not be written or published, a study whose cluster run failed. Each names the value and where it came
from; the command prints it and exits with the status given.

>>> input_error("fit", FileNotFoundError(2, "No such file or directory", "runs/x/record.bin"))
'pafp fit: cannot read runs/x/record.bin: No such file or directory'
>>> input_error("replay", ValueError("record r.bin: not found"))
'pafp replay: record r.bin: not found'
>>> study_error("faults", None, OSError(111, "Connection refused"), "kept")
('pafp faults: cannot start the cluster: [Errno 111] Connection refused', 2)
"""

from __future__ import annotations

from host_tools.outdir import EXIT_WRITE_FAILED, OutDirError, RunDir, write_failed

__all__ = ["input_error", "output_error", "study_error"]


def input_error(command: str, e: OSError | ValueError) -> str:
    """The line for an input checked before the work: a file that cannot be read (OSError) or a bad value
    (ValueError, whose message names it)."""
    if isinstance(e, OSError):
        return f"pafp {command}: cannot read {e.filename}: {e.strerror}"
    return f"pafp {command}: {e}"


def output_error(command: str, e: OSError | OutDirError, run_dir: RunDir, what: str = "nothing published") -> str:
    """The line (exit EXIT_WRITE_FAILED) for a write into run_dir's staging directory that failed during the work
    (an OSError naming the file; ``what`` says what happened to the work) or an --out that files not from a run took
    meanwhile (the OutDirError from :meth:`RunDir.publish`, which names where the outputs are kept)."""
    if isinstance(e, OutDirError):
        return f"pafp {command}: {e} (exit {EXIT_WRITE_FAILED})"
    if e.filename:
        e.filename = str(e.filename).replace(str(run_dir.path), f"{run_dir.out} (staged)")
    return write_failed(command, e, f"{what}: {run_dir.out} keeps what it held")


def study_error(command: str, scheduler: str | None, e: OSError | ValueError, kept: str) -> tuple[str, int]:
    """(line, exit status) for a study whose run on the cluster raised `e`: a spec or --out refused
    (ValueError, 2), a result file that could not be written (an OSError naming it, 74: `kept` says what is
    kept), a scheduler that could not be reached or a cluster that could not start (another OSError, 2)."""
    if isinstance(e, ValueError):
        return f"pafp {command}: {e}", 2
    if e.filename is not None:
        return write_failed(command, e, kept), EXIT_WRITE_FAILED
    what = f"cannot reach the Dask scheduler {scheduler}" if scheduler else "cannot start the cluster"
    return f"pafp {command}: {what}: {e}", 2
