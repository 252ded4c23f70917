"""Output directories of a run: checked before anything runs, filled in a staging directory, swapped in whole.

A run writes into a hidden staging directory beside ``--out`` (``.<name>.<random>.partial``) and only
:meth:`RunDir.publish` puts it in place, so ``--out`` never holds the files of two runs: it is either the
previous run's directory, untouched, or the new one. An existing ``--out`` must be empty or provably a previous
output of pafp: it holds the ``MANIFEST`` publishing wrote, and nothing that manifest does not list (a
``summary.json`` alone proves nothing); anything else is refused before the run, not replaced. An output that
is one of the command's inputs, or holds one (host_tools/contract.py registers them with
:func:`protect_inputs`), is refused too (:func:`check_holds_no_input`, called by :func:`check_writable`). Single files
are written to a temporary name in their directory and renamed (:func:`write_atomic`, :func:`save_figure`).

Every command checks its output paths before its work (:func:`check_writable`: not a file, creatable,
writable, at least ``MIN_FREE_BYTES`` free; exit 2). A write that fails later (a disk that fills, a
device that goes away) is one line naming the file and the error, exit ``EXIT_WRITE_FAILED`` (74, EX_IOERR
of sysexits.h); the partial file is removed and the files already complete stay as they are. A staging
directory is named after the process that made it (``.<name>.<pid>@<host>.<random>.partial``): one left by a
killed run is removed by the next run to the same ``--out`` once that process is gone (:func:`clean_stale`).
A path inside ``--out`` (a ``--capture`` there) is written inside the staging directory (:meth:`RunDir.staged`).
Should files that are not a run's appear in ``--out`` during the run, publishing refuses to replace them and
keeps the run's outputs in ``<name>.unpublished.<random>`` beside it (exit 74).

>>> import tempfile
>>> root = Path(tempfile.mkdtemp())
>>> run = RunDir(root / "run1")
>>> write_atomic(run.path / "summary.json", b"{}")
>>> run.publish(); sorted(p.name for p in (root / "run1").iterdir())
['.pafp-outputs.json', 'summary.json']
>>> RunDir(root / "run1").publish()  # a previous run's directory is replaced as a whole
>>> [p.name for p in (root / "run1").iterdir()]
['.pafp-outputs.json']
"""

from __future__ import annotations

import io
import json
import os
import re
import shutil
import socket
import tempfile
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import Any

__all__ = ["EXIT_WRITE_FAILED", "MANIFEST", "MIN_FREE_BYTES", "OutDirError", "RunDir", "check_capture_dir",
           "check_holds_no_input", "check_out_dir", "check_writable", "clean_stale", "mark_outputs", "naming",
           "protect_inputs", "save_figure", "write_atomic", "write_failed"]

MANIFEST = ".pafp-outputs.json"
"""What pafp writes into every output directory it publishes: the names of the files it put there. A directory
holding it and nothing it does not list is a previous output of pafp, which a new run may replace."""
EXIT_WRITE_FAILED = 74
"""Exit code of a command whose output could not be written once its work had begun (EX_IOERR, sysexits.h)."""
MIN_FREE_BYTES = 1 << 20
"""An output directory on a filesystem with less free space than this is refused before the work."""


class OutDirError(ValueError):
    """An output directory that cannot take a run; the message names it and says what is allowed."""


_INPUTS: list[Path] = []


def protect_inputs(paths: list[Path]) -> list[Path]:
    """Register the (resolved) inputs of the command being run: no output may be or hold one. Returns them."""
    _INPUTS[:] = paths
    return list(paths)


def check_holds_no_input(out: Path, option: str = "--out", inputs: list[Path] | None = None) -> None:
    """Refuse an output ``out`` (given as ``option``) that is an input, holds one, or lies inside an input file
    (OutDirError naming both); ``inputs`` defaults to those registered by :func:`protect_inputs`. An output inside
    an input directory is allowed (`pafp fit RUN`'s default RUN/fit): replacing it touches no input."""
    target = Path(os.path.abspath(out)).resolve()
    for source in _INPUTS if inputs is None else inputs:
        if target == source or source.is_relative_to(target):
            what = "is" if target == source else "holds"
            raise OutDirError(f"{option} {out} {what} the input {source}: writing it would destroy the input; "
                              f"name another {'file' if option == '--csv' else 'directory'}")
        if target.is_relative_to(source) and not source.is_dir():
            raise OutDirError(f"{option} {out} lies inside the input file {source}: name a directory")


def check_writable(path: Path, option: str = "--out") -> None:
    """Refuse a directory ``path`` (given as ``option``) that is an input or holds one (:func:`check_holds_no_input`),
    is a file, cannot be created or written, or whose filesystem has less than MIN_FREE_BYTES free (OutDirError
    naming it)."""
    check_holds_no_input(path, option)
    if path.exists() and not path.is_dir():
        raise OutDirError(f"{option} {path} is a file: a directory is needed")
    parent = _parent(path)
    if not parent.is_dir():
        raise OutDirError(f"{option} {path}: {parent} is not a directory")
    target = path if path.is_dir() else parent
    if not os.access(target, os.W_OK | os.X_OK):
        raise OutDirError(f"{option} {path} is not writable (no write permission on {target})")
    st = os.statvfs(target)
    if st.f_flag & os.ST_RDONLY:
        raise OutDirError(f"{option} {path} is not writable ({target} is on a read-only filesystem)")
    free = st.f_bavail * st.f_frsize
    if free < MIN_FREE_BYTES:
        raise OutDirError(f"{option} {path}: only {free} bytes free on the filesystem of {target}, at least "
                          f"{MIN_FREE_BYTES} (1 MiB) are needed")


def check_out_dir(out: Path) -> None:
    """Refuse an ``out`` that is or holds an input, is a file, holds files not from a run, or is not writable
    (:func:`check_writable`)."""
    check_holds_no_input(out)
    _check_previous_run(out)
    check_writable(out)


def _check_previous_run(out: Path) -> None:
    """Refuse an ``out`` that is a file or is not provably a previous output of pafp (:data:`MANIFEST`)."""
    if out.exists() and not out.is_dir():
        raise OutDirError(f"--out {out} is an existing file: name a new directory, an empty one or a previous run's")
    if out.is_dir():
        entries = sorted(p.name for p in out.iterdir())
        if not entries:
            return
        ours = _manifest(out)
        foreign = [e for e in entries if e != MANIFEST and (ours is None or e not in ours)]
        if foreign:
            why = f"no {MANIFEST} lists its files" if ours is None else f"not in its {MANIFEST}"
            raise OutDirError(f"--out {out} holds files that are not a pafp run's (e.g. {foreign[0]!r}; {why}): name a "
                              "new directory, an empty one or one pafp published")


def _manifest(out: Path) -> set[str] | None:
    """The names the manifest in ``out`` lists, None when there is no readable one."""
    try:
        doc = json.loads((out / MANIFEST).read_text(encoding="utf-8"))
        files = doc["files"]
        if not isinstance(files, list) or not all(isinstance(f, str) for f in files):
            return None
        return set(files)
    except (OSError, ValueError, KeyError, TypeError):
        return None


def mark_outputs(directory: Path) -> None:
    """Write :data:`MANIFEST` into ``directory``: every name it holds is an output of pafp's."""
    names = sorted(p.name for p in directory.iterdir() if p.name != MANIFEST)
    write_atomic(directory / MANIFEST, json.dumps({"written_by": "pafp", "files": names}, indent=1) + "\n")


def check_capture_dir(path: Path) -> None:
    """Refuse a ``--capture`` directory that is a file, is not writable or already holds a capture (index.csv)."""
    check_writable(path, "--capture")
    if (path / "index.csv").exists():
        raise OutDirError(f"--capture {path} already holds a capture (index.csv): give a new or empty directory")


def write_failed(command: str, e: OSError, kept: str) -> str:
    """The one line of a write that failed during the work: the file, the error, and what ``kept`` holds."""
    what = f"{e.filename}" if e.filename else "an output file"
    return f"pafp {command}: cannot write {what}: {e.strerror or e}; {kept} (exit {EXIT_WRITE_FAILED})"


@contextmanager
def naming(path: Path) -> Iterator[None]:
    """Give an OSError raised inside (a write to an open file has none) the name of ``path``."""
    try:
        yield
    except OSError as e:
        if e.filename is None:
            raise OSError(e.errno, e.strerror or str(e), str(path)) from e
        raise


_STAGED = re.compile(r"\.(?P<pid>\d+)@(?P<host>[^.]*)\..*\.(partial|old)$")


def _tag() -> str:
    """``<pid>@<host>``: who made a staging directory (the host's name without dots)."""
    return f"{os.getpid()}@{socket.gethostname().replace('.', '-')}"


def _alive(pid: int) -> bool:
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:
        return True
    return True


def clean_stale(out: Path) -> list[Path]:
    """Remove the staging directories beside ``out`` left by runs of this host whose process is gone; return them."""
    out = out.absolute()
    if not out.parent.is_dir():
        return []
    host = socket.gethostname().replace(".", "-")
    removed = []
    prefix = f".{out.name}"
    for p in out.parent.iterdir():
        m = _STAGED.match(p.name[len(prefix):]) if p.name.startswith(prefix + ".") else None
        if m and p.is_dir() and m["host"] == host and not _alive(int(m["pid"])):
            shutil.rmtree(p, ignore_errors=True)
            removed.append(p)
    return removed


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
        self.kept = False  # publish found out taken by other files: the staging directory stays
        clean_stale(self.out)
        try:
            self.out.parent.mkdir(parents=True, exist_ok=True)
            self.path = Path(tempfile.mkdtemp(prefix=f".{self.out.name}.{_tag()}.", suffix=".partial",
                                              dir=self.out.parent))
            self.path.chmod(0o777 & ~_umask())  # as mkdir would make it (mkdtemp's is private)
        except OSError as e:
            raise OutDirError(f"--out {out} is not writable: {e.strerror or e}") from None

    def staged(self, path: Path) -> Path:
        """Where ``path`` is written during the run: inside the staging directory if it lies inside ``out`` (it is
        published with the run; out itself is replaced), else ``path`` itself."""
        try:
            return self.path / path.absolute().relative_to(self.out)
        except ValueError:
            return path

    def publish(self) -> None:
        """Put the staged files at ``out``: a previous run's directory there is replaced as a whole. If something
        else wrote files that are not a run's into ``out`` meanwhile, nothing is replaced and the staging
        directory is kept (OutDirError naming it)."""
        mark_outputs(self.path)
        if self.out.is_dir() and not any(self.out.iterdir()):
            self.out.rmdir()
        old = None
        if self.out.exists():
            try:
                _check_previous_run(self.out)  # still a previous run's: replace it, never mix with it
            except OutDirError as e:  # renamed out of clean_stale's way: kept until the user moves it
                kept = Path(tempfile.mkdtemp(prefix=f"{self.out.name}.unpublished.", dir=self.out.parent))
                os.replace(self.path, kept)
                self.path, self.kept = kept, True
                raise OutDirError(f"{e}; this run's outputs are kept in {kept}") from None
            old = Path(tempfile.mkdtemp(prefix=f".{self.out.name}.{_tag()}.", suffix=".old", dir=self.out.parent))
            os.replace(self.out, old / "run")
        os.rename(self.path, self.out)
        if old is not None:
            shutil.rmtree(old, ignore_errors=True)

    @contextmanager
    def filling(self) -> Iterator[Path]:
        """Yield the staging directory to write into and publish it when the block ends; on any exception
        (BaseException too: a stop signal, a failed write) the staging directory is removed and the exception
        goes on, so ``out`` keeps what it held."""
        try:
            yield self.path
            self.publish()
        finally:
            self.discard()

    def discard(self) -> None:
        """Remove the staging directory and what it holds (a run that will not be published), unless
        :meth:`publish` kept it."""
        if not self.kept:
            shutil.rmtree(self.path, ignore_errors=True)


def write_atomic(path: Path, data: bytes | str) -> None:
    """Write data (str as UTF-8) to a temporary name in path's directory, then rename it to path."""
    payload = data.encode("utf-8") if isinstance(data, str) else data
    with naming(path):
        fd, tmp = tempfile.mkstemp(prefix=f".{path.name}.", suffix=".tmp", dir=path.parent)
        try:
            with os.fdopen(fd, "wb") as f:
                f.write(payload)
            os.chmod(tmp, 0o666 & ~_umask())  # as open() would make it (mkstemp's is private)
            os.replace(tmp, path)
        except BaseException:
            Path(tmp).unlink(missing_ok=True)
            raise


def save_figure(fig: Any, path: Path, **savefig: Any) -> None:
    """Draw a matplotlib figure into memory, then write it to ``path`` atomically (never a 0-byte image)."""
    buf = io.BytesIO()
    fig.savefig(buf, format=path.suffix.lstrip(".") or "png", **savefig)
    write_atomic(path, buf.getvalue())
