"""GMR motion ``.pkl``: a pickled dict of numpy arrays, as GMR's retargeting scripts save it and
:func:`pipeline.readers.peers.read_gmr_pkl` reads it.

* ``fps`` -- an int when integral (GMR saves its rate as a number);
* ``root_pos`` ``[T, 3]`` (world), ``root_rot`` ``[T, 4]`` scalar-last ``xyzw`` (GMR's order, not MuJoCo's);
* ``dof_pos`` ``[T, 29]`` in the Unitree G1 29-DoF order (= mjlab's entity order; GMR stores no joint names);
* ``local_body_pos`` ``[T, 38, 3]`` -- every body of GMR's G1 (``assets/unitree_g1/g1_mocap_29dof.xml`` in
  ``YanjieZe/GMR``), in that xml's order (:data:`GMR_BODY_NAMES`; GMR's ``KinematicsModel`` walks the xml
  depth-first), at its position in the root (pelvis) frame, ``R_root^T (p_body - p_root)`` (GMR: forward kinematics
  with the root at the origin, unrotated), and ``link_body_list`` (their names): the fields TWIST-style loaders
  read and look bodies up in by name (``left_rubber_hand``, ``head_mocap``, ...). 30 of them are mjlab's entity
  bodies (the same offsets as GMR's xml); the other 8 are fixed frames on them, :data:`GMR_FIXED_FRAMES`
  (``p = p_parent + R_parent offset``);
* beside them (not GMR's own: GMR has no object), per object ``object_name``, ``object_pos`` ``[T, 3]`` and
  ``object_rot`` ``[T, 4]`` ``xyzw``; a second object ``object_2_name`` etc.

float64 arrays (GMR's), a plain ``pickle`` (protocol 4) that the numpy-only unpickler of the readers accepts.
"""

from __future__ import annotations

import pickle
from pathlib import Path

import numpy as np

from motion_export.bodies import BodyMotion, body_motion, entity_joints
from motion_export.episodes import ExportEpisode
from motion_export.writer import Written, fps_value
from pipeline.dataset.objects import object_column
from pipeline.robot import JOINTS_QPOS, ROOT_POS, ROOT_QUAT
from pipeline.rotations import rotation_from_wxyz, wxyz_to_xyzw

#: GMR's G1 bodies in ``g1_mocap_29dof.xml``'s order (depth-first, as its KinematicsModel and MuJoCo list them)
GMR_BODY_NAMES: tuple[str, ...] = (
    "pelvis",
    "left_hip_pitch_link", "left_hip_roll_link", "left_hip_yaw_link", "left_knee_link", "left_ankle_pitch_link",
    "left_ankle_roll_link", "left_toe_link",
    "pelvis_contour_link",
    "right_hip_pitch_link", "right_hip_roll_link", "right_hip_yaw_link", "right_knee_link", "right_ankle_pitch_link",
    "right_ankle_roll_link", "right_toe_link",
    "waist_yaw_link", "waist_roll_link", "torso_link", "head_link", "head_mocap", "imu_in_torso",
    "left_shoulder_pitch_link", "left_shoulder_roll_link", "left_shoulder_yaw_link", "left_elbow_link",
    "left_wrist_roll_link", "left_wrist_pitch_link", "left_wrist_yaw_link", "left_rubber_hand",
    "right_shoulder_pitch_link", "right_shoulder_roll_link", "right_shoulder_yaw_link", "right_elbow_link",
    "right_wrist_roll_link", "right_wrist_pitch_link", "right_wrist_yaw_link", "right_rubber_hand",
)  # fmt: skip

#: GMR's bodies that mjlab's G1 lacks: jointless children of an entity body, ``name: (parent, offset [m] in the
#: parent's frame)``, as ``g1_mocap_29dof.xml`` places them (``pos``; every one unrotated, ``quat`` 1 0 0 0)
GMR_FIXED_FRAMES: dict[str, tuple[str, tuple[float, float, float]]] = {
    "left_toe_link": ("left_ankle_roll_link", (0.1, 0.0, -0.02)),
    "pelvis_contour_link": ("pelvis", (0.0, 0.0, 0.0)),
    "right_toe_link": ("right_ankle_roll_link", (0.1, 0.0, -0.02)),
    "head_link": ("torso_link", (0.0039635, 0.0, -0.044)),
    "head_mocap": ("torso_link", (0.0, 0.0, 0.4)),
    "imu_in_torso": ("torso_link", (-0.03959, -0.00224, 0.14792)),
    "left_rubber_hand": ("left_wrist_yaw_link", (0.0415, 0.003, 0.0)),
    "right_rubber_hand": ("right_wrist_yaw_link", (0.0415, -0.003, 0.0)),
}


def gmr_body_pos(bodies: BodyMotion) -> np.ndarray:
    """``[T, 38, 3]`` world positions of :data:`GMR_BODY_NAMES`: the entity's bodies, and each fixed frame at
    ``p_parent + R_parent offset``."""
    out = np.empty((bodies.frames, len(GMR_BODY_NAMES), 3))
    for k, name in enumerate(GMR_BODY_NAMES):
        if name in GMR_FIXED_FRAMES:
            parent, offset = GMR_FIXED_FRAMES[name]
            b = bodies.names.index(parent)
            out[:, k] = bodies.pos[:, b] + rotation_from_wxyz(bodies.quat[:, b]).apply(offset)
        else:
            out[:, k] = bodies.pos[:, bodies.names.index(name)]
    return out


def local_body_pos(body_pos: np.ndarray, root_pos: np.ndarray, root_quat: np.ndarray) -> np.ndarray:
    """``[T, B, 3]`` body positions ``body_pos`` (world) in the root frame: ``R_root^T (p_body - p_root)``
    (``root_quat`` ``wxyz``)."""
    T, B = body_pos.shape[:2]
    rel = (body_pos - root_pos[:, None]).reshape(T * B, 3)
    inv = rotation_from_wxyz(np.repeat(root_quat, B, axis=0)).inv()
    return inv.apply(rel).reshape(T, B, 3)


def gmr_dict(ep: ExportEpisode, bodies: BodyMotion) -> dict:
    """The pickled dict (module doc)."""
    q = ep.clip.qpos
    d = {
        "fps": fps_value(ep.fps),
        "root_pos": q[:, ROOT_POS].copy(),
        "root_rot": wxyz_to_xyzw(q[:, ROOT_QUAT]),
        "dof_pos": entity_joints(q[:, JOINTS_QPOS]),
        "local_body_pos": local_body_pos(gmr_body_pos(bodies), q[:, ROOT_POS], q[:, ROOT_QUAT]),
        "link_body_list": list(GMR_BODY_NAMES),
    }
    for k, o in enumerate(ep.clip.objects):
        col = object_column(k)
        d[f"{col}_name"], d[f"{col}_pos"], d[f"{col}_rot"] = o.name, o.pose[:, :3].copy(), wxyz_to_xyzw(o.pose[:, 3:])
    return d


def write(ep: ExportEpisode, folder: Path, stem: str) -> Written:
    """``<stem>.pkl`` (module doc)."""
    path = folder / f"{stem}.pkl"
    path.write_bytes(pickle.dumps(gmr_dict(ep, body_motion(ep.clip.qpos, ep.qvel)), protocol=4))
    where = tuple(f"{object_column(k)}_pos, {object_column(k)}_rot (xyzw)" for k in range(len(ep.clip.objects)))
    layout = {
        "keys": "fps; root_pos [T, 3]; root_rot [T, 4] xyzw; dof_pos [T, 29] (Unitree = mjlab order); "
        "local_body_pos [T, 38, 3] (pelvis frame); link_body_list (GMR's g1_mocap_29dof.xml bodies, its order)"
    }
    return Written((path,), ep.fps, ep.frames, where, layout)
