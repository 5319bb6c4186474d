"""One run per results folder: an exclusive lock on the folder while a run uses it.

A run holds ``fcntl.flock`` on the file ``.ngat-lock`` in its results folder (a sweep also on
its sweep folder) from the check of the folder to its last write. Another process that tries
the folder is refused at once with :class:`FolderInUse`, naming the holder's process id, which
the lock file holds. The kernel drops the lock when the holding process ends, however it ends
(SIGKILL included), so a lock file left behind never blocks a later run; a run that ends
normally removes it. Within one process the lock is re-entrant for the thread that holds it
(the command line locks the folder before it checks it, the driver locks it again for the
run) and refused to other threads.
"""

from __future__ import annotations

import contextlib
import fcntl
import logging
import os
import threading
import time
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path

from ngat.output import OutputError

__all__ = ["folder_lock", "FolderInUse", "LOCK_FILE"]

log = logging.getLogger(__name__)

LOCK_FILE = ".ngat-lock"
HOLDER_WAIT = 1.0
"""Seconds a refused process waits for the lock's winner to write its process id (it writes
it just after it wins the lock, so a process refused in between would read an empty file)."""


class FolderInUse(OutputError):
    """The results folder is locked by another run."""


@dataclass
class _Held:
    """A lock this process holds: its file descriptor, the owning thread, the nesting depth."""

    fd: int
    thread: int
    depth: int = 0


_held: dict[Path, _Held] = {}
_guard = threading.Lock()


def _in_use(folder: Path, holder: str) -> FolderInUse:
    by = f"process {holder}" if holder else "another process"
    return FolderInUse(
        f"results folder '{folder}' is already in use by {by}: wait until that run ends or "
        "choose another folder"
    )


def _holder(fd: int) -> str:
    """Return the process id written in the lock file ``fd`` ("" if none within HOLDER_WAIT s)."""
    deadline = time.monotonic() + HOLDER_WAIT
    while True:
        written = os.pread(fd, 32, 0).decode(errors="replace")
        if written.endswith("\n") or time.monotonic() > deadline:
            return written.strip()
        time.sleep(0.01)


def _acquire(folder: Path) -> int:
    """Lock ``folder/.ngat-lock`` and write this process's id into it; return its descriptor."""
    path = folder / LOCK_FILE
    while True:
        try:
            fd = os.open(path, os.O_RDWR | os.O_CREAT, 0o644)
        except OSError as error:
            raise OutputError(
                f"results folder '{folder}' is not writable ({error.strerror}); choose another "
                "with --out"
            ) from None
        try:
            fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except BlockingIOError:
            holder = _holder(fd)
            os.close(fd)
            raise _in_use(folder, holder) from None
        except OSError as error:  # a file system without locks (some network or FUSE mounts)
            log.warning("%s: no file locks (%s): nothing keeps a second run out", folder, error)
            break
        # The previous holder removes the file while it still holds the lock: a lock won on a
        # removed file guards nothing, so try again on the file now at the path.
        with contextlib.suppress(FileNotFoundError):
            if os.stat(path).st_ino == os.fstat(fd).st_ino:
                break
        os.close(fd)
    os.ftruncate(fd, 0)
    os.write(fd, f"{os.getpid()}\n".encode())
    return fd


def _release(folder: Path, fd: int) -> None:
    """Remove the lock file, then unlock it (in this order, see :func:`_acquire`)."""
    with contextlib.suppress(OSError):
        (folder / LOCK_FILE).unlink()
    os.close(fd)


@contextlib.contextmanager
def folder_lock(folder: str | Path) -> Iterator[Path]:
    """Hold the exclusive lock of a results folder; create the folder if it is missing.

    Parameters
    ----------
    folder
        Results folder (or sweep folder).

    Yields
    ------
    Path
        The folder.

    Raises
    ------
    FolderInUse
        If another process, or another thread of this one, holds the lock.
    OutputError
        If the folder cannot be created or written.
    """
    folder = Path(folder)
    try:
        folder.mkdir(parents=True, exist_ok=True)
    except OSError as error:
        raise OutputError(
            f"results folder '{folder}' is not writable ({error.strerror}); choose another "
            "with --out"
        ) from None
    key = folder.resolve()
    with _guard:
        held = _held.get(key)
        if held is not None and held.thread != threading.get_ident():
            raise _in_use(folder, str(os.getpid()))
        if held is None:
            held = _held[key] = _Held(_acquire(folder), threading.get_ident())
        held.depth += 1
    try:
        yield folder
    finally:
        with _guard:
            held.depth -= 1
            if held.depth == 0:
                del _held[key]
                _release(folder, held.fd)
