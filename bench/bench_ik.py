"""Speed probe of the retarget IK (:mod:`retarget.ik`): frames/s on one core, and where the time goes.

    python bench/bench_ik.py [--frames 300] [--iterations 2] [--tolerance 0.02] [--repeat 5]
                             [--mesh ../shared/mocap/omomo/largebox.obj [--collision hull]] [--profile]

Targets are the G1's own forward kinematics (14 frame tasks), so the IK has an exact answer:
:func:`demo_qpos` (squat, arm reach, waist twist, 90-degree turn and 0.4 m of travel) with no
object, standing still with both feet pinned, 3x faster, and with a box the right hand's targets
reach 5 cm into (robot-box collision avoidance active); :func:`march_qpos` (marching in place,
foot contacts switching every step). Reported: frames/s, QP solves
per frame, body position error, and with ``--profile`` the split of the time between the QP
solver, the task Jacobians/errors, collision distances, forward kinematics and the rest.
"""

from __future__ import annotations

import argparse
import cProfile
import math
import os
import pstats
import sys
from pathlib import Path

os.environ.setdefault("OMP_NUM_THREADS", "1")
os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")
sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

import mujoco  # noqa: E402
import numpy as np  # noqa: E402

from pipeline.robot import G1_JOINT_NAMES, G1_LINK_NAMES, actuator_profile, default_qpos  # noqa: E402
from pipeline.scene import Scene, SceneObject, build_scene  # noqa: E402
from retarget.ik import G1Retargeter  # noqa: E402
from retarget.ik_config import IKConfig  # noqa: E402
from retarget.targets import targets_from_qpos  # noqa: E402


def _smooth(s: np.ndarray) -> np.ndarray:
    """Smoothstep 3s^2 - 2s^3 on [0, 1] (zero slope at both ends)."""
    s = np.clip(s, 0.0, 1.0)
    return s * s * (3.0 - 2.0 * s)


def _sole_height(model: mujoco.MjModel, data: mujoco.MjData, geoms: list[int]) -> float:
    """Lowest world z of the capsule ``geoms`` at the current kinematics."""
    low = np.inf
    for g in geoms:
        axis_z = abs(data.geom_xmat[g, 8])
        low = min(low, data.geom_xpos[g, 2] - axis_z * model.geom_size[g, 1] - model.geom_size[g, 0])
    return float(low)


def demo_qpos(
    model: mujoco.MjModel,
    frames: int = 300,
    yaw0: float = 0.0,
    turn: float = math.pi / 2,
    travel: float = 0.4,
    squat: float = 0.5,
    reach: float = 1.0,
) -> np.ndarray:
    """``(frames, 36)`` G1 motion: squat ``squat`` rad deep twice, right arm reaching forward by
    ``reach``, left arm out, waist twist, heading ``yaw0 -> yaw0 + turn`` and ``travel`` metres
    forward (the feet's midpoint moves along the path, so with no turn and no travel the feet
    stand still); the root height keeps the lowest foot capsule point on z = 0 and the soles stay
    level (ankle pitch = -(hip pitch + knee))"""
    s = np.linspace(0.0, 1.0, frames)
    q = np.tile(_default_qpos(), (frames, 1))
    j = {n: 7 + i for i, n in enumerate(G1_JOINT_NAMES)}
    a = squat * np.sin(2 * math.pi * s) ** 2
    for side in ("left", "right"):
        q[:, j[f"{side}_hip_pitch_joint"]] -= a
        q[:, j[f"{side}_knee_joint"]] += 2 * a
        q[:, j[f"{side}_ankle_pitch_joint"]] = -(
            q[:, j[f"{side}_hip_pitch_joint"]] + q[:, j[f"{side}_knee_joint"]]
        )  # sole level
    r = reach * _smooth(2 * s) * _smooth(2 - 2 * s)  # up and back down
    q[:, j["right_shoulder_pitch_joint"]] -= 1.4 * r
    q[:, j["right_elbow_joint"]] -= 0.5 * r
    q[:, j["left_shoulder_roll_joint"]] += 0.8 * r
    q[:, j["left_elbow_joint"]] += 0.4 * r
    q[:, j["waist_yaw_joint"]] = 0.3 * np.sin(2 * math.pi * s)
    lo, hi = model.jnt_range[1:30].T  # joints 1..29 of g1.xml are G1_JOINT_NAMES (joint 0: the root)
    if (q[:, 7:] < lo).any() or (q[:, 7:] > hi).any():
        raise ValueError(
            f"demo_qpos: squat {squat} / reach {reach} leave the joint range (ankle pitch limit: squat <= ~0.5)"
        )
    yaw = yaw0 + turn * _smooth(s)
    q[:, 3], q[:, 6] = np.cos(yaw / 2), np.sin(yaw / 2)
    path = travel * _smooth(s)[:, None] * np.array([math.cos(yaw0), math.sin(yaw0)])
    data = mujoco.MjData(model)
    feet = [g for g in range(model.ngeom) if "foot" in model.geom(g).name and model.geom_contype[g]]
    ankles = [model.body(f"{side}_ankle_roll_link").id for side in ("left", "right")]
    for t in range(frames):
        q[t, :3] = 0.0
        data.qpos[:36] = q[t]
        mujoco.mj_kinematics(model, data)
        q[t, :2] = path[t] - data.xpos[ankles, :2].mean(axis=0)  # the feet's midpoint follows the path
        q[t, 2] = -_sole_height(model, data, feet)
    return q


def march_qpos(
    model: mujoco.MjModel, frames: int = 300, steps: int = 6, lift: float = 0.5
) -> tuple[np.ndarray, np.ndarray]:
    """Marching in place: ``(frames, 36)`` qpos and ``(frames, 2)`` foot contacts (left, right).

    Step ``k`` of ``steps`` lifts the left leg (even ``k``) or the right one by ``b = lift sin^2``
    (hip pitch ``-b``, knee ``+2b``, ankle pitch ``-b``: the sole stays level) while the arms swing;
    the other foot stands still on z = 0. A foot is in contact while its sole is below 5 mm.
    """
    s = np.linspace(0.0, 1.0, frames)
    u = steps * s
    k, frac = np.minimum(np.floor(u), steps - 1), u - np.minimum(np.floor(u), steps - 1)
    bump = lift * np.sin(math.pi * frac) ** 2
    q = np.tile(_default_qpos(), (frames, 1))
    j = {n: 7 + i for i, n in enumerate(G1_JOINT_NAMES)}
    for side, parity in (("left", 0), ("right", 1)):
        b = np.where(k % 2 == parity, bump, 0.0)
        q[:, j[f"{side}_hip_pitch_joint"]] -= b
        q[:, j[f"{side}_knee_joint"]] += 2 * b
        q[:, j[f"{side}_ankle_pitch_joint"]] = -(q[:, j[f"{side}_hip_pitch_joint"]] + q[:, j[f"{side}_knee_joint"]])
        q[:, j[f"{side}_shoulder_pitch_joint"]] += 0.8 * np.where(k % 2 == parity, bump, -bump)  # arms swing
    data = mujoco.MjData(model)
    caps = [
        [g for g in range(model.ngeom) if model.geom(g).name.startswith(f"{side}_foot") and model.geom_contype[g]]
        for side in ("left", "right")
    ]
    contact = np.zeros((frames, 2), bool)
    for t in range(frames):
        q[t, 2] = 0.0
        data.qpos[:36] = q[t]
        mujoco.mj_kinematics(model, data)
        soles = [_sole_height(model, data, c) for c in caps]
        q[t, 2] = -min(soles)
        contact[t] = np.array(soles) - min(soles) < 0.005
    return q, contact


def _default_qpos() -> np.ndarray:
    """The mjlab profile's standing pose (knees bent), the IK's posture target too."""
    return default_qpos(actuator_profile("mjlab"))


def box_for_reach(model: mujoco.MjModel, qpos: np.ndarray, depth: float = 0.05, half: float = 0.1) -> tuple[float, ...]:
    """Pose of a ``half``-size box whose near face is ``depth`` behind the right hand capsule's farthest forward
    point."""
    data = mujoco.MjData(model)
    g = model.geom("right_hand_collision").id
    best, pose = -np.inf, None
    for t in range(len(qpos)):
        data.qpos[:36] = qpos[t]
        mujoco.mj_kinematics(model, data)
        yaw = 2 * math.atan2(qpos[t, 6], qpos[t, 3])
        fwd = np.array([math.cos(yaw), math.sin(yaw), 0.0])
        reach = (data.geom_xpos[g] - qpos[t, :3]) @ fwd + model.geom_size[g, 1] + model.geom_size[g, 0]
        if reach > best:
            best, centre = (
                reach,
                data.geom_xpos[g] + fwd * (model.geom_size[g, 1] + model.geom_size[g, 0] - depth + half),
            )
            pose = (*centre, math.cos(yaw / 2), 0.0, 0.0, math.sin(yaw / 2))
    return pose


def box_scene(model: mujoco.MjModel, qpos: np.ndarray, depth: float = 0.05) -> tuple[Scene, np.ndarray]:
    """Scene with a free 0.2 m box placed by :func:`box_for_reach`, and its ``(T, 7)`` (static) track."""
    from pipeline.geometry import Primitive

    pose = box_for_reach(model, qpos, depth)
    scene = build_scene([SceneObject("box", Primitive("box", (0.1, 0.1, 0.1)), pose=pose)])
    return scene, np.tile(np.array(pose), (len(qpos), 1))


def _run(
    name: str, scene: Scene, targets, objects_pose, config: IKConfig, qpos_true: np.ndarray, profile: bool, repeat: int
) -> None:
    ik = G1Retargeter(scene, config)
    ik.retarget(targets, objects_pose)  # warm-up (imports, first-call costs)
    rates = []
    for _ in range(repeat):
        q = ik.retarget(targets, objects_pose)
        rates.append(ik.stats["frames_per_s"])
    st = ik.stats
    err = _position_error(ik.model, q, qpos_true, targets.body_names)
    print(
        f"{name:28s} {np.median(rates):6.0f} (best {max(rates):5.0f}) frames/s  {st['qp_solves'] / st['frames']:.2f} "
        f"QP/frame  body pos err mean {1000 * err.mean():.1f} mm, max {1000 * err.max():.1f} mm"
    )
    if profile:
        prof = cProfile.Profile()
        prof.enable()
        ik.retarget(targets, objects_pose)
        prof.disable()
        _split(prof)


def _position_error(model, q, q_true, bodies) -> np.ndarray:
    d = mujoco.MjData(model)
    ids = [model.body(b).id for b in bodies]
    out = []
    for a, b in zip(q, q_true):
        d.qpos[:] = a
        mujoco.mj_kinematics(model, d)
        pa = d.xpos[ids].copy()
        d.qpos[:] = b
        mujoco.mj_kinematics(model, d)
        out.append(np.linalg.norm(pa - d.xpos[ids], axis=1))
    return np.array(out)


_GROUPS = {
    "QP solve (qpsolvers + daqp)": ("qpsolvers",),
    "task errors + Jacobians": (
        "frame_task.py",
        "posture_task.py",
        "tasks/task.py",
        "get_frame_jacobian",
        "_get_transform",
        "_lie_ops",
    ),
    "collision distances + rows": (
        "ik_config.py:compute_qp_inequalities",
        "collision_avoidance_limit.py",
        "mj_geomDistance",
        "mj_jac",
    ),
    "forward kinematics": ("mj_kinematics", "mj_comPos", "mj_integratePos"),
}


def _split(prof: cProfile.Profile) -> None:
    """Print self time per group (by file and function name); the rest is QP assembly and glue."""
    st = pstats.Stats(prof)
    sums = dict.fromkeys(_GROUPS, 0.0)
    for (file, _line, func), (_cc, _nc, tt, _ct, _callers) in st.stats.items():
        key = f"{file}:{func}"
        group = next((g for g, pats in _GROUPS.items() if any(p in key for p in pats)), None)
        if group:
            sums[group] += tt
    prof_total = sum(v[2] for v in st.stats.values())
    for g, v in sums.items():
        print(f"    {g:32s} {100 * v / prof_total:5.1f} %")
    print(
        f"    {'QP assembly, limits, glue':32s} {100 * (1 - sum(sums.values()) / prof_total):5.1f} %   (of "
        f"{prof_total:.2f} s under the profiler)"
    )


def trimesh_bounds(path: str) -> np.ndarray:
    from pipeline.collision_mesh import load_mesh

    return load_mesh(path).bounds


def main(argv: list[str] | None = None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--frames", type=int, default=300)
    ap.add_argument("--iterations", type=int, default=IKConfig.iterations)
    ap.add_argument("--tolerance", type=float, default=IKConfig.tolerance, help="0: always take --iterations steps")
    ap.add_argument("--repeat", type=int, default=5, help="timed runs per case (median and best reported)")
    ap.add_argument("--mesh", help="also: this mesh object (e.g. OMOMO's largebox.obj) in the right hand's way")
    ap.add_argument(
        "--collision", default="hull", choices=("hull", "decomposition"), help="how the physics sees --mesh"
    )
    ap.add_argument("--profile", action="store_true")
    args = ap.parse_args(argv)
    config = IKConfig(iterations=args.iterations, tolerance=args.tolerance)
    plain = build_scene()
    q = demo_qpos(plain.model, args.frames)
    targets = targets_from_qpos(plain.model, q, G1_LINK_NAMES, fps=30.0)
    print(
        f"G1 IK, {args.frames} frames at 30 fps, {len(G1_LINK_NAMES)} frame tasks, up to {args.iterations} QP "
        f"steps/frame (tolerance {args.tolerance}), 1 thread"
    )
    _run("no object", plain, targets, None, config, q, args.profile, args.repeat)
    q_still = demo_qpos(plain.model, args.frames, turn=0.0, travel=0.0)
    t_still = targets_from_qpos(
        plain.model, q_still, G1_LINK_NAMES, fps=30.0, foot_contact=np.ones((args.frames, 2), bool)
    )
    _run("no object, feet pinned", plain, t_still, None, config, q_still, args.profile, args.repeat)
    q_march, contact = march_qpos(plain.model, args.frames)
    t_march = targets_from_qpos(plain.model, q_march, G1_LINK_NAMES, fps=30.0, foot_contact=contact)
    _run("marching, contacts switch", plain, t_march, None, config, q_march, args.profile, args.repeat)
    q_fast = demo_qpos(plain.model, max(2, args.frames // 3))
    t_fast = targets_from_qpos(plain.model, q_fast, G1_LINK_NAMES, fps=30.0)
    _run("no object, 3x faster", plain, t_fast, None, config, q_fast, args.profile, args.repeat)
    scene, box = box_scene(plain.model, q)
    _run("box + collision avoidance", scene, targets, {"box": box}, config, q, args.profile, args.repeat)
    if args.mesh:
        from pipeline.geometry import MeshGeometry

        geo = MeshGeometry(args.mesh, collision=args.collision)
        half = float(np.max(np.abs(trimesh_bounds(args.mesh))))
        pose = box_for_reach(plain.model, q, depth=0.05, half=half)
        scene = build_scene([SceneObject("mesh", geo, pose=pose)])
        n = sum(
            scene.model.geom_bodyid[g] == scene.model.body("mesh").id and scene.model.geom_contype[g] > 0
            for g in range(scene.model.ngeom)
        )
        _run(
            f"mesh ({args.collision}, {n} pieces)",
            scene,
            targets,
            {"mesh": np.tile(np.array(pose), (len(q), 1))},
            config,
            q,
            args.profile,
            args.repeat,
        )


if __name__ == "__main__":
    main()
