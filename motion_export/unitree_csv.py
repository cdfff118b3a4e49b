"""Unitree's G1 retargeting ``.csv``: the layout of Unitree's public G1 dataset (LAFAN1 retargeted) that mjlab's
``scripts/csv_to_npz.py`` reads (``np.loadtxt(delimiter=",")``, ``input_fps`` 30 by default).

One row per frame, comma-separated, no header: root position (3, world), root quaternion scalar-last ``xyzw`` (4),
the 29 joint angles in the Unitree G1 order (= mjlab's entity order). The file carries no rate: it is written at
:data:`CSV_FPS` (30 Hz, Unitree's), **resampled** from the dataset's 50 Hz at ``t_k = k / 30`` s for
``k = 0 .. floor(duration * 30)`` (no extrapolation past the last frame): root position and joints by linear
interpolation, root orientation by spherical linear interpolation (scipy ``Slerp``;
:meth:`pipeline.clip.RobotClip.resampled`). Numbers with 10 significant digits.

Each object's track goes beside it at the same rows as ``<stem>.<object>.csv``: position (3), quaternion ``xyzw``
(4), resampled the same way. The sidecar says so (``motion.resampled``).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from motion_export.bodies import entity_joints
from motion_export.episodes import ExportEpisode
from motion_export.writer import Written
from pipeline.rotations import wxyz_to_xyzw
from pipeline.stage.paths import file_stem

CSV_FPS = 30.0
NUMBER_FORMAT = "%.10g"


def csv_rows(qpos: np.ndarray) -> np.ndarray:
    """``[T, 36]`` rows (module doc) of ``qpos [T, 36]`` (root quaternion ``wxyz``, joints in mjlab order)."""
    return np.concatenate([qpos[:, :3], wxyz_to_xyzw(qpos[:, 3:7]), entity_joints(qpos[:, 7:])], axis=1)


def write(ep: ExportEpisode, folder: Path, stem: str) -> Written:
    """``<stem>.csv`` at 30 Hz and one ``<stem>.<object>.csv`` per object (module doc)."""
    clip = ep.clip.resampled(CSV_FPS)
    path = folder / f"{stem}.csv"
    np.savetxt(path, csv_rows(clip.qpos), delimiter=",", fmt=NUMBER_FORMAT)
    files, where = [path], []
    for o in clip.objects:
        obj_path = folder / f"{stem}.{file_stem(o.name)}.csv"
        np.savetxt(obj_path, np.concatenate([o.pose[:, :3], wxyz_to_xyzw(o.pose[:, 3:])], 1), delimiter=",",
                   fmt=NUMBER_FORMAT)  # fmt: skip
        files.append(obj_path)
        where.append(f"{obj_path.name}: x, y, z, qx, qy, qz, qw per row")
    layout = {
        "keys": "per row: root x, y, z; root qx, qy, qz, qw; 29 joints (Unitree = mjlab order); no header",
        "resampled": {
            "from_fps": ep.fps,
            "to_fps": CSV_FPS,
            "times": "t_k = k / 30 s, k = 0 .. floor(duration * 30)",
            "method": "root position and joints linear interpolation, root orientation slerp (scipy Slerp)",
        },
        "mjlab": "python -m mjlab.scripts.csv_to_npz --input-file <file> --input-fps 30 --output-fps 50 ...",
    }
    return Written(tuple(files), CSV_FPS, clip.frames, tuple(where), layout)
