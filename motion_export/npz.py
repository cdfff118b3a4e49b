"""Motion ``.npz`` for mjlab (``mjlab-npz``) and for BeyondMimic (``beyondmimic-npz``): exactly the arrays each
tracker's loader reads, in its own joint and body order, plus the object beside.

What mjlab's ``scripts/csv_to_npz.py`` writes and ``tasks/tracking/mdp/commands.py: MotionLoader`` reads
(``np.load``, every array cast to float32), and BeyondMimic's (``whole_body_tracking``) namesakes of both:

* ``fps`` -- ``[fps]``, a one-element float array (``csv_to_npz.py`` writes ``[output_fps]``; the loaders read no
  rate: the tracking tasks step the motion at their own 50 Hz, which is our datasets' rate);
* ``joint_pos``, ``joint_vel`` -- ``[T, 29]`` (no root columns: OmniRetarget's ``[T, 36]`` is not this layout);
* ``body_pos_w``, ``body_quat_w`` (``wxyz``), ``body_lin_vel_w``, ``body_ang_vel_w`` -- ``[T, 30, .]``, every body of
  the robot, world frame (:mod:`motion_export.bodies`); the loaders index them by the robot's body indices of the
  task's tracked bodies.

The loaders read the columns by index, never by name, so the order is the tracker's own:

* ``mjlab-npz`` -- mjlab's entity order (MuJoCo's depth-first: :data:`~motion_export.bodies.ENTITY_JOINT_NAMES`,
  :data:`~motion_export.bodies.ENTITY_BODY_NAMES`); ``body_lin_vel_w`` the velocity of each body frame's origin
  (what mjlab's ``csv_to_npz.py`` records);
* ``beyondmimic-npz`` -- Isaac Lab's breadth-first order (:mod:`motion_export.isaaclab`); ``body_lin_vel_w`` the
  velocity of each body's centre of mass (Isaac Lab's ``body_lin_vel_w``). An mjlab file read by BeyondMimic puts
  27 of the 29 joint columns on the wrong joint.

Beside them (the loaders ignore other keys): ``joint_names`` and ``body_names`` in the file's order (OmniRetarget
writes them too; our reader orders joints by them), and per object, as OmniRetarget writes the object:
``object_pos_w`` ``[T, 3]``, ``object_quat_w`` ``[T, 4]`` ``wxyz``, with ``object_lin_vel_w`` / ``object_ang_vel_w``
(world) and ``object_names`` ``[N]``; a second object is ``object_2_pos_w`` etc. Arrays are float32, as the trackers
write them; uncompressed (``np.savez``).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from motion_export.bodies import ENTITY_JOINT_NAMES, BodyMotion, body_motion, entity_joints
from motion_export.episodes import ExportEpisode
from motion_export.isaaclab import ISAACLAB_BODY_INDEX, ISAACLAB_BODY_NAMES, ISAACLAB_JOINT_INDEX, ISAACLAB_JOINT_NAMES
from motion_export.writer import Written, object_motions
from pipeline.dataset.objects import object_column
from pipeline.robot import JOINTS_QPOS, JOINTS_QVEL


def _f32(a) -> np.ndarray:
    return np.asarray(a, dtype=np.float32)


BODY_KEYS = ("body_pos_w", "body_quat_w", "body_lin_vel_w", "body_ang_vel_w")


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


def beyondmimic_arrays(ep: ExportEpisode, bodies: BodyMotion) -> dict[str, np.ndarray]:
    """BeyondMimic's arrays (module doc): :func:`robot_arrays` with the joints and bodies in Isaac Lab's order and
    ``body_lin_vel_w`` the bodies' centre-of-mass velocity."""
    a = robot_arrays(ep, bodies)
    out = {k: a[k][:, ISAACLAB_JOINT_INDEX] for k in ("joint_pos", "joint_vel")}
    out.update({k: a[k][:, ISAACLAB_BODY_INDEX] for k in BODY_KEYS})
    out["body_lin_vel_w"] = _f32(bodies.com_lin_vel[:, ISAACLAB_BODY_INDEX])
    out["joint_names"], out["body_names"] = np.array(ISAACLAB_JOINT_NAMES), np.array(ISAACLAB_BODY_NAMES)
    return out


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


def _save(ep: ExportEpisode, path: Path, robot: dict[str, np.ndarray], layout: dict) -> Written:
    objects, where = object_arrays(ep)
    np.savez(path, fps=np.array([ep.fps]), **robot, **objects)
    return Written((path,), ep.fps, ep.frames, where, layout)


def write(ep: ExportEpisode, folder: Path, stem: str) -> Written:
    """``<stem>.npz`` in mjlab's layout and order (module doc)."""
    layout = {
        "keys": "fps [1]; joint_pos, joint_vel [T, 29] (mjlab entity joint order); body_pos_w, body_quat_w (wxyz), "
        "body_lin_vel_w (body frame origin), body_ang_vel_w [T, 30, .] (every entity body, world); joint_names, "
        "body_names",
        "order": "mjlab (MuJoCo depth-first); not BeyondMimic's: export --format beyondmimic-npz for it",
        "loader": "mjlab.tasks.tracking.mdp.commands.MotionLoader (the tracking task steps it at 50 Hz)",
    }
    return _save(ep, folder / f"{stem}.npz", robot_arrays(ep, body_motion(ep.clip.qpos, ep.qvel)), layout)


def write_beyondmimic(ep: ExportEpisode, folder: Path, stem: str) -> Written:
    """``<stem>.npz`` in BeyondMimic's layout and Isaac Lab's order (module doc)."""
    layout = {
        "keys": "fps [1]; joint_pos, joint_vel [T, 29] (Isaac Lab joint order); body_pos_w, body_quat_w (wxyz), "
        "body_lin_vel_w (centre of mass), body_ang_vel_w [T, 30, .] (Isaac Lab body order, world); joint_names, "
        "body_names",
        "order": "Isaac Lab / PhysX breadth-first (what whole_body_tracking's csv_to_npz.py saves)",
        "loader": "whole_body_tracking.tasks.tracking.mdp.commands.MotionLoader (by index; names ignored)",
    }
    return _save(ep, folder / f"{stem}.npz", beyondmimic_arrays(ep, body_motion(ep.clip.qpos, ep.qvel)), layout)
