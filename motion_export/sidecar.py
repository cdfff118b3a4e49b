"""The JSON beside each exported motion (``<stem>.json``): what a trainer needs besides the motion to reproduce the
conditions the motion was made and validated under, and to judge it.

* ``source`` -- dataset, stage, episode index, the clip's source, task, method and provenance;
* ``motion`` -- the exported file's frame rate, frames, seconds, quaternion and joint order, where the velocities
  come from (a Unitree CSV holds none), and (Unitree CSV) the resampling and what mjlab's ``csv_to_npz.py`` makes of
  it;
* ``start_prefix`` -- the synthetic start prefix (:mod:`physicalize.start`: a standing settle and a blend into the
  clip's first frame, simulated and validated with the rest), when the episode has one: its length in the source and
  the exported frames ``[0, n)`` it covers (it is included, never cut: the episode's physics starts from rest there);
* ``actuator_profile`` -- the PD gains the dataset's actions are for (``tau = kp (q* - q) - kd qd``, clipped to
  the effort limit), the default pose, and ``action_scale`` by mjlab's rule ``0.25 effort_limit / kp`` (mjlab's
  ``JointPositionAction``: ``q* = default + scale a``; under the ``mjlab`` profile it equals mjlab's
  ``G1_ACTION_SCALE``). The dataset's own actions are absolute joint targets ``q*``, not scaled offsets;
* ``physics`` -- the scene the motion was simulated in (:func:`pipeline.scene.build_scene`, read from its compiled
  model): timestep, substeps per control step, integrator, friction cone, impratio, gravity, the robot's mass, the
  feet-floor friction (feet priority over the floor), and per object its mass, the hand-object friction (the
  object's: its geoms win the mixing by priority), the object-floor friction (explicit pairs) and restitution;
* ``objects`` -- per object its name, the exported keys or body that carry its pose, where that pose sits on the
  object (``pose_origin``: a primitive's centre, a chair's floor point under the seat, a mesh file's origin), and
  its geometry: a primitive's or chair's parameters, or a mesh copied beside the motion (``file``, relative) with
  its ``scale`` (per axis, applied to the mesh's vertices in the object frame);
* ``validation`` -- the physicalize stage's figures for the episode (None for a retargeted, never simulated
  motion): ``valid``, the failure class and reason, tracking errors (mean per-joint position error, the root's
  largest error, the object's), the largest penetration, the foot-slide fraction, and every figure under ``all``.
"""

from __future__ import annotations

import filecmp
import shutil
from functools import lru_cache
from pathlib import Path

import mujoco
import numpy as np

from motion_export.bodies import ENTITY_JOINT_NAMES, entity_joints
from motion_export.episodes import ExportEpisode, ExportSource
from pipeline.errors import InputError
from pipeline.geometry import Chair, MeshGeometry, geometry_to_dict
from pipeline.robot import actuator_profile
from pipeline.scene import build_scene
from pipeline.terms.layout import CONTROL_FPS, SUBSTEPS

TRACKING_ERRORS = ("mpjpe_m", "root_pos_err_max_m", "object_pos_err_m", "object_rot_err_rad")


def profile_entry(name: str) -> dict:
    """The actuator profile ``name`` in the entity's joint order (module doc)."""
    p = actuator_profile(name)

    def row(a) -> list[float]:
        return entity_joints(np.asarray(a)[None])[0].tolist()

    return {
        "name": p.name,
        "description": p.description,
        "joint_names": list(ENTITY_JOINT_NAMES),
        "kp": row(p.kp),
        "kd": row(p.kd),
        "effort_limit": row(p.effort_limit),
        "armature": row(p.armature),
        "default_joint_pos": row(p.default_joint_pos),
        "action_clip": p.action_clip,
        "action_scale": row(0.25 * p.effort_limit / p.kp),
        "action_scale_rule": "0.25 * effort_limit / kp (mjlab's G1_ACTION_SCALE rule; q* = default + scale * a)",
        "dataset_actions": "absolute joint position targets q*, held for one 50 Hz control step",
    }


@lru_cache(maxsize=4)
def _robot_physics(profile: str) -> dict:
    m = build_scene((), profile).model
    feet = [g for g in range(m.ngeom) if m.geom(g).name.startswith(("left_foot", "right_foot"))]
    return {
        "timestep_s": float(m.opt.timestep),
        "substeps": SUBSTEPS,
        "control_hz": CONTROL_FPS,
        "integrator": mujoco.mjtIntegrator(m.opt.integrator).name.removeprefix("mjINT_").lower(),
        "cone": mujoco.mjtCone(m.opt.cone).name.removeprefix("mjCONE_").lower(),
        "impratio": float(m.opt.impratio),
        "gravity": m.opt.gravity.tolist(),
        "robot_mass_kg": float(m.body_mass[1:].sum()),
        "feet_floor_friction": float(m.geom_friction[feet[0], 0]),
        "floor_friction": float(m.geom_friction[m.geom("floor").id, 0]),
    }


def physics_entry(ep: ExportEpisode, profile: str) -> dict:
    """The scene's physics and each object's physical properties (module doc)."""
    objects = []
    for o in ep.clip.objects:
        ph = o.physics()
        objects.append(
            {
                "name": o.name,
                "mass_kg": ph.mass,
                "hand_object_friction": ph.friction,
                "object_floor_friction": ph.floor_friction,
                "restitution": ph.restitution,
                "material": o.material or "default",
            }
        )
    return {**_robot_physics(profile), "objects": objects}


def copy_mesh(geometry: MeshGeometry, folder: Path, stem: str, name: str) -> str:
    """Copy the mesh file beside the motion as ``<name><suffix>`` (where the importer looks for it), or as
    ``<stem>.<name><suffix>`` when another episode's different mesh took that name; returns the file name."""
    src = Path(geometry.path)
    if not src.is_file():
        raise InputError(src, f"object {name} mesh", "the dataset's object mesh file does not exist")
    for candidate in (f"{name}{src.suffix}", f"{stem}.{name}{src.suffix}"):
        dest = folder / candidate
        if not dest.exists():
            shutil.copyfile(src, dest)
            return candidate
        if filecmp.cmp(src, dest, shallow=False):
            return candidate
    raise InputError(src, f"object {name} mesh", f"{folder / candidate} exists with other content")


def pose_origin(geometry) -> str:
    """Where on the object its exported pose (position, orientation) sits: the object frame's origin and axes."""
    if isinstance(geometry, MeshGeometry):
        return "the mesh file's own origin and axes: its vertex coordinates, times scale per axis, are the object frame"
    if isinstance(geometry, Chair):
        return "on the floor under the seat centre; +x forward (away from the back), z up"
    return (
        f"the {geometry.kind}'s centre; its axes the object frame's (MuJoCo's sizes: box half-extents along x, y, z; "
        "cylinder and capsule along z)"
    )


def objects_entry(ep: ExportEpisode, folder: Path, stem: str, carried_by: list[str]) -> list[dict]:
    """Per object its name, where the motion file carries its pose and where that pose sits on it, and its
    geometry (meshes copied beside)."""
    out = []
    for o, where in zip(ep.clip.objects, carried_by):
        geometry = geometry_to_dict(o.geometry)
        if isinstance(o.geometry, MeshGeometry):
            geometry["source_path"] = geometry.pop("path")
            geometry["file"] = copy_mesh(o.geometry, folder, stem, o.name)
        out.append({"name": o.name, "pose_in": where, "pose_origin": pose_origin(o.geometry), "geometry": geometry})
    return out


def start_prefix_entry(ep: ExportEpisode, fps: float, frames: int) -> dict | None:
    """The synthetic start prefix in the source and in the exported file (module doc); None when there is none."""
    n = ep.prefix_frames
    if n <= 0:
        return None
    seconds = n / ep.fps
    rows = int(np.count_nonzero(np.arange(frames) / fps < seconds - 1e-9))
    return {
        "source_frames": n,
        "seconds": seconds,
        "frames": [0, rows],
        "included": True,
        "what": "a synthetic standing settle and a blend into the clip's first frame (physicalize/start.py), "
        "simulated and validated with the rest; the clip's own motion starts at frame frames[1]",
    }


def validation_entry(validation: dict | None) -> dict | None:
    """The episode's validation figures (module doc); None for a motion that was never simulated."""
    if validation is None:
        return None
    v = validation
    return {
        "valid": bool(v.get("valid", False)),
        "failure_class": v.get("failure"),
        "reason": v.get("reason", ""),
        "tracking_error": {k: v.get(k) for k in TRACKING_ERRORS},
        "penetration_max_m": v.get("penetration_max_m"),
        "foot_slide_frac_1cm_per_frame": v.get("foot_slide_frac_1cm_per_frame"),
        "fell": v.get("fell"),
        "all": v,
    }


def sidecar(source: ExportSource, ep: ExportEpisode, fmt: str, motion: dict, objects: list[dict]) -> dict:
    """The sidecar of episode ``ep`` exported as ``fmt``; ``motion``: the writer's facts (frame rate, frames,
    files, layout), ``objects``: :func:`objects_entry`."""
    c = ep.clip
    return {
        "format": fmt,
        "exporter": "lessmimic export-motion (motion_export/)",
        "source": {
            "dataset": source.name,
            "stage": source.stage,
            "root": str(source.root),
            "episode_index": ep.index,
            "clip": c.source,
            "task": c.task,
            "method": c.method,
            "provenance": c.provenance,
        },
        "motion": {"velocities": ep.velocity_source, **motion, "source_fps": ep.fps, "source_frames": ep.frames},
        "start_prefix": start_prefix_entry(ep, motion["fps"], motion["frames"]),
        "actuator_profile": profile_entry(source.profile),
        "physics": physics_entry(ep, source.profile),
        "objects": objects,
        "validation": validation_entry(ep.validation),
    }
