"""Bring your own G1 motion: other retargeters' G1 clips (BeyondMimic/mjlab ``.npz``, GMR ``.pkl``, HDMI
``motion.npz`` + ``meta.json`` folders; :mod:`pipeline.readers.peers`) become ``datasets/<NAME>/retargeted/``,
so the physicalize and features stages run on them as on our own retargeting.

``lessmimic import --input FILE_OR_FOLDER --name NAME [--object-mesh MESH] [--joint-names ORDER]``. Each motion is
resampled to the control rate (:data:`retarget.clip.FPS`) and labelled, per G1 link, with its contacts with the
objects (a link's collision geoms within :data:`CONTACT_GAP_M` of an object's, in the same collision model the
physics uses), because a peer's file carries no contact labels and the physicalize teacher's grasps come from them.
Joints a file lacks that carry no weight (HDMI's wrists) are held at the default pose and named in the card; a file
without a leg, waist or arm joint, or whose object has no geometry, is a one-line error. Motion files carry no
object masses: ``--object-mass`` sets them (default: :class:`pipeline.geometry.ObjectPhysics`'s 2 kg). A
BeyondMimic/mjlab ``.npz`` that names none of its joints is read in the order its bodies' kinematics match; where
they cannot tell, ``--joint-names`` gives it (:func:`pipeline.readers.npz_order.joint_names_option`). The stage
follows the recipe of :mod:`pipeline.stage.run` (up to date, resumable).
"""

from __future__ import annotations

import time
from collections.abc import Sequence
from dataclasses import replace

import mujoco
import numpy as np

from pipeline.clip import RobotClip
from pipeline.collision_mesh import check_meshes
from pipeline.dataset.card import DatasetCard
from pipeline.dataset.clips import robot_clips_to_episodes
from pipeline.dataset.objects import objects_note
from pipeline.dataset.write import write_dataset
from pipeline.errors import InputError
from pipeline.geometry import MeshGeometry
from pipeline.readers import read_robot_clips
from pipeline.robot import NQ_ROBOT
from pipeline.scene import SceneObject, build_scene, link_collision_geoms, object_collision_geoms
from pipeline.stage.executor import check_executor
from pipeline.stage.inspect_log import write_robot_log
from pipeline.stage.paths import file_stem, stage_dir
from pipeline.stage.run import StageRun, digest
from pipeline.stage.state import files_fingerprint, fingerprint
from retarget.clip import FPS
from retarget.stage import feature_frames

CONTACT_GAP_M = 0.02  # a link this close to an object touches it (the human labels' 2 cm)
#: The links labelled with contacts: those our own retargeting labels from SMPL skeletons (a test checks it).
CONTACT_LINKS: tuple[str, ...] = (
    "pelvis", "torso_link", "left_hip_pitch_link", "left_knee_link", "left_ankle_roll_link", "left_shoulder_roll_link",
    "left_elbow_link", "left_wrist_yaw_link", "right_hip_pitch_link", "right_knee_link", "right_ankle_roll_link",
    "right_shoulder_roll_link", "right_elbow_link", "right_wrist_yaw_link",
)  # fmt: skip
METHOD = "imported"


def contact_labels(clip: RobotClip, links: tuple[str, ...] = CONTACT_LINKS) -> np.ndarray:
    """(T, len(links)) bool: each link's collision geoms within :data:`CONTACT_GAP_M` of an object's, per frame."""
    scene = build_scene([SceneObject(o.name, o.geometry, o.physics(), pose=tuple(o.pose[0])) for o in clip.objects])
    m, d = scene.model, mujoco.MjData(scene.model)
    objects = object_collision_geoms(m, scene)
    link_geoms = [link_collision_geoms(m, name) for name in links]
    out = np.zeros((clip.frames, len(links)), bool)
    fromto = np.zeros(6)
    for t in range(clip.frames):
        d.qpos[:NQ_ROBOT] = clip.qpos[t]
        for o in clip.objects:
            if o.name in scene.object_qpos_adr:
                adr = scene.object_qpos_adr[o.name]
                d.qpos[adr : adr + 7] = o.pose[t]
        mujoco.mj_kinematics(m, d)
        for k, geoms in enumerate(link_geoms):
            out[t, k] = any(
                mujoco.mj_geomDistance(m, d, g, og, CONTACT_GAP_M, fromto) < CONTACT_GAP_M
                for g in geoms
                for og in objects
            )
    return out


def import_one(item: tuple[int, RobotClip]) -> RobotClip:
    """The motion at the control rate, labelled with its link-object contacts."""
    _, clip = item
    clip = clip.resampled(FPS) if abs(clip.fps - FPS) > 1e-9 else clip
    if not clip.objects:
        return replace(clip, method=f"{clip.method} (imported)")
    contacts = contact_labels(clip)
    objects = tuple(replace(o, contact=contacts.any(axis=1)) for o in clip.objects)
    return replace(
        clip, objects=objects, contact_links=CONTACT_LINKS, contacts=contacts, method=f"{clip.method} (imported)"
    )


def run_stage(
    input_path: str,
    name: str,
    *,
    overwrite: bool = False,
    jobs: int = 1,
    executor: str = "local",
    object_mesh: str | None = None,
    object_mass: float | None = None,
    joint_names: Sequence[str] | None = None,
) -> dict:
    """``lessmimic import``: read every G1 motion of ``input_path``, label contacts, write the retargeted dataset.
    ``joint_names``: the column order of the ``.npz`` motions that name none of their joints (``--joint-names``)."""
    check_executor(executor, jobs)
    geometry = MeshGeometry(object_mesh) if object_mesh else None
    if object_mass is not None and not object_mass > 0:
        raise InputError(object_mass, "--object-mass", "must be a positive mass in kg")
    fp = fingerprint(
        stage="retargeted",
        method=METHOD,
        input=files_fingerprint([input_path]),
        object_mesh=files_fingerprint([object_mesh]) if object_mesh else None,
        object_mass=object_mass,
        **({"joint_names": list(joint_names)} if joint_names is not None else {}),  # none: the fingerprints before it
    )
    run = StageRun(stage_dir(name, "retargeted"), fp)
    if not overwrite and (done := run.finished()) is not None:
        return {**done, "up_to_date": True}
    clips = read_robot_clips(input_path, object_geometry=geometry, joint_names=joint_names)  # fails before the claim
    if joint_names is not None and not any(c.provenance.get("format") == "beyondmimic_npz" for c in clips):
        why = "applies to BeyondMimic/mjlab .npz motions that name none of their joints; this input has none"
        raise InputError(input_path, "--joint-names", why)
    check_meshes(clips)
    if object_mass is not None:  # motion files carry no masses (default: pipeline.geometry.ObjectPhysics)
        clips = [replace(c, objects=tuple(replace(o, mass=object_mass) for o in c.objects)) for c in clips]
    run.begin(overwrite)
    t0 = time.perf_counter()
    robots = run.map(
        import_one,
        list(enumerate(clips)),
        key=lambda k, item: digest(k, item[1].source, item[1].qpos),
        jobs=jobs,
        executor=executor,
        desc="import",
    )
    held = sorted({j for r in robots for j in r.provenance.get("held_joints", [])})
    features, episodes = robot_clips_to_episodes(robots)
    card = DatasetCard(
        title=f"{name}: G1 motion (imported)",
        description="G1 motion retargeted by other tools ("
        + ", ".join(sorted({r.provenance.get("format", "?") for r in robots}))
        + "), imported as this toolkit's retargeted stage (kinematic: not yet physically simulated).",
        provenance=[r.source for r in robots],
        fps=FPS,
        synthetic=False,
        stage="retargeted",
        license="other",
        feature_frames=feature_frames(features),
        notes=[
            "Contacts are labelled from the motion itself: a link within 2 cm of an object touches it.",
            objects_note(robots),
        ]
        + ([f"Joints the source files lack, held at the default pose: {', '.join(held)}."] if held else []),
    )
    write_dataset(run.out, f"lessmimic/{name}-retargeted", FPS, features, episodes, card=card, overwrite=run.replaces)
    for k, r in enumerate(robots):
        write_robot_log(r, run.logs / f"{k:03d}_{file_stem(r.source)}.mcap")
    report = {
        "stage": "retargeted",
        "method": METHOD,
        "fps": FPS,
        "input": input_path,
        "clips": [
            {
                "source": r.source,
                "task": r.task,
                "frames": r.frames,
                "held_joints": r.provenance.get("held_joints", []),
                "objects": [o.name for o in r.objects],
            }
            for r in robots
        ],
        "failed": [],
        "summary": {"clips": len(robots), "frames": sum(r.frames for r in robots)},
        "seconds_wall": time.perf_counter() - t0,
    }
    return run.finish(report, dataset_written=True)
