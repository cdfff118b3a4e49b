"""What every format writer shares: its result (:class:`Written`) and the objects' world-frame motion.

A writer is ``write(ep, folder, stem) -> Written``: it writes episode ``ep`` into ``folder`` under the name ``stem``
and says what it wrote; the writers whose format holds bodies run the forward kinematics
(:func:`motion_export.bodies.body_motion`) themselves, the Unitree CSV (no bodies) does not.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from motion_export.episodes import ExportEpisode
from pipeline.rotations import rotation_from_wxyz


@dataclass(frozen=True)
class Written:
    """The files one motion was written to (the motion first), the exported frame rate and frames, where each
    object's pose is carried (one string per object), and the format's own facts for the sidecar (``layout``)."""

    files: tuple[Path, ...]
    fps: float
    frames: int
    objects_in: tuple[str, ...] = ()
    layout: dict = field(default_factory=dict)

    def motion_entry(self, folder: Path) -> dict:
        """The sidecar's ``motion`` facts (file names relative to ``folder``)."""
        files = [str(p.relative_to(folder)) for p in self.files]
        return {"files": files, "fps": self.fps, "frames": self.frames, "seconds": self.frames / self.fps,
                **self.layout}  # fmt: skip


@dataclass(frozen=True)
class ObjectMotion:
    """One object's ``[T, 3]`` world position, ``[T, 4]`` orientation ``wxyz``, and linear / angular velocity, both
    in the world frame (the dataset's angular velocity is in the object frame: rotated by the orientation)."""

    name: str
    pos: np.ndarray
    quat: np.ndarray
    lin_vel: np.ndarray
    ang_vel: np.ndarray


def object_motions(ep: ExportEpisode) -> list[ObjectMotion]:
    """Every object of ``ep`` as :class:`ObjectMotion`."""
    out = []
    for o, vel in zip(ep.clip.objects, ep.object_vel):
        ang_w = rotation_from_wxyz(o.pose[:, 3:7]).apply(vel[:, 3:6])
        out.append(ObjectMotion(o.name, o.pose[:, :3], o.pose[:, 3:7], vel[:, :3], ang_w))
    return out


def fps_value(fps: float) -> int | float:
    """An integral frame rate as an int (how GMR and HDMI files write theirs), else the float."""
    return int(round(fps)) if abs(fps - round(fps)) < 1e-9 else float(fps)
