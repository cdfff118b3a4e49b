"""The physicalize stage's teacher as a service: joint targets for ANY state at reference time ``t``.

:class:`Teacher` is the training-free whole-body QP controller (:class:`physicalize.wbc.WholeBodyController`)
tracking an episode's feasible reference (:func:`physicalize.problem.tracking_problem` of the retargeted clip,
with the gain set the physicalize stage kept for that clip), bound to an environment's model: the object may be
scaled there (the reference stays the 1.0x one: the reference-based baseline of the paper's Table 2), and the
state may be anywhere the student went (DAgger labels). :meth:`Teacher.act` reads the state from a live
``MjData`` of that model (after ``mj_forward``, with the actuators' last targets in ``ctrl``);
:meth:`Teacher.act_state` from plain ``(qpos, qvel)`` arrays. The controller keeps its stepping state between
calls, as in a rollout: one teacher per environment episode.
"""

from __future__ import annotations

import mujoco
import numpy as np

from physicalize.problem import tracking_problem
from physicalize.reference import Reference
from physicalize.start import clean_start, prefix_frames
from physicalize.wbc import WholeBodyController
from physicalize.wbc_config import TEACHER_GAINS
from pipeline.robot import actuator_profile
from train.episodes import Episode


def episode_reference(episode: Episode) -> Reference:
    """The feasible reference the physicalize teacher tracked for this episode (its retargeted clip, scale 1, under
    the episode's actuator profile, after the same start prefix where the physicalized episode has one)."""
    clip = clean_start(episode.reference) if prefix_frames(episode.simulated.robot) else episode.reference
    _, ref, _, _ = tracking_problem(clip, episode.profile)
    return ref


class Teacher:
    """Joint targets of the QP teacher for an episode, on ``model`` (module docstring)."""

    def __init__(self, episode: Episode, model: mujoco.MjModel, ref: Reference | None = None):
        self.ref = ref if ref is not None else episode_reference(episode)
        gains = TEACHER_GAINS[int(episode.simulated.robot.provenance.get("teacher_gains", 0))]
        self.model = model
        self.controller = WholeBodyController(model, actuator_profile(episode.profile), gains)
        self._data = mujoco.MjData(model)

    def act(self, data: mujoco.MjData, t: int) -> np.ndarray:
        """(29,) joint targets for the state in ``data`` at reference frame ``t`` (clamped to the clip)."""
        mujoco.mj_forward(self.model, data)
        return self.controller.solve(data, self.ref.target(t)).action

    def act_state(self, qpos: np.ndarray, qvel: np.ndarray, t: int, ctrl: np.ndarray | None = None) -> np.ndarray:
        """(29,) joint targets for the scene state ``(qpos, qvel)`` (robot and objects; ``ctrl``: the actuators' last
        targets, default zero) at reference frame ``t``."""
        d = self._data
        d.qpos[:], d.qvel[:] = qpos, qvel
        d.ctrl[:] = 0.0 if ctrl is None else ctrl
        return self.act(d, t)
