"""Output directories of a run: checked before anything runs, filled in a staging directory, swapped in whole.

A run writes into a hidden staging directory beside ``--out`` (``.<name>.<random>.partial``) and only
:meth:`RunDir.publish` puts it in place, so ``--out`` never holds the files of two runs: it is either the
previous run's directory, untouched, or the new one. An existing ``--out`` must be empty or a previous
run's (it holds a ``summary.json``); anything else is refused before the run, not overwritten. Single files
are written to a temporary name in their directory and renamed (:func:`write_atomic`).

>>> import tempfile
>>> root = Path(tempfile.mkdtemp())
>>> run = RunDir(root / "run1")
>>> write_atomic(run.path / "summary.json", b"{}")
>>> run.publish(); sorted(p.name for p in (root / "run1").iterdir())
['summary.json']
>>> RunDir(root / "run1").publish()  # a previous run's directory is replaced as a whole
>>> list((root / "run1").iterdir())
[]
"""

from __future__ import annotations

import os
import shutil
import tempfile
from pathlib import Path

__all__ = ["MARKER", "OutDirError", "RunDir", "check_out_dir", "write_atomic"]

MARKER = "summary.json"
"""The file every run writes (interrupted ones too): a directory holding it is a previous run's."""


class OutDirError(ValueError):
    """An output directory that cannot take a run; the message names it and says what is allowed."""


def check_out_dir(out: Path) -> None:
    """Refuse an ``out`` that is a file, holds files not from a run, or whose parent is not writable."""
    if out.exists() and not out.is_dir():
        raise OutDirError(f"--out {out} is an existing file: name a new directory, an empty one or a previous run's")
    if out.is_dir():
        entries = sorted(p.name for p in out.iterdir())
        if entries and MARKER not in entries:
            raise OutDirError(f"--out {out} holds files that are not a pafp run's (e.g. {entries[0]!r}): name a new "
                              "directory, an empty one or a previous run's (it has a summary.json)")
    parent = _parent(out)
    if not parent.is_dir():
        raise OutDirError(f"--out {out}: {parent} is not a directory")
    if not os.access(parent, os.W_OK | os.X_OK) or (out.is_dir() and not os.access(out, os.W_OK | os.X_OK)):
        raise OutDirError(f"--out {out} is not writable (no write permission on {parent if not out.is_dir() else out})")


def _umask() -> int:
    mask = os.umask(0)
    os.umask(mask)
    return mask


def _parent(out: Path) -> Path:
    """The nearest existing ancestor of out (created directories go below it)."""
    parent = out.absolute().parent
    while not parent.exists() and parent != parent.parent:
        parent = parent.parent
    return parent


class RunDir:
    """A staging directory for the run that will become ``out``; :meth:`publish` swaps it in."""

    def __init__(self, out: Path) -> None:
        """Check out (:func:`check_out_dir`) and create the staging directory beside it (OutDirError if not)."""
        check_out_dir(out)
        self.out = out.absolute()
        try:
            self.out.parent.mkdir(parents=True, exist_ok=True)
            self.path = Path(tempfile.mkdtemp(prefix=f".{self.out.name}.", suffix=".partial", dir=self.out.parent))
            self.path.chmod(0o777 & ~_umask())  # as mkdir would make it (mkdtemp's is private)
        except OSError as e:
            raise OutDirError(f"--out {out} is not writable: {e.strerror or e}") from None

    def publish(self) -> None:
        """Put the staged files at ``out``: a previous run's directory there is replaced as a whole."""
        if self.out.is_dir() and not any(self.out.iterdir()):
            self.out.rmdir()
        old = None
        if self.out.exists():
            check_out_dir(self.out)  # still a previous run's: replace it, never mix with it
            old = Path(tempfile.mkdtemp(prefix=f".{self.out.name}.", suffix=".old", dir=self.out.parent))
            os.replace(self.out, old / "run")
        os.rename(self.path, self.out)
        if old is not None:
            shutil.rmtree(old, ignore_errors=True)

    def discard(self) -> None:
        """Remove the staging directory and what it holds (a run that will not be published)."""
        shutil.rmtree(self.path, ignore_errors=True)


def write_atomic(path: Path, data: bytes | str) -> None:
    """Write data (str as UTF-8) to a temporary name in path's directory, then rename it to path."""
    payload = data.encode("utf-8") if isinstance(data, str) else data
    fd, tmp = tempfile.mkstemp(prefix=f".{path.name}.", suffix=".tmp", dir=path.parent)
    try:
        with os.fdopen(fd, "wb") as f:
            f.write(payload)
        os.chmod(tmp, 0o666 & ~_umask())  # as open() would make it (mkstemp's is private)
        os.replace(tmp, path)
    except BaseException:
        Path(tmp).unlink(missing_ok=True)
        raise
