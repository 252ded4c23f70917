"""The commands' shared one-line errors: an input refused before the work, a study whose cluster run failed."""

from __future__ import annotations

import errno
from pathlib import Path

from host_tools.command_errors import input_error, study_error
from host_tools.outdir import EXIT_WRITE_FAILED, OutDirError


def test_input_error_names_the_file_or_says_the_value():
    e = FileNotFoundError(errno.ENOENT, "No such file or directory", "runs/a/record.bin")
    assert input_error("replay", e) == "pafp replay: cannot read runs/a/record.bin: No such file or directory"
    assert input_error("fit", OutDirError("--out x: not empty")) == "pafp fit: --out x: not empty"


def test_study_error_tells_a_write_from_the_cluster():
    line, status = study_error("design", None, ValueError("--out d holds another study"), "kept")
    assert (line, status) == ("pafp design: --out d holds another study", 2)
    write = OSError(errno.ENOSPC, "No space left on device", "runs/d/rows.jsonl")
    line, status = study_error("faults", None, write, "every row finished before it is in runs/d/rows.jsonl")
    assert status == EXIT_WRITE_FAILED
    assert "cannot write runs/d/rows.jsonl: No space left on device" in line and "every row finished" in line
    line, status = study_error("sweep", "tcp://10.0.0.1:8786", ConnectionRefusedError(111, "refused"), "kept")
    assert status == 2 and line.startswith("pafp sweep: cannot reach the Dask scheduler tcp://10.0.0.1:8786: ")
    line, status = study_error("sweep", None, OSError(errno.EMFILE, "Too many open files"), "kept")
    assert status == 2 and line.startswith("pafp sweep: cannot start the cluster: ")


def test_fit_and_replay_print_the_same_shape_for_a_missing_record(tmp_path: Path, capsys):
    from host_tools.cli import main

    missing = tmp_path / "nothing"
    missing.mkdir()
    for command in ("fit", "replay"):
        assert main([command, str(missing)]) == 2
        err = capsys.readouterr().err.strip().splitlines()
        assert len(err) == 1 and err[0].startswith(f"pafp {command}: ") and f"{missing}" in err[0], err
        assert "not found" in err[0], err
