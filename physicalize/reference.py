"""The tracking reference: a retargeted motion (``qpos`` at the control rate) turned into the
per-step quantities the whole-body controller tracks, by forward kinematics of the same model.

* ``qvel``/``qacc`` by central differences (root angular velocity in the pelvis frame, as MuJoCo);
* centre of mass ``com`` (the planner may replace it with a dynamically feasible one);
* foot support schedule: a foot is in stance where its sole is within :data:`STANCE_HEIGHT` of
  the floor and moves slower than :data:`STANCE_SPEED` (the retargeter's pinned feet); on frames
  where no foot is, every foot that low and slower than :data:`GAP_SPEED` supports (heel-strike/
  toe-off: double support), else the lower foot; runs shorter than 3 frames (60 ms) are merged into their neighbours;
* feet, hands and torso poses.
"""

from __future__ import annotations

from dataclasses import dataclass

import mujoco
import numpy as np
from scipy.signal import savgol_filter

from physicalize.target import Target
from pipeline.foot_contact import keep_runs
from pipeline.kinematics import qvel_from_qpos
from pipeline.robot import FOOT_BODIES, HAND_BODIES, NQ_ROBOT, NV_ROBOT, sole_corners

STANCE_HEIGHT = 0.03
STANCE_SPEED = 0.1
GAP_SPEED = 0.5  # m/s: between two stance runs a low foot moving slower than this supports (heel strike, toe-off)
MIN_RUN = 3
SMOOTH_S = 0.2  # s, window of the Savitzky-Golay filter of the tracked CoM and foot derivatives


@dataclass
class Reference:
    """Per-frame tracking quantities (T frames at ``fps``)."""

    fps: float
    qpos: np.ndarray  # (T, 36)
    qvel: np.ndarray  # (T, 35)
    qacc: np.ndarray  # (T, 35)
    com: np.ndarray  # (T, 3)
    stance: np.ndarray  # (T, 2) bool
    foot_pos: np.ndarray  # (T, 2, 3)
    foot_quat: np.ndarray  # (T, 2, 4)
    sole_height: np.ndarray  # (T, 2) lowest sole corner above the floor
    corners: np.ndarray  # (T, 2, 4, 3) sole corners (world)
    hand_pos: np.ndarray  # (T, 2, 3)
    torso_quat: np.ndarray  # (T, 4)
    com_plan: np.ndarray | None = None  # (T, 3) feasible CoM (physicalize.plan), else the kinematic one
    seat: np.ndarray | None = None  # (T, k, 3) seat support points, NaN rows where none (physicalize.seat.seat_support)
    grasp: object | None = None  # physicalize.grasp.GraspSchedule: hand targets and forces while holding objects

    @property
    def frames(self) -> int:
        return self.qpos.shape[0]

    def _derivatives(self) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """(com, com velocity, com acceleration, foot velocity, foot acceleration) over the clip, computed once per CoM
        series (the plan may replace ``com_plan`` after construction). A Savitzky-Golay filter (cubic,
        :data:`SMOOTH_S` window) smooths the CoM and gives the derivatives: double finite differences of a
        retargeted clip's CoM height reached 9-34 m/s^2, which the QP turned into 100+ N force swings."""
        com = self.com if self.com_plan is None else self.com_plan
        cached = getattr(self, "_cache", None)
        if cached is None or cached[0] is not com:
            n = int(round(SMOOTH_S * self.fps)) | 1  # odd window
            dt = 1.0 / self.fps
            if self.frames > n and n >= 5:
                sg = lambda x, k: savgol_filter(x, n, 3, deriv=k, delta=dt, axis=0, mode="interp")  # noqa: E731
                derived = (sg(com, 0), sg(com, 1), sg(com, 2), sg(self.foot_pos, 1), sg(self.foot_pos, 2))
            elif self.frames > 1:
                cv = np.gradient(com, dt, axis=0)
                fv = np.gradient(self.foot_pos, dt, axis=0)
                derived = (com, cv, np.gradient(cv, dt, axis=0), fv, np.gradient(fv, dt, axis=0))
            else:
                z = np.zeros_like(self.foot_pos)
                derived = (com, np.zeros_like(com), np.zeros_like(com), z, z)
            cached = self._cache = (com, *derived)
        return cached[1:]

    def target(self, t: int) -> Target:
        """The controller's target at frame ``t`` (clamped to the clip)."""
        t = min(max(t, 0), self.frames - 1)
        com, cv, ca, fv, fa = self._derivatives()
        target = Target(
            qpos=self.qpos[t],
            qvel=self.qvel[t],
            qacc=self.qacc[t],
            com=com[t],
            com_vel=cv[t],
            com_acc=ca[t],
            stance=(bool(self.stance[t, 0]), bool(self.stance[t, 1])),
            foot_pos=self.foot_pos[t],
            foot_quat=self.foot_quat[t],
            foot_vel=fv[t],
            foot_acc=fa[t],
            sole_height=self.sole_height[t],
            hand_pos=self.hand_pos[t],
            torso_quat=self.torso_quat[t],
            seated=self.seat is not None and bool(np.isfinite(self.seat[t, :, 0]).any()),
        )
        return target if self.grasp is None else self.grasp.fill(target, t)


def build_reference(model: mujoco.MjModel, qpos: np.ndarray, fps: float) -> Reference:
    """Forward kinematics of ``qpos`` (T, 36) on ``model`` (its robot part) at ``fps``."""
    qpos = np.asarray(qpos, dtype=np.float64)
    T = qpos.shape[0]
    d = mujoco.MjData(model)
    feet = [model.body(b).id for b in FOOT_BODIES]
    hands = [model.body(b).id for b in HAND_BODIES]
    torso, pelvis = model.body("torso_link").id, model.body("pelvis").id
    corners = [sole_corners(model, b) for b in FOOT_BODIES]
    com = np.zeros((T, 3))
    foot_pos, foot_quat = np.zeros((T, 2, 3)), np.zeros((T, 2, 4))
    sole = np.zeros((T, 2, 4, 3))
    hand_pos, torso_quat = np.zeros((T, 2, 3)), np.zeros((T, 4))
    for t in range(T):
        d.qpos[:NQ_ROBOT] = qpos[t]
        mujoco.mj_kinematics(model, d)
        mujoco.mj_comPos(model, d)
        com[t] = d.subtree_com[pelvis]
        for k in range(2):
            foot_pos[t, k] = d.xpos[feet[k]]
            mujoco.mju_mat2Quat(foot_quat[t, k], d.xmat[feet[k]])
            sole[t, k] = d.xpos[feet[k]] + corners[k] @ d.xmat[feet[k]].reshape(3, 3).T
            hand_pos[t, k] = d.xpos[hands[k]]
        mujoco.mju_mat2Quat(torso_quat[t], d.xmat[torso])
    qvel = qvel_from_qpos(qpos, fps) if T > 1 else np.zeros((1, NV_ROBOT))
    qacc = np.gradient(qvel, 1.0 / fps, axis=0) if T > 2 else np.zeros_like(qvel)
    height = sole[..., 2].min(axis=2)
    speed = np.zeros((T, 2))
    if T > 1:
        speed = np.linalg.norm(np.gradient(sole.mean(axis=2)[..., :2], 1.0 / fps, axis=0), axis=-1)
    low = height < STANCE_HEIGHT
    stance = low & (speed < STANCE_SPEED)
    gap = ~stance.any(axis=1)  # between one foot's lift-off and the other's landing: every low foot supports
    stance[gap] = (low & (speed < GAP_SPEED))[gap]
    for k in range(2):
        stance[:, k] = keep_runs(keep_runs(stance[:, k], MIN_RUN, False), MIN_RUN, True)
    none = ~stance.any(axis=1)  # never plan a flight phase: the lower foot supports
    stance[none, np.argmin(height[none], axis=1)] = True
    return Reference(fps, qpos, qvel, qacc, com, stance, foot_pos, foot_quat, height, sole, hand_pos, torso_quat)


def place_on_floor(model: mujoco.MjModel, qpos: np.ndarray) -> np.ndarray:
    """``qpos`` (T, 36) with each frame's root raised or lowered so its lowest sole corner is on the floor."""
    qpos = np.array(qpos, dtype=np.float64, copy=True)
    d = mujoco.MjData(model)
    feet = [model.body(b).id for b in FOOT_BODIES]
    corners = [sole_corners(model, b) for b in FOOT_BODIES]
    for q in qpos:
        d.qpos[:NQ_ROBOT] = q
        mujoco.mj_kinematics(model, d)
        low = min((d.xpos[f] + c @ d.xmat[f].reshape(3, 3).T)[:, 2].min() for f, c in zip(feet, corners))
        q[2] -= low
    return qpos
