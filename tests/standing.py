"""The G1 standing still in its default pose, feet on the floor: the hand-made reference several tests track."""

from __future__ import annotations

import numpy as np

from physicalize.problem import tracking_problem
from physicalize.reference import place_on_floor
from physicalize.rollout import initial_state
from pipeline.clip import RobotClip
from pipeline.robot import actuator_profile, default_qpos
from pipeline.scene import build_scene


def standing_qpos(frames: int) -> np.ndarray:
    """(frames, nq) the default pose, placed on the floor, held."""
    return place_on_floor(build_scene().model, np.repeat(default_qpos(actuator_profile("mjlab"))[None], frames, 0))


def stand_problem(frames: int = 80):
    """``(scene, ref, (qpos0, qvel0))`` of tracking :func:`standing_qpos` at 50 Hz."""
    scene, ref, objects, _ = tracking_problem(RobotClip(standing_qpos(frames), 50, "hand-made:stand"))
    return scene, ref, initial_state(scene, ref, objects)
