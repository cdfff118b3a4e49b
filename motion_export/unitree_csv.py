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

What the sidecar also says, because a CSV is not the validated motion: it holds no velocities (``csv_to_npz.py``
differentiates the positions: ``torch.gradient``); and mjlab's ``csv_to_npz.py`` re-interpolates it to 50 Hz at
``t = 0, 0.02, ... < (N - 1) / 30`` s (linear, slerp), so the ``.npz`` it writes is the validated 50 Hz motion twice
interpolated, off by :func:`csv_round_trip` (measured per episode: ``motion.csv_to_npz.round_trip``); it saves
``/tmp/motion.npz`` and uploads it to a W&B registry (``--output-name`` is the registry's collection; a W&B login
needed). ``--format mjlab-npz`` writes the validated motion as mjlab reads it, with no round trip.
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


def csv_round_trip(source: np.ndarray, csv_fps: float, csv_qpos: np.ndarray, fps: float) -> dict:
    """Largest joint [rad] and root position [m] difference between the source ``qpos`` at ``fps`` and the CSV's
    rows ``csv_qpos`` (at ``csv_fps``) linearly interpolated back at ``csv_to_npz.py``'s times ``k / fps <
    (N - 1) / csv_fps`` (module doc)."""
    t_csv = np.arange(len(csv_qpos)) / csv_fps
    t = np.arange(0.0, (len(csv_qpos) - 1) / csv_fps, 1.0 / fps)[: len(source)]
    cols = list(range(3)) + list(range(7, source.shape[1]))
    back = np.stack([np.interp(t, t_csv, csv_qpos[:, k]) for k in cols], axis=1)
    err = np.abs(back - source[: len(t)][:, cols])
    return {"max_joint_err_rad": float(err[:, 3:].max()), "max_root_pos_err_m": float(err[:, :3].max()),
            "frames": len(t)}  # fmt: skip


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
        "velocities": "none in the file (csv_to_npz.py differentiates the positions)",
        "csv_to_npz": {
            "command": "python -m mjlab.scripts.csv_to_npz --input-file <file> --input-fps 30 --output-fps 50 "
            "--output-name <collection>",
            "writes": "/tmp/motion.npz, then uploads it to a W&B registry (output-name: the collection; needs a W&B "
            "login); for a local file of the validated motion export --format mjlab-npz instead",
            "round_trip": {
                **csv_round_trip(ep.clip.qpos, CSV_FPS, clip.qpos, ep.fps),
                "what": "this CSV re-interpolated to 50 Hz as csv_to_npz.py does, against the validated motion: "
                "its npz is not the validated motion",
            },
        },
    }
    return Written(tuple(files), CSV_FPS, clip.frames, tuple(where), layout)
