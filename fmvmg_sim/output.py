"""Output folders written as one unit: a command's ``-o DIR`` holds one run's complete output or nothing new.

Every command that writes a folder does so through :class:`OutputFolder` (also named ``output_folder``)::

    with output_folder(out) as tmp:      # checked before any work: refused with exit 2 if unusable
        write_record(tmp / "record.csv", ...)
        plot(..., tmp / "startup.png")
    # here `out` holds exactly this run's files

or, where a context manager does not fit the code, ``staged = OutputFolder(out)``, writes into
``staged.path``, then ``staged.commit()``.

The files are written into a temporary folder beside ``DIR`` (``.DIR.tmp-*``, same file system) that
is renamed into place once the block ends without an exception, plots included. A second run into
the same ``DIR`` replaces the first whole; an error or Ctrl-C inside the block leaves the old folder
(or nothing) and removes the temporary one. The swap is two renames with Ctrl-C held off between
them. A folder is replaced only when it is empty or was written by fmvmg and holds nothing else (its
marker file :data:`MARKER` lists every file), so ``-o .``, ``-o ~`` or a run's folder with a
compensation written into it later never loses a user's files.

Files and folders get the usual permissions under the process umask (0644 and 0755 under 022).
"""

from __future__ import annotations

import contextlib
import json
import os
import shutil
import signal
import tempfile
import threading
import weakref
from collections.abc import Iterator
from pathlib import Path

from .errors import InputError

#: Marker file written into every output folder: which command wrote it and the files it holds.
MARKER = ".fmvmg-output.json"


def umask() -> int:
    """The process umask (read without changing it where the system allows).

    Returns
    -------
    int
    """
    try:
        with open("/proc/self/status", encoding="ascii") as fh:
            for line in fh:
                if line.startswith("Umask:"):
                    return int(line.split()[1], 8)
    except (OSError, ValueError):
        pass
    mask = os.umask(0o022)
    os.umask(mask)
    return mask


def file_mode() -> int:
    """Permission bits of a new regular file under the umask (0o644 under 0o022).

    Returns
    -------
    int
    """
    return 0o666 & ~umask()


def dir_mode() -> int:
    """Permission bits of a new folder under the umask (0o755 under 0o022).

    Returns
    -------
    int
    """
    return 0o777 & ~umask()


def format_bytes(n: float) -> str:
    """A byte count in binary units, e.g. ``14.5 TiB``.

    Parameters
    ----------
    n : float

    Returns
    -------
    str
    """
    for unit in ("B", "KiB", "MiB", "GiB", "TiB", "PiB"):
        if abs(n) < 1024 or unit == "PiB":
            return f"{n:.3g} {unit}" if unit != "B" else f"{int(n)} B"
        n /= 1024
    return f"{n:.3g} PiB"  # pragma: no cover


def _foreign_files(target: Path) -> list[str] | None:
    """Files in an existing folder that an fmvmg run did not write there (None: not an fmvmg folder).

    An empty folder has none. A folder with the marker file has those not listed in it (added after the
    run, e.g. a compensation written beside a record), which replacing the folder would delete.
    """
    if not any(target.iterdir()):
        return []
    try:
        listed = set(json.loads((target / MARKER).read_text(encoding="utf-8"))["files"])
    except (OSError, ValueError, KeyError, TypeError):
        return None
    present = {str(p.relative_to(target)) for p in target.rglob("*") if p.is_file() and p.name != MARKER}
    return sorted(present - listed)


def _refusal(target: Path) -> str | None:
    foreign = _foreign_files(target)
    if foreign is None:
        return (f"is a folder holding other files (no {MARKER}: not an fmvmg output folder); "
                "give a new or empty folder")
    if foreign:
        more = f" and {len(foreign) - 3} more" if len(foreign) > 3 else ""
        return (f"holds files the earlier run did not write ({', '.join(foreign[:3])}{more}), which replacing "
                "it would delete; move them or give another folder")
    return None


def check_output_folder(path: str | os.PathLike, expect_bytes: int | None = None) -> Path:
    """Refuse an output folder that cannot be written, before any work is done.

    Parameters
    ----------
    path : path-like
        The ``-o`` folder.
    expect_bytes : int, optional
        Size of the output; refused when the file system has less free space.

    Returns
    -------
    Path
        The folder, absolute.

    Raises
    ------
    InputError
        ``path`` is a file, an existing folder holding files fmvmg did not write, a folder whose
        parent cannot be created or written, or on a file system without room for the output.
    """
    target = Path(path).absolute()
    if target.exists() and not target.is_dir():
        raise InputError("exists and is not a folder; expected an output folder", str(path))
    refusal = _refusal(target) if target.is_dir() else None
    if refusal:
        raise InputError(refusal, str(path))
    parent = target.parent
    existing = parent
    while not existing.exists():
        existing = existing.parent
    if not existing.is_dir():
        raise InputError(f"cannot create the output folder: {existing} is not a folder", str(path))
    if not os.access(existing, os.W_OK | os.X_OK):
        raise InputError(f"cannot write the output folder: no write permission in {existing}", str(path))
    if expect_bytes is not None:
        free = shutil.disk_usage(existing).free
        if expect_bytes > free:
            raise InputError(f"the output needs about {format_bytes(expect_bytes)} but only {format_bytes(free)} "
                             f"is free on that file system", str(path))
    return target


@contextlib.contextmanager
def _no_interrupt() -> Iterator[None]:
    """Hold SIGINT off (main thread only) so that a Ctrl-C lands before or after, not inside."""
    if threading.current_thread() is not threading.main_thread() or not hasattr(signal, "pthread_sigmask"):
        yield
        return
    old = signal.pthread_sigmask(signal.SIG_BLOCK, {signal.SIGINT})
    try:
        yield
    finally:
        signal.pthread_sigmask(signal.SIG_SETMASK, old)


def _finish(folder: Path, command: str | None) -> None:
    """Give every file and sub-folder the umask's permissions and write the marker file."""
    fmode, dmode = file_mode(), dir_mode()
    files = []
    for p in sorted(folder.rglob("*")):
        if p.is_symlink():
            continue
        if p.is_dir():
            os.chmod(p, dmode)
        elif p.is_file():
            os.chmod(p, fmode)  # temporary files made with mkstemp are 0600
            if p.name != MARKER:
                files.append(str(p.relative_to(folder)))
    from . import __version__
    text = json.dumps({"written_by": f"fmvmg-sim {__version__}", "command": command, "files": files}, indent=1)
    p = folder / MARKER
    p.write_text(text + "\n", encoding="utf-8")
    os.chmod(p, fmode)


class OutputFolder:
    """A command's output folder being written: checked now, moved into place by :meth:`commit`.

    Use it as a context manager (``with OutputFolder(out) as tmp:``; :func:`output_folder` is the
    same), or keep the object and call :meth:`commit` once every file is written; a folder never
    committed is discarded when the object is collected or the interpreter exits.

    Parameters
    ----------
    path : path-like
        The ``-o`` folder.
    expect_bytes : int, optional
        Expected size of the output (checked against the free space before any work).
    command : str, optional
        The command's name, recorded in the folder's marker file.
    in_place : bool, optional
        Write into ``path`` itself instead of a temporary folder, for outputs whose files name
        their own paths (cases read back by later runs). The previous folder is moved aside first
        and restored if the new one is discarded.

    Attributes
    ----------
    target : Path
        The final folder (absolute).
    path : Path
        The folder to write into (temporary unless ``in_place``).

    Raises
    ------
    InputError
        On creation, before any work: see :func:`check_output_folder`.
    """

    def __init__(self, path: str | os.PathLike, expect_bytes: int | None = None, command: str | None = None,
                 in_place: bool = False):
        self.target = check_output_folder(path, expect_bytes)
        self._user_path = str(path)
        self.command = command
        self.in_place = in_place
        self.target.parent.mkdir(parents=True, exist_ok=True)
        self._old: Path | None = None
        if in_place:
            if self.target.is_dir():
                self._old = self._aside()
            self.target.mkdir(mode=dir_mode())
            os.chmod(self.target, dir_mode())
            self.path = self.target
        else:
            self.path = Path(tempfile.mkdtemp(prefix=f".{self.target.name}.tmp-", dir=self.target.parent))
            os.chmod(self.path, dir_mode())
        self._finalizer = weakref.finalize(self, _discard, self.path, self.target, self._old, in_place)

    def _aside(self) -> Path:
        old = Path(tempfile.mkdtemp(prefix=f".{self.target.name}.old-", dir=self.target.parent))
        with _no_interrupt():
            os.replace(self.target, old)
        return old

    @property
    def committed(self) -> bool:
        """Whether :meth:`commit` or :meth:`discard` has run."""
        return not self._finalizer.alive

    def commit(self) -> Path:
        """Move the written folder into place (replacing an earlier output there).

        Returns
        -------
        Path
            The final folder.
        """
        if self.committed:
            raise RuntimeError(f"{self.target} was already committed or discarded")
        _finish(self.path, self.command)
        if not self.in_place:
            with _no_interrupt():
                if self.target.is_dir():
                    refusal = _refusal(self.target)  # filled by someone else while we worked
                    if refusal:
                        self.discard()
                        raise InputError(f"{refusal} (the output is not moved there)", self._user_path)
                    self._old = self._aside()
                os.replace(self.path, self.target)
        self._finalizer.detach()
        if self._old is not None:
            shutil.rmtree(self._old, ignore_errors=True)
        return self.target

    def discard(self) -> None:
        """Remove what was written (and, in place, put the earlier output back)."""
        self._finalizer()

    def __enter__(self) -> Path:
        return self.path

    def __exit__(self, exc_type, exc, tb) -> None:
        if exc_type is None:
            self.commit()
        else:
            self.discard()


def _discard(path: Path, target: Path, old: Path | None, in_place: bool) -> None:
    with _no_interrupt():
        shutil.rmtree(path, ignore_errors=True)
        if in_place and old is not None and old.is_dir() and not target.exists():
            os.replace(old, target)


#: The same, under the name that reads well in a ``with`` statement: ``with output_folder(out) as tmp:``.
output_folder = OutputFolder
