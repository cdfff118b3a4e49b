"""Per-clip inspection plot (PNG) of a retargeted clip: what a person checks first.

Three panels over time:

1. robot foot heights (the ``left_foot`` / ``right_foot`` sole sites of g1.xml, world z) with the
   human's detected foot contacts shaded (:func:`pipeline.foot_contact.detect_foot_contacts`);
2. hand-object distance: the signed distance between each hand's collision geom
   (``<side>_hand_collision``) and the nearest object collision geom (``mj_geomDistance``,
   capped at 0.5 m), with the human's hand-contact frames shaded;
3. joint speeds: the largest ``|dq/dt|`` over the 29 joints per frame (forward differences).
"""

from __future__ import annotations

from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import mujoco  # noqa: E402
import numpy as np  # noqa: E402

from pipeline.clip import HumanClip, RobotClip  # noqa: E402
from pipeline.foot_contact import detect_foot_contacts  # noqa: E402
from pipeline.robot import JOINTS_QPOS, NQ_ROBOT
from pipeline.stage.figure import save_figure  # noqa: E402
from retarget.collision_sweep import scene_for  # noqa: E402

DIST_CAP = 0.5
SIDES = ("left", "right")


def _shade(ax, t: np.ndarray, mask: np.ndarray, color: str, label: str) -> None:
    edges = np.flatnonzero(np.diff(np.r_[0, mask.astype(int), 0]))
    for k, (a, b) in enumerate(zip(edges[::2], edges[1::2])):
        ax.axvspan(t[a], t[min(b, len(t)) - 1], color=color, alpha=0.15, lw=0, label=label if k == 0 else None)


def clip_series(robot: RobotClip) -> dict[str, np.ndarray]:
    """Per-frame foot heights (T,2), hand-object distances (T,2) (NaN without objects), max joint speed (T,)."""
    scene = scene_for(robot.objects)
    m, d = scene.model, mujoco.MjData(scene.model)
    feet = [m.site(f"{s}_foot").id for s in SIDES]
    hands = [m.geom(f"{s}_hand_collision").id for s in SIDES]
    obj_geoms = [
        g
        for g in range(m.ngeom)
        if m.geom_contype[g] and m.body_rootid[m.geom_bodyid[g]] != m.body("pelvis").id and m.geom_bodyid[g] != 0
    ]
    T = robot.frames
    foot_z, hand_d = np.zeros((T, 2)), np.full((T, 2), np.nan)
    fromto = np.zeros(6)
    for t in range(T):
        d.qpos[:NQ_ROBOT] = robot.qpos[t]
        for o in robot.objects:
            a = scene.object_qpos_adr[o.name]
            d.qpos[a : a + 7] = o.pose[t]
        mujoco.mj_kinematics(m, d)
        foot_z[t] = d.site_xpos[feet, 2]
        if obj_geoms:
            hand_d[t] = [min(mujoco.mj_geomDistance(m, d, h, g, DIST_CAP, fromto) for g in obj_geoms) for h in hands]
    speed = np.abs(np.diff(robot.qpos[:, JOINTS_QPOS], axis=0)).max(axis=1) * robot.fps
    return {"foot_z": foot_z, "hand_dist": hand_d, "joint_speed": np.r_[speed, speed[-1:]]}


def plot_clip(robot: RobotClip, human: HumanClip, path: Path) -> Path:
    """Write the three-panel PNG for ``robot`` (retargeted from ``human``) to ``path``, atomically."""
    s = clip_series(robot)
    t = np.arange(robot.frames) / robot.fps
    idx = np.clip(np.rint(t * human.fps).astype(int), 0, human.frames - 1)
    fc = detect_foot_contacts(human).both[idx]
    fig, axes = plt.subplots(3, 1, figsize=(10, 8), sharex=True)
    for k, (side, color) in enumerate(zip(SIDES, ("tab:blue", "tab:orange"))):
        axes[0].plot(t, s["foot_z"][:, k], color=color, label=f"{side} sole z")
        _shade(axes[0], t, fc[:, k], color, f"human {side} foot contact")
        axes[1].plot(t, s["hand_dist"][:, k], color=color, label=f"{side} hand to object")
    if human.contacts is not None:
        wrists = [j for j, n in enumerate(human.skeleton.joint_names) if "wrist" in n.lower() or "hand" in n.lower()]
        if wrists:
            _shade(axes[1], t, human.contacts[idx][:, wrists].any(axis=1), "tab:green", "human hand contact")
    axes[0].axhline(0.0, color="k", lw=0.5)
    axes[1].axhline(0.02, color="tab:red", lw=0.8, ls="--", label="2 cm")
    axes[0].set_ylabel("m")
    axes[1].set_ylabel("m")
    axes[2].plot(t, s["joint_speed"], color="tab:purple", label="max joint speed")
    axes[2].set_ylabel("rad/s")
    axes[2].set_xlabel("time (s)")
    for ax in axes:
        ax.legend(loc="upper right", fontsize=7)
    fig.suptitle(
        f"{robot.source} ({robot.task or 'no task'}){' [SYNTHETIC]' if robot.provenance.get('synthetic') else ''}"
    )
    fig.tight_layout()
    return save_figure(fig, path, dpi=90)
