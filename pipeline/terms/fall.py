"""The fall test every simulation of the G1 shares: the physicalize stage's rollouts (a clip that falls is invalid),
the training environments' terminations (CPU and mjlab) and the evaluation's episodes.

Fallen: the pelvis :data:`FALL_HEIGHT_DROP` below the reference's, or the torso's up-axis more than 60 degrees
(:data:`FALL_TILT_COS`) from the reference torso's up-axis. The tilt is relative: a reference that bends over a
table or a box (> 60 degrees) is not a fall when tracked.
"""

from __future__ import annotations

import mujoco
import numpy as np

from pipeline.rotations import quat_mat

FALL_HEIGHT_DROP = 0.30  # pelvis this far below the reference's: fallen
FALL_TILT_COS = 0.5  # torso up-axis this far (60 degrees) from the reference torso's up-axis: fallen


def fallen(d: mujoco.MjData, ref_pelvis_z: float, torso: int, ref_torso_quat: np.ndarray | None = None) -> bool:
    """The test of the module docstring on ``d``; ``torso`` the torso's body id, ``ref_torso_quat`` the reference
    torso's orientation (wxyz; None: the vertical)."""
    up = d.xmat[torso].reshape(3, 3)[:, 2]
    ref_up = np.array([0.0, 0.0, 1.0]) if ref_torso_quat is None else quat_mat(ref_torso_quat)[:, 2]
    return bool(d.qpos[2] < ref_pelvis_z - FALL_HEIGHT_DROP or float(up @ ref_up) < FALL_TILT_COS)
