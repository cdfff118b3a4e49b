"""Physical validity of a physicalized clip: the figures every clip carries in ``report.json``.

A clip is ``valid`` only if every bar in :class:`Bars` holds; ``reason`` names the first that does
not, with the time it first failed where that has one ("fell at t=3.24 s", "object lost at t=...").

* ``external_force_max_n`` -- largest ``xfrc_applied`` on any body (the teacher applies none);
  ``root_residual_max_n`` -- the free joint's inverse-dynamics residual of the recorded frames,
  ``max |(M qdd + h - J_c^T f_c)_{root}|`` (``mj_inverse`` at each frame's forward acceleration under
  its recorded action): the root force beyond gravity and contacts that the motion needs;
* ``penetration_max_m`` -- deepest contact over all physics steps;
* ``foot_slide_frac_1cm_per_frame`` -- frames where a foot loaded with more than :data:`LOADED_N`
  at both ends moves more than 1 cm horizontally, over the frames with a loaded foot;
* ``torque_saturation_frac`` -- frames where any actuator is at 99 % of its effort limit;
* ``joint_limit_violation_frac`` -- frames where any joint is past its range by more than
  :data:`LIMIT_TOL` (MuJoCo's limits are soft);
* ``mpjpe_m`` -- mean over frames and :data:`pipeline.robot.G1_LINK_NAMES` of the link position
  error vs the retargeted reference; ``root_pos_err_max_m``;
* ``object_pos_err_m`` / ``object_rot_err_rad`` -- mean error vs the reference object track;
* ``fell``, ``realtime_factor`` (simulated seconds per wall second on one core; the stage adds
  ``realtime_factor_per_core``: per CPU second, robust to a loaded machine, and the tracked
  reference's ``reference_static_torque_*``, :mod:`physicalize.static_torque`, and
  ``reference_grasp_outside_friction_frac``, the held frames whose planned hand forces leave the hands'
  friction cones, :func:`physicalize.grasp.press_force`: not bars, causes).
"""

from __future__ import annotations

from dataclasses import asdict, dataclass

import mujoco
import numpy as np

from physicalize.rollout import Rollout
from pipeline.robot import FOOT_BODIES, G1_JOINT_NAMES, G1_LINK_NAMES, JOINTS_QPOS, NQ_ROBOT
from pipeline.scene import Scene
from pipeline.terms.layout import SUBSTEPS

LOADED_N = 50.0
LIMIT_TOL = 0.02
OBJECT_LOST_M = 0.25


@dataclass(frozen=True)
class Bars:
    """The validity bars (issue #4)."""

    external_force_max_n: float = 0.0
    penetration_max_m: float = 0.02
    foot_slide_frac_1cm_per_frame: float = 0.05
    joint_limit_violation_frac: float = 0.0
    mpjpe_m: float = 0.10
    root_pos_err_max_m: float = 0.25
    object_pos_err_m: float = 0.10


def _link_positions(model: mujoco.MjModel, qpos: np.ndarray, bodies: list[int]) -> np.ndarray:
    d = mujoco.MjData(model)
    out = np.zeros((len(qpos), len(bodies), 3))
    for t, q in enumerate(qpos):
        d.qpos[: q.shape[0]] = q
        mujoco.mj_kinematics(model, d)
        out[t] = d.xpos[bodies]
    return out


def foot_slide_frac(foot_xy: np.ndarray, loaded: np.ndarray, tol: float = 0.01) -> float:
    """Fraction of loaded-foot frame pairs (loaded at both ends) whose foot moves more than ``tol``."""
    both = loaded[1:] & loaded[:-1]
    if not both.any():
        return 0.0
    step = np.linalg.norm(np.diff(foot_xy, axis=0), axis=-1)
    return float((both & (step > tol)).any(axis=1).sum() / both.any(axis=1).sum())


def root_residual(model: mujoco.MjModel, qpos: np.ndarray, qvel: np.ndarray, action: np.ndarray) -> float:
    """Largest free-joint residual ``|qfrc_inverse[0:6]|`` of the recorded frames: the generalized
    root force, beyond gravity and contacts, that their accelerations would need (0: unassisted)."""
    d = mujoco.MjData(model)
    worst = 0.0
    for q, v, a in zip(qpos, qvel, action):
        d.qpos[:], d.qvel[:], d.ctrl[:] = q, v, a
        mujoco.mj_forward(model, d)
        mujoco.mj_inverse(model, d)
        worst = max(worst, float(np.abs(d.qfrc_inverse[:6]).max()))
    return worst


def _quat_angle(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    return 2.0 * np.arccos(np.clip(np.abs(np.sum(a * b, axis=-1)), 0.0, 1.0))


def validate(
    scene: Scene, rollout: Rollout, ref_qpos: np.ndarray, ref_objects: dict[str, np.ndarray], bars: Bars = Bars()
) -> dict:
    """The report entry of one clip (see the module docstring); ``ref_qpos`` (T, 36) at the control rate."""
    m, T_ref, T = scene.model, len(ref_qpos), rollout.frames
    fps = 1.0 / (m.opt.timestep * SUBSTEPS)
    q = rollout.qpos
    lo, hi = np.array([m.jnt_range[m.joint(j).id] for j in G1_JOINT_NAMES]).T
    joints = q[:, JOINTS_QPOS]
    bodies = [m.body(b).id for b in G1_LINK_NAMES]
    sim_links = _link_positions(m, q[:, :NQ_ROBOT], bodies)
    ref_links = _link_positions(m, ref_qpos[:T], bodies)
    foot_xy = sim_links[:, [G1_LINK_NAMES.index(b) for b in FOOT_BODIES], :2]
    root_err = np.linalg.norm(q[:, :3] - ref_qpos[:T, :3], axis=1)
    figures = {
        "frames": T_ref,
        "frames_simulated": T,
        "external_force_max_n": float(rollout.external_force.max(initial=0.0)),
        "root_residual_max_n": root_residual(m, q, rollout.qvel, rollout.action),
        "penetration_max_m": float(rollout.penetration.max(initial=0.0)),
        "foot_slide_frac_1cm_per_frame": foot_slide_frac(foot_xy, rollout.foot_force > LOADED_N),
        "torque_saturation_frac": float(
            (np.abs(rollout.torque) >= 0.99 * scene.profile.effort_limit).any(axis=1).mean()
        ),
        "joint_limit_violation_frac": float(((joints < lo - LIMIT_TOL) | (joints > hi + LIMIT_TOL)).any(axis=1).mean()),
        "mpjpe_m": float(np.linalg.norm(sim_links - ref_links, axis=-1).mean()),
        "root_pos_err_max_m": float(root_err.max()),
        "fell": rollout.fell_at is not None,
        "qp_failures": rollout.qp_failures,
        "realtime_factor": T / fps / max(rollout.seconds, 1e-9),
    }
    obj_pos, obj_rot, lost_at = [], [], None
    for name, adr in scene.object_qpos_adr.items():
        ref = ref_objects[name][:T]
        e = np.linalg.norm(q[:, adr : adr + 3] - ref[:, :3], axis=1)
        obj_pos.append(e.mean())
        obj_rot.append(_quat_angle(q[:, adr + 3 : adr + 7], ref[:, 3:7]).mean())
        far = np.flatnonzero(e > OBJECT_LOST_M)
        if far.size and (lost_at is None or far[0] < lost_at):
            lost_at = int(far[0])
    if obj_pos:
        figures["object_pos_err_m"], figures["object_rot_err_rad"] = float(max(obj_pos)), float(max(obj_rot))
    reasons = []
    if rollout.fell_at is not None:
        reasons.append(f"fell at t={rollout.fell_at / fps:.2f} s")
    if lost_at is not None:
        reasons.append(f"object lost at t={lost_at / fps:.2f} s")
    for key, bar in asdict(bars).items():
        if key in figures and figures[key] > bar + 1e-12:
            reasons.append(f"{key} {figures[key]:.4g} > {bar:g}")
    figures["fell_at_s"] = None if rollout.fell_at is None else rollout.fell_at / fps
    figures["object_lost_at_s"] = None if lost_at is None else lost_at / fps
    figures["valid"] = not reasons
    figures["reason"] = "; ".join(reasons)
    return figures


CONTACT_WINDOW_S = 1.0  # a fall this soon after the reference's first contact is a fall at contact
FAILURE_CLASSES = (
    "fell before contact",
    "fell at contact",
    "fell while interacting",
    "object lost",
    "joint limits",
    "penetration",
    "foot sliding",
    "tracking error",
    "error",
)


def failure_class(figures: dict, bars: Bars = Bars()) -> str | None:
    """Why an invalid clip failed, one of :data:`FAILURE_CLASSES` (None when valid): the first thing that went
    wrong. An object lost before the robot fell (or without a fall) is ``object lost``; a fall is classed by
    when it came relative to the reference's first robot-object contact (``reference_first_contact_s``): before
    it (approach or locomotion), within :data:`CONTACT_WINDOW_S` of it, or later; without a fall or a loss, the
    first bar exceeded (joint limits, penetration, foot sliding, else the tracking errors)."""
    if figures.get("valid"):
        return None
    if str(figures.get("reason", "")).startswith("error:"):
        return "error"
    fell, lost, onset = (
        figures.get("fell_at_s"),
        figures.get("object_lost_at_s"),
        figures.get("reference_first_contact_s"),
    )
    if lost is not None and (fell is None or lost < fell):
        return "object lost"
    if fell is not None:
        if onset is None or fell < onset:
            return "fell before contact"
        return "fell at contact" if fell < onset + CONTACT_WINDOW_S else "fell while interacting"
    for key, name in (
        ("joint_limit_violation_frac", "joint limits"),
        ("penetration_max_m", "penetration"),
        ("foot_slide_frac_1cm_per_frame", "foot sliding"),
    ):
        if figures.get(key, 0.0) > getattr(bars, key) + 1e-12:
            return name
    return "tracking error"


NOT_AVERAGED = ("episode",)  # an index, not a figure
COUNTED = ("teacher_gains",)  # which gain set was kept: clips per set, not a mean


def summarise(per_clip: list[dict]) -> dict:
    """Dataset-level summary: ``valid_frac``, ``clips``, the mean of each numeric figure over the clips that have it
    (a figure that is None for a clip, as ``fell_at_s`` of a clip that did not fall, is left out of that mean, whichever
    clip comes first) and, for the :data:`COUNTED` ones, the number of clips per value
    (``clips_per_teacher_gains``: {"0": 3, "1": 1})."""
    if not per_clip:
        return {"valid_frac": 0.0, "clips": 0}
    out = {"valid_frac": float(np.mean([c["valid"] for c in per_clip])), "clips": len(per_clip)}
    keys = dict.fromkeys(k for c in per_clip for k in c)  # every clip's figures, in first-seen order
    for k in keys:
        values = [c[k] for c in per_clip if isinstance(c.get(k), (int, float)) and not isinstance(c.get(k), bool)]
        if k in NOT_AVERAGED or not values:
            continue
        if k in COUNTED:
            out[f"clips_per_{k}"] = {str(x): values.count(x) for x in sorted(set(values))}
        else:
            out[k] = float(np.mean(values))
    return out
