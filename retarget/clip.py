"""Retarget one human clip to the G1: resample it to the control rate (:data:`FPS`), pick its mapping
and map its joints once (:func:`retarget.mapping.map_human`), compute the scale and the IK targets
(:mod:`retarget.scaling`), map the objects into the robot's world (:mod:`retarget.objects`), solve
the IK in a scene built with the same collision model as the physics (:mod:`retarget.ik`), label
per-link contacts from the human's (:mod:`retarget.contact`) and measure it
(:func:`retarget.metrics.retarget_metrics`)."""

from __future__ import annotations

import time
from dataclasses import replace

from pipeline.clip import HumanClip, RobotClip
from pipeline.errors import InputError
from pipeline.scene import SceneObject, build_scene
from pipeline.take import human_hold, object_field
from pipeline.terms.layout import CONTROL_FPS
from retarget.augment import Variant, augment
from retarget.contact import link_contact_flags
from retarget.grip import SQUEEZE, anchored_targets, g1_opposition
from retarget.ik import G1Retargeter
from retarget.mapping import load_mapping, map_human
from retarget.metrics import DEFAULT_LINK_MAP, retarget_metrics
from retarget.objects import map_objects
from retarget.scaling import compute_scale, human_to_targets

FPS = CONTROL_FPS
METHOD = "lessmimic-mink"


def _link_map(clip: HumanClip, mapping) -> dict[str, str]:
    names = set(clip.skeleton.joint_names)
    return {
        **{j: b for j, b in DEFAULT_LINK_MAP.items() if j in names},
        **{link.joint: link.body for link in mapping.links},
    }


def retarget_clip(
    clip: HumanClip,
    *,
    height_override: float | None = None,
    mapping_name: str | None = None,
    variant: Variant | None = None,
) -> tuple[RobotClip, dict, dict]:
    """(robot clip, metrics, scale summary) for one human clip; ``variant``: its object varied
    (:mod:`retarget.augment`), the clip's source then ends in ``@<variant label>``."""
    if clip.frames < 2:
        raise InputError(clip.source, "frames", f"a clip needs at least 2 frames, got {clip.frames}")
    t0 = time.perf_counter()
    human = clip.resampled(FPS)
    mapping = load_mapping(human.skeleton, mapping_name, source=human.source)
    mapped = map_human(human, mapping)  # the clip's human points, once
    info = compute_scale(mapped, height_override=height_override)
    targets = human_to_targets(mapped, height_override=height_override, scale=info)
    objects = map_objects(mapped, info, targets)
    link_map = _link_map(human, mapping)
    links, contacts = link_contact_flags(human, link_map)
    targets = replace(targets, contact_links=links, object_contact=contacts if objects else None)
    vmap, augmented = None, None
    if variant is not None and not variant.identity:
        targets, objects, vmap, augmented = augment(targets, objects, variant, human.source)
    scene = build_scene([SceneObject(o.name, o.geometry, o.physics(), pose=tuple(o.pose[0])) for o in objects])
    ik = G1Retargeter(scene)
    qpos = ik.retarget(targets, {o.name: o.pose for o in objects}, source=human.source)
    field = object_field(human) if objects else None  # the object's distance field, for the hands' faces
    hold = None if field is None else human_hold(human, field=field)
    squeeze = hold[0] if hold is not None and hold[1] <= SQUEEZE else None
    robot_field = field if vmap is None else vmap.variant_field
    opposition = None if squeeze is None else g1_opposition(robot_field, qpos, objects, squeeze, human.source)
    if opposition is not None and opposition > SQUEEZE:  # the human squeezes it, the scaled G1 does not
        targets = anchored_targets(human, targets, objects, squeeze, carry=None if vmap is None else vmap.carry)
        ik = G1Retargeter(scene)
        qpos = ik.retarget(targets, {o.name: o.pose for o in objects}, source=human.source)
    objects = tuple(replace(o, pose=ik.objects_pose[o.name]) for o in objects)  # moved clear of planted feet
    robot = RobotClip(
        qpos,
        FPS,
        human.source if augmented is None else f"{human.source}@{variant.label}",
        objects=objects,
        contact_links=links,
        contacts=contacts,
        method=METHOD,
        task=human.task,
        provenance={
            "source": human.source,
            "synthetic": human.synthetic,
            "mapping": mapping.name,
            "source_fps": clip.fps,
            # the human's grasp (pipeline.take): -1 a squeeze between opposite faces; physicalize's feasibility reads it
            "human_hand_opposition": None if hold is None else hold[1],
            # the G1's before its wrists were anchored on the human's faces (retarget.grip), None: not anchored
            "g1_hand_opposition_scaled": opposition if opposition is not None and opposition > SQUEEZE else None,
            # the object's variant (retarget.augment): scale, shape, mass rule; the demonstration itself: x1
            **({} if variant is None else {"augment": augmented or variant.to_dict()}),
        },
    )
    seconds = time.perf_counter() - t0
    return robot, retarget_metrics(robot, human, link_map=link_map, seconds_wall=seconds), info.summary()
