"""One writer per dataset: ``datasets/<NAME>/.lock``, held by every command that writes into ``datasets/<NAME>/``.

Why: two runs on one NAME with different inputs interleave their stages (``human/`` of one input, ``retargeted/`` of
the other) and a rerun then finds the mix "up to date". A second writer must stop before it writes anything, in one
line naming the first.

How: the writer holds an exclusive ``fcntl.flock`` on the lock file (the kernel drops it when the holder dies, SIGKILL
included, so exclusion never depends on a clean exit) and writes into it who it is: pid, the process's start time
(``/proc/<pid>/stat``, so a pid the system reused for another process is not taken for the holder) and its command
line. A refused writer reads that to name the holder. A lock file whose flock is free but which still names a writer
is the stale lock of a killed run: taken over, with a line saying so; one whose writer still runs (same pid, same start
time: a file system without flock) is held. The holder removes the file when it is done, and the dataset's folder if
taking the lock made it and it is still empty, so a refused or failed command leaves nothing new.
"""

from __future__ import annotations

import fcntl
import json
import os
import sys
import time
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path

from pipeline.errors import InputError

LOCK_NAME = ".lock"
_HELD: dict[Path, int] = {}  # lock files this process holds -> nesting depth (a command calling another)


def process_start(pid: int) -> int | None:
    """The start time of process ``pid`` in clock ticks since boot (``/proc/<pid>/stat`` field 22), None if no
    such process runs (or there is no ``/proc``)."""
    try:
        stat = Path(f"/proc/{pid}/stat").read_text()
    except OSError:
        return None
    return int(stat.rsplit(")", 1)[1].split()[19])


def _alive(holder: dict) -> bool:
    """Whether the process a lock file names still runs (the same pid started at the same time)."""
    pid = holder.get("pid")
    return isinstance(pid, int) and process_start(pid) is not None and process_start(pid) == holder.get("start")


def _describe(holder: dict) -> str:
    if not holder.get("pid"):
        return "another process (starting)"
    since = time.strftime("%Y-%m-%d %H:%M:%S", time.localtime(holder.get("since", 0)))
    return f"pid {holder['pid']} ({holder.get('command', '?')}, since {since})"


def _read(fd: int) -> dict:
    os.lseek(fd, 0, os.SEEK_SET)
    try:
        holder = json.loads(os.read(fd, 1 << 16) or b"{}")
    except ValueError:
        return {}
    return holder if isinstance(holder, dict) else {}


def _open_locked(path: Path) -> tuple[int, bool]:
    """An fd of ``path`` and whether this process got the flock; the fd refers to the file now at ``path`` (a
    holder removing it between our open and our flock makes us open it again)."""
    while True:
        fd = os.open(path, os.O_RDWR | os.O_CREAT, 0o644)
        try:
            fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except BlockingIOError:
            return fd, False
        try:
            same = os.fstat(fd).st_ino == os.stat(path).st_ino
        except FileNotFoundError:
            same = False
        if same:
            return fd, True
        os.close(fd)


def _made_folders(folder: Path) -> list[Path]:
    """The folders ``mkdir(parents=True)`` of ``folder`` creates, deepest first."""
    made, p = [], folder
    while not p.exists():
        made.append(p)
        p = p.parent
    return made


@contextmanager
def dataset_lock(folder: Path, command: str | None = None) -> Iterator[Path]:
    """Hold ``<folder>/.lock`` (``folder``: ``datasets/<NAME>``) for the block; another writer gets one
    :class:`InputError` line naming the holder (see the module docstring). Re-entrant within one process."""
    folder = Path(folder)
    path = (folder / LOCK_NAME).absolute()
    if path in _HELD:
        _HELD[path] += 1
        try:
            yield path
        finally:
            _HELD[path] -= 1
        return
    made = _made_folders(folder)
    folder.mkdir(parents=True, exist_ok=True)
    fd, got = _open_locked(path)
    try:
        holder = _read(fd)
        if not got or (_alive(holder) and holder.get("pid") != os.getpid()):
            raise InputError(folder, "lock", f"held by {_describe(holder)}: one writer per dataset; wait for it")
        if holder.get("pid"):
            stale = f"{folder}: lock: took over the stale lock of {_describe(holder)}: no longer running"
            print(stale, file=sys.stderr)
        me = {
            "pid": os.getpid(),
            "start": process_start(os.getpid()),
            "since": time.time(),
            "command": command or " ".join(["lessmimic", *sys.argv[1:]]),
        }
        os.ftruncate(fd, 0)
        os.lseek(fd, 0, os.SEEK_SET)
        os.write(fd, json.dumps(me).encode())
        _HELD[path] = 1
    except BaseException:
        os.close(fd)
        _remove_empty(made)
        raise
    try:
        yield path
    finally:
        del _HELD[path]
        path.unlink(missing_ok=True)  # while holding the flock: a waiting writer reopens the path (_open_locked)
        os.close(fd)
        _remove_empty(made)


def _remove_empty(folders: list[Path]) -> None:
    for p in folders:
        try:
            p.rmdir()
        except OSError:
            return


@contextmanager
def writer_lock(name: str | None) -> Iterator[Path | None]:
    """:func:`dataset_lock` of ``datasets/<name>/`` (the datasets root of :func:`pipeline.stage.paths.datasets_root`),
    or nothing when ``name`` is None (a command that writes no dataset); a bad name is its one-line error."""
    if name is None:
        yield None
        return
    from pipeline.dataset.schema import dataset_root
    from pipeline.stage.paths import datasets_root

    with dataset_lock(dataset_root(datasets_root(), name)) as path:
        yield path
