"""Where a rollout loses its balance: the figures a fall is traced by, carried by every physicalized clip beside its
validity figures (:mod:`physicalize.validate`). Not bars: causes.

* ``pelvis_drift_pre_fall_m`` / ``com_drift_pre_fall_m`` -- the horizontal distance of the simulated pelvis from the
  tracked reference's and of the simulated centre of mass from the plan's (:mod:`physicalize.plan`),
  :data:`PRE_FALL_S` before the fall (at the last frame when the robot did not fall);
* ``drift_onset_s`` -- when the pelvis first strays :data:`DRIFT_M` from its reference (None: never), and
  ``drift_onset_support`` -- the planned support then (``double``, ``left``, ``right``, ``none``): a drift that starts
  on one foot is the single support's, one that starts in double support the plan's or the posture's;
* ``step_adjustments`` / ``step_adjust_max_m`` -- the landings whose capture-point shift
  (:mod:`physicalize.stepping`) moved the foot more than :data:`STEP_ADJUST_M`, and the largest such shift;
* ``support_mismatch_frac`` -- frames whose measured foot contacts (a foot pressing the floor with more than
  ``touch_force``) differ from the planned support;

and, the same for every rollout of one reference (:func:`reference_balance_figures`, computed once per clip):

* ``reference_single_support_max_s`` -- the longest single-support run of the tracked reference;
* ``plan_zmp_outside_max_m`` -- how far the planned ZMP leaves the planned support polygon (0: the plan is
  supportable by the feet it plans);
* ``reference_foot_gap_min_m`` -- the least lateral distance between the reference's feet in the pelvis's heading
  frame (negative: the feet cross).

:func:`com_series` gathers the reference, planned and simulated CoM of a rollout for the clip's plot.
"""

from __future__ import annotations

import mujoco
import numpy as np

from physicalize.plan import clip_to_polygon, support_polygon
from physicalize.reference import Reference
from physicalize.rollout import Rollout
from pipeline.clip import RobotClip
from pipeline.foot_contact import runs
from pipeline.rotations import yaw_of

DRIFT_M = 0.05
PRE_FALL_S = 0.2
STEP_ADJUST_M = 0.02
SUPPORT_NAMES = {(True, True): "double", (True, False): "left", (False, True): "right", (False, False): "none"}


def simulated_com(model: mujoco.MjModel, qpos: np.ndarray) -> np.ndarray:
    """(T, 3) the robot's centre of mass (the pelvis subtree's) along the simulated ``qpos``."""
    d = mujoco.MjData(model)
    out = np.zeros((len(qpos), 3))
    pelvis = model.body("pelvis").id
    for t, q in enumerate(qpos):
        d.qpos[:] = q
        mujoco.mj_kinematics(model, d)
        mujoco.mj_comPos(model, d)
        out[t] = d.subtree_com[pelvis]
    return out


def _zmp_outside(ref: Reference, zmp: np.ndarray | None) -> float:
    """Largest distance of the planned ZMP from the planned support polygon (0 inside)."""
    if zmp is None:
        return 0.0
    worst = 0.0
    for t in range(min(len(zmp), ref.frames)):
        if not ref.stance[t].any():
            continue
        poly = support_polygon(ref, t)
        worst = max(worst, float(np.linalg.norm(zmp[t] - clip_to_polygon(zmp[t], poly, 0.0))))
    return worst


def reference_balance_figures(ref: Reference, zmp: np.ndarray | None) -> dict:
    """The reference's figures of the module docstring (``zmp``: the planned ZMP, None when the reference was not
    planned)."""
    single = ref.stance.sum(axis=1) == 1
    yaw = yaw_of(ref.qpos[:, 3:7])
    lateral = np.stack([-np.sin(yaw), np.cos(yaw)], axis=-1)  # the pelvis's left in the floor plane
    gap = np.einsum("ti,ti->t", ref.foot_pos[:, 0, :2] - ref.foot_pos[:, 1, :2], lateral)
    return {
        "reference_single_support_max_s": max((b - a for a, b in runs(single)), default=0) / ref.fps,
        "plan_zmp_outside_max_m": _zmp_outside(ref, zmp),
        "reference_foot_gap_min_m": float(gap.min()) if len(gap) else 0.0,
    }


def balance_figures(model: mujoco.MjModel, ref: Reference, roll: Rollout, touch_force: float) -> dict:
    """The rollout's figures of the module docstring, for one rollout of ``ref``."""
    fps, T = ref.fps, roll.frames
    pelvis = np.linalg.norm(roll.qpos[:, :2] - ref.qpos[:T, :2], axis=1)
    plan = ref.com if ref.com_plan is None else ref.com_plan
    com = np.linalg.norm(simulated_com(model, roll.qpos)[:, :2] - plan[:T, :2], axis=1)
    k = T - 1 if roll.fell_at is None else max(min(roll.fell_at, T) - int(round(PRE_FALL_S * fps)), 0)
    onset = np.flatnonzero(pelvis > DRIFT_M)
    figures = {
        "pelvis_drift_pre_fall_m": float(pelvis[k]),
        "com_drift_pre_fall_m": float(com[k]),
        "drift_onset_s": float(onset[0] / fps) if onset.size else None,
        "drift_onset_support": SUPPORT_NAMES[tuple(bool(s) for s in ref.stance[onset[0]])] if onset.size else None,
    }
    shifts = []
    if roll.support is not None and roll.landing_shift is not None:
        support = np.asarray(roll.support, bool)
        for f in range(2):
            lands = np.flatnonzero(support[1:, f] & ~support[:-1, f]) + 1
            shifts += [float(np.linalg.norm(roll.landing_shift[t - 1, f])) for t in lands]
    adjusted = [s for s in shifts if s > STEP_ADJUST_M]
    figures["step_adjustments"] = len(adjusted)
    figures["step_adjust_max_m"] = max(adjusted, default=0.0)
    measured = roll.foot_force > touch_force
    figures["support_mismatch_frac"] = float((measured != ref.stance[:T]).any(axis=1).mean()) if T else 0.0
    return figures


def com_series(clip: RobotClip, scene, ref, zmp, roll: Rollout) -> dict:
    """Reference, planned and simulated CoM, planned ZMP, pelvis heights and the support box: the clip's plot; and the
    tracked reference's ``qpos`` (the dataset's ``reference.state``)."""
    T = roll.frames
    return {
        "reference_qpos": clip.qpos,  # what was tracked: the retargeted clip after its start prefix, if any
        "reference": ref.com[:T],
        "planned": (ref.com if ref.com_plan is None else ref.com_plan)[:T],
        "zmp_planned": None if zmp is None else zmp[:T],
        "simulated": simulated_com(scene.model, roll.qpos),
        "pelvis_ref": clip.qpos[:T, 2],
        "pelvis_sim": roll.qpos[:, 2],
        "support": _support_box(ref)[:T],
    }


def _support_box(ref) -> np.ndarray:
    """(T, 2, 2) per frame the [min, max] x and y of the stance feet's sole corners (the support region's bounds)."""
    corners = np.where(ref.stance[:, :, None, None], ref.corners[..., :2], np.nan).reshape(ref.frames, -1, 2)
    return np.stack([np.nanmin(corners, axis=1), np.nanmax(corners, axis=1)], axis=1)
