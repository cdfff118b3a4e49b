"""Errors for bad input: one line naming the file, the frame (or row) and the field."""

from __future__ import annotations

from pathlib import Path


class InputError(ValueError):
    """Bad input data.

    The message is always one line of the form
    ``<file>: frame <k>: <field>: <what is wrong>`` (``frame`` is omitted when the
    problem is not tied to one frame), so a user can find the offending value.
    """

    def __init__(self, file: str | Path | None, field: str, message: str, frame: int | None = None):
        self.file = str(file) if file is not None else "<memory>"
        self.field = field
        self.frame = frame
        where = f"{self.file}: " + (f"frame {frame}: " if frame is not None else "")
        super().__init__((where + f"{field}: {message}").replace("\n", " "))


def first_bad_frame(mask) -> int:
    """Index of the first True along axis 0 of a boolean array (any trailing axes reduced)."""
    import numpy as np

    m = np.asarray(mask)
    if m.ndim > 1:
        m = m.reshape(m.shape[0], -1).any(axis=1)
    return int(np.flatnonzero(m)[0])


#: What the command line says after Ctrl-C: every write is atomic and every stage resumable (pipeline.stage.run).
INTERRUPTED = "nothing half-written was kept; the same command resumes where it stopped"


def os_error_line(exc: OSError) -> str:
    """An :class:`OSError` as one line naming the path and the reason (``<path>: <reason>``), instead of a
    traceback: an unreadable folder, a read-only output, a network failure, a full disk."""
    reason = exc.strerror or str(exc) or type(exc).__name__
    where = f"{exc.filename}: " if exc.filename is not None else ""
    if exc.filename2 is not None:
        where = f"{exc.filename} -> {exc.filename2}: "
    return (where + reason).replace("\n", " ")


#: A human subject's height in metres: anything outside is a wrong unit or a wrong number, never a person.
SUBJECT_HEIGHT_M = (0.5, 2.5)
