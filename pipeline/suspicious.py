"""What is only suspicious in an input is a warning in the stage's report, never silence (issue 55).

An absurd input is an error (:class:`~pipeline.errors.InputError`: a root faster than 15 m/s between two frames, an
Euler angle beyond +-720 degrees, a subject height outside 0.5-2.5 m). An input that is possible but unlike a person
moving (a root between 5 and 15 m/s, an angle past a full turn, a stated height far from the one its joints give) is
read, and said, in the form of an error line (``<file>: frame <k>: <field>: <what>``):

* :func:`suspect` -- says one such thing;
* :func:`collecting` -- the block's suspicions, each printed once on stderr as ``warning: <line>`` and listed for the
  stage's report (``"warnings"`` in ``report.json``: the human and retargeted stages'); outside such a block a
  suspicion is a Python warning of the category :class:`SuspiciousInput`;
* :func:`check_height` -- the stated height against the joints' (every clip :func:`pipeline.readers.read_clip` reads).
"""

from __future__ import annotations

import sys
import warnings
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path

from pipeline.body_height import estimate_height
from pipeline.errors import InputError

#: Faster than this between two frames (and not above :data:`pipeline.readers.MAX_ROOT_SPEED_MPS`), a clip's root is
#: running: possible, unlike the motions this toolkit is for, and what a unit slip or a noisy marker also gives.
SUSPICIOUS_ROOT_SPEED_MPS = 5.0
#: A stated subject height this far (relative) from the head-to-ankle estimate of the joints is a wrong height or a
#: wrong skeleton (the estimate is within 3% of the stated height on OMOMO, the synthetic clips and LAFAN1).
HEIGHT_MISMATCH = 0.15


class SuspiciousInput(UserWarning):
    """An input read as it is, though it is unlike a person moving (see the module docstring)."""


_COLLECTING: list[list[str]] = []  # the lists of the open collecting() blocks, innermost last


def suspect(file: str | Path | None, field: str, why: str, frame: int | None = None) -> str:
    """Say that ``field`` of ``file`` (at ``frame``) is suspicious: into every open :func:`collecting` block (printed
    once), else a :class:`SuspiciousInput` warning; the line comes back."""
    line = str(InputError(file, field, why, frame=frame))
    if not _COLLECTING:
        warnings.warn(line, SuspiciousInput, stacklevel=2)
        return line
    if all(line not in seen for seen in _COLLECTING):
        print(f"warning: {line}", file=sys.stderr)
    for seen in _COLLECTING:
        if line not in seen:
            seen.append(line)
    return line


@contextmanager
def collecting() -> Iterator[list[str]]:
    """The suspicions said inside the block (:func:`suspect`), in order, each once."""
    seen: list[str] = []
    _COLLECTING.append(seen)
    try:
        yield seen
    finally:
        _COLLECTING.pop()


def check_height(clip, path: str | Path) -> None:
    """A clip's stated ``subject_height`` (OMOMO's ``height_dict.pkl``, a BVH's rest pose) more than
    :data:`HEIGHT_MISMATCH` from the head-to-ankle estimate of its joints is suspicious (:func:`suspect`)."""
    if clip.subject_height is None:
        return
    estimate = estimate_height(clip.joint_pos, clip.skeleton)
    if estimate is None or abs(clip.subject_height / estimate - 1.0) <= HEIGHT_MISMATCH:
        return
    why = (
        f"{clip.subject_height:.3g} m as the input states it, {estimate:.3g} m from its joints (head to ankle): "
        f"{abs(clip.subject_height / estimate - 1.0):.0%} apart; read as stated (--height M overrides it)"
    )
    suspect(path, "subject_height", why)
