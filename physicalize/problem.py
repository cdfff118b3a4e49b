"""The tracking problem of one retargeted clip: its scene (the robot and the clip's objects as free bodies
moved only by contact) and the reference the teacher tracks (:mod:`physicalize.reference`, planned by
:mod:`physicalize.plan`, re-solved by :mod:`physicalize.feasible`, with the grasps of :mod:`physicalize.grasp`).
Shared by the physicalize stage (:mod:`physicalize.clip`) and the residual's training (:mod:`physicalize.residual`)."""

from __future__ import annotations

from functools import partial

import numpy as np

from physicalize.feasible import feasible_reference
from physicalize.grasp import grasp_schedule
from physicalize.plan import HandLoads, plan_com
from physicalize.reference import Reference, build_reference
from physicalize.seat import seat_support
from pipeline.clip import RobotClip
from pipeline.robot import FREE_NQ, NQ_ROBOT
from pipeline.scene import Scene, SceneObject, build_scene


def scene_for(clip: RobotClip, profile: str) -> Scene:
    """The clip's scene: the G1 with the ``profile``'s actuators and the clip's objects at their first poses."""
    return build_scene(
        [SceneObject(o.name, o.geometry, o.physics(), pose=tuple(o.pose[0])) for o in clip.objects], profile
    )


REFERENCES = ("raw", "planned", "feasible")


def object_qpos(scene: Scene, clip: RobotClip, frames: int) -> np.ndarray:
    """(frames, nq - 36): the scene's free objects' qpos along the clip's object tracks (fixed ones: the model's)."""
    obj_q = np.repeat(scene.model.qpos0[None, NQ_ROBOT:], frames, 0)
    for o in (o for o in clip.objects if o.name in scene.object_qpos_adr):
        adr = scene.object_qpos_adr[o.name] - NQ_ROBOT
        obj_q[:, adr : adr + FREE_NQ] = o.pose[:frames]
    return obj_q


def tracking_problem(
    clip: RobotClip, profile: str = "mjlab", reference: str = "feasible", grasp: bool = True
) -> tuple[Scene, Reference, dict[str, np.ndarray], np.ndarray | None]:
    """``(scene, tracked Reference, object tracks {name: (T, 7)}, planned ZMP or None)`` of one clip,
    tracking the ``reference``: ``raw`` (the retargeted motion and its kinematic CoM), ``planned`` (its
    posture with the ZMP-planned CoM) or ``feasible`` (the whole body re-solved by IK onto the plan);
    with ``grasp``, hands that hold an object squeeze it and carry its weight (:mod:`physicalize.grasp`).
    """
    if reference not in REFERENCES:
        raise ValueError(f"unknown reference {reference!r}; known: {', '.join(REFERENCES)}")
    scene = scene_for(clip, profile)
    ref = build_reference(scene.model, clip.qpos, clip.fps)
    zmp = None
    m = scene.model
    obj_q = object_qpos(scene, clip, ref.frames)
    ref.seat = seat_support(m, ref, clip.contact_links, clip.contacts, obj_q)  # the plan's support includes the seat
    if reference == "planned":
        ref.com_plan, _, zmp = plan_com(ref)
    elif reference == "feasible":
        stats: dict = {}
        hands = pre = None
        # hands held on an object move with its reference track (the retargeted hands drift off it): the IK re-solves
        # the arms onto that
        if grasp:
            pre = grasp_schedule(scene, ref, clip.contact_links, clip.contacts, {o.name: o.pose for o in clip.objects})
            hands = None if pre is None else pre.hand_body_targets()
        plan_fn = (
            plan_com
            if pre is None
            else partial(
                plan_com, loads=HandLoads(pre.attached, pre.force, float(m.body_subtreemass[m.body("pelvis").id]))
            )
        )
        seat = ref.seat
        ref = feasible_reference(
            m, ref, plan_fn, stats=stats, objects=obj_q if clip.objects else None, hand_targets=hands
        )
        ref.seat = seat
        zmp = stats["plan"][2]
    objects = {o.name: o.pose for o in clip.objects}
    if grasp:
        ref.grasp = grasp_schedule(scene, ref, clip.contact_links, clip.contacts, objects)
    return scene, ref, objects, zmp
