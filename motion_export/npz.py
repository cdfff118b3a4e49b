"""mjlab / BeyondMimic motion ``.npz``: exactly the arrays mjlab's tracking task loads, plus the object beside.

What mjlab's ``scripts/csv_to_npz.py`` writes and ``tasks/tracking/mdp/commands.py: MotionLoader`` reads
(``np.load``, every array cast to float32):

* ``fps`` -- ``[fps]``, a one-element float array (``csv_to_npz.py`` writes ``[output_fps]``; the loader reads no
  rate: the tracking task steps the motion at its own 50 Hz, which is our datasets' rate);
* ``joint_pos``, ``joint_vel`` -- ``[T, 29]`` in the entity's joint order (no root columns: OmniRetarget's
  ``[T, 36]`` is not this layout);
* ``body_pos_w``, ``body_quat_w`` (``wxyz``), ``body_lin_vel_w``, ``body_ang_vel_w`` -- ``[T, 30, .]``, every body of
  the entity in its order, world frame (:mod:`motion_export.bodies`); the loader indexes them by the entity's body
  indices of the task's tracked bodies.

Beside them (the loader ignores other keys): ``joint_names`` and ``body_names`` (OmniRetarget writes them too; our
reader orders joints by them), and per object, as OmniRetarget writes the object: ``object_pos_w`` ``[T, 3]``,
``object_quat_w`` ``[T, 4]`` ``wxyz``, with ``object_lin_vel_w`` / ``object_ang_vel_w`` (world) and
``object_names`` ``[N]``; a second object is ``object_2_pos_w`` etc. Arrays are float32, as mjlab writes them;
uncompressed (``np.savez``).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from motion_export.bodies import ENTITY_JOINT_NAMES, BodyMotion, body_motion, entity_joints
from motion_export.episodes import ExportEpisode
from motion_export.writer import Written, object_motions
from pipeline.dataset.objects import object_column
from pipeline.robot import JOINTS_QPOS, JOINTS_QVEL


def _f32(a) -> np.ndarray:
    return np.asarray(a, dtype=np.float32)


def robot_arrays(ep: ExportEpisode, bodies: BodyMotion) -> dict[str, np.ndarray]:
    """mjlab's arrays (module doc) of the robot: ``joint_pos`` ... ``body_ang_vel_w``, with the joint and body names."""
    return {
        "joint_pos": _f32(entity_joints(ep.clip.qpos[:, JOINTS_QPOS])),
        "joint_vel": _f32(entity_joints(ep.qvel[:, JOINTS_QVEL])),
        "body_pos_w": _f32(bodies.pos),
        "body_quat_w": _f32(bodies.quat),
        "body_lin_vel_w": _f32(bodies.lin_vel),
        "body_ang_vel_w": _f32(bodies.ang_vel),
        "joint_names": np.array(ENTITY_JOINT_NAMES),
        "body_names": np.array(bodies.names),
    }


def object_arrays(ep: ExportEpisode) -> tuple[dict[str, np.ndarray], tuple[str, ...]]:
    """The objects' arrays (``object_pos_w`` ..., module doc) and, per object, the keys that carry its pose."""
    arrays, where = {}, []
    motions = object_motions(ep)
    for k, o in enumerate(motions):
        col = object_column(k)
        arrays.update(
            {
                f"{col}_pos_w": _f32(o.pos),
                f"{col}_quat_w": _f32(o.quat),
                f"{col}_lin_vel_w": _f32(o.lin_vel),
                f"{col}_ang_vel_w": _f32(o.ang_vel),
            }
        )
        where.append(f"{col}_pos_w, {col}_quat_w (wxyz)")
    if motions:
        arrays["object_names"] = np.array([o.name for o in motions])
    return arrays, tuple(where)


def write(ep: ExportEpisode, folder: Path, stem: str) -> Written:
    """``<stem>.npz`` in mjlab's layout (module doc)."""
    path = folder / f"{stem}.npz"
    objects, where = object_arrays(ep)
    np.savez(path, fps=np.array([ep.fps]), **robot_arrays(ep, body_motion(ep.clip.qpos, ep.qvel)), **objects)
    layout = {
        "keys": "fps [1]; joint_pos, joint_vel [T, 29] (entity joint order); body_pos_w, body_quat_w (wxyz), "
        "body_lin_vel_w, body_ang_vel_w [T, 30, .] (every entity body, world); joint_names, body_names",
        "loader": "mjlab.tasks.tracking.mdp.commands.MotionLoader (the tracking task steps it at 50 Hz)",
    }
    return Written((path,), ep.fps, ep.frames, where, layout)
