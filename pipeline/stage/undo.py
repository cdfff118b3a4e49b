"""A failed command leaves ``datasets/<NAME>/`` as it found it.

Why: a stage that fails after it started writing left its traces (the ``human/`` dataset and its logs of an input
whose clips all failed, a ``.work/<stage>/run.json``, a message pointing at a dataset that is not there), and
``--overwrite`` with such an input replaced ``human/`` under a ``retargeted/`` made from the old one. The writers swap
whole folders into place and never change a file in place (:mod:`pipeline.stage.atomic`), so a snapshot of the folder
as hard links costs no copy of the data and still holds the old files after the command replaced them.

:class:`Undo` takes that snapshot before the command (held under the dataset's lock: :mod:`pipeline.stage.lock`),
:meth:`Undo.restore` puts it back when the command failed (an error, or nothing written), :meth:`Undo.drop` forgets
it when the command succeeded or was interrupted (Ctrl-C or a kill keeps the resume state: :mod:`pipeline.stage.run`).
"""

from __future__ import annotations

import os
import shutil
import uuid
from pathlib import Path

from pipeline.stage.lock import LOCK_NAME, process_start

_TAG = ".undo-"


def _linked_copy(src: Path, dst: Path) -> None:
    if src.is_dir() and not src.is_symlink():
        shutil.copytree(src, dst, copy_function=os.link, symlinks=True)
    else:
        os.link(src, dst, follow_symlinks=False)


def _remove_dead_snapshots(folder: Path) -> None:
    """Delete the snapshots left by killed commands (their pid no longer runs)."""
    for old in folder.glob(f"{_TAG}*-*"):
        pid = old.name.removeprefix(_TAG).split("-")[0]
        if pid.isdigit() and process_start(int(pid)) is None:
            shutil.rmtree(old, ignore_errors=True)


def _remove(p: Path) -> None:
    if p.is_dir() and not p.is_symlink():
        shutil.rmtree(p)
    else:
        p.unlink(missing_ok=True)


class Undo:
    """A hard-link snapshot of ``folder`` (``datasets/<NAME>``) but its lock (see the module docstring)."""

    def __init__(self, folder: Path):
        self.folder = Path(folder)
        _remove_dead_snapshots(self.folder)
        self.saved = self.folder / f"{_TAG}{os.getpid()}-{uuid.uuid4().hex[:8]}"
        self.entries = [p.name for p in self._entries()]
        self.saved.mkdir()
        for name in self.entries:
            _linked_copy(self.folder / name, self.saved / name)

    def _entries(self) -> list[Path]:
        if not self.folder.is_dir():
            return []
        return sorted(p for p in self.folder.iterdir() if p.name != LOCK_NAME and not p.name.startswith(_TAG))

    def restore(self) -> None:
        """Put ``folder`` back as it was: what the command made removed, what it replaced put back."""
        for p in self._entries():
            _remove(p)
        for name in self.entries:
            os.replace(self.saved / name, self.folder / name)
        self.drop()

    def drop(self) -> None:
        shutil.rmtree(self.saved, ignore_errors=True)
