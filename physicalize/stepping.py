"""Support from the simulation and capture-point stepping for the whole-body controller
(:class:`physicalize.wbc.WholeBodyController`): which feet support this control step and where the
swing foot lands, given the scheduled target and the measured state.

With the divergent component of motion ``xi = c + c_dot / omega``, ``omega = sqrt(g / z_c)``, a
swing foot's landing point moves by ``xi - xi_ref`` so it lands where the DCM can be caught; the CoM
target follows the footholds taken by :data:`COM_ANCHOR` times their landing shift.
"""

from __future__ import annotations

from dataclasses import replace

import mujoco
import numpy as np

from physicalize.target import Target
from physicalize.wbc_config import WBCConfig
from pipeline.contacts import ContactSets, robot_contacts

# the CoM target moves by this fraction of the stance feet's landing shift (without it the plan kept pulling the CoM
# toward the reference footsteps, the next landing was shifted further, and a 20 N side push diverged)
COM_ANCHOR = 0.5


def foot_floor_forces(robot: ContactSets, d: mujoco.MjData) -> np.ndarray:
    """(2,) normal force of the floor on each of the ``robot.feet`` bodies, measured in the simulation [N]
    (the floor is a plane: its contact normals are vertical)."""
    m, out = robot.model, np.zeros(2)
    for c in robot_contacts(m, d, robot.robot_geoms):
        if c.other != robot.floor:
            continue
        b = m.geom_bodyid[c.geom]
        if b in robot.feet:
            out[robot.feet.index(b)] += c.wrench()[0]
    return out


def dcm_error(c: np.ndarray, c_dot: np.ndarray, target: Target) -> np.ndarray:
    """Horizontal divergent-component-of-motion error ``xi - xi_ref`` of the CoM ``c`` moving at ``c_dot``,
    with ``xi = c + c_dot / omega``, ``omega = sqrt(g / z_c)`` (``z_c``: the target CoM height)."""
    omega = np.sqrt(9.81 / max(float(target.com[2]), 0.3))
    return (c[:2] + c_dot[:2] / omega) - (target.com[:2] + target.com_vel[:2] / omega)


class Stepping:
    """The stepping state of one rollout: the capture-point shift each foot last landed with."""

    def __init__(self, dt: float):
        self.dt = dt
        self.landing_shift = np.zeros((2, 2))

    def adapt(
        self,
        robot: ContactSets,
        cfg: WBCConfig,
        d: mujoco.MjData,
        target: Target,
        c: np.ndarray,
        c_dot: np.ndarray,
    ) -> Target:
        """The target with its support taken from the simulation and the swing foot's landing point
        moved by the capture-point error of the robot's CoM ``c`` moving at ``c_dot``:

        * a scheduled stance foot that does not press the floor (< ``touch_force``) while the other
          foot supports becomes a swing foot driven down onto its footstep (late touchdown);
        * a scheduled swing foot pressing the floor whose reference sole is low (< ``touchdown_height``)
          and not rising becomes a stance foot (early touchdown);
        * a swing foot's target moves horizontally by ``xi - xi_ref`` (at most ``step_max``, never
          closer than ``min_foot_gap`` sideways to the stance foot): where the robot's DCM runs ahead of
          or beside the plan, the foot lands where the DCM can be caught;
        * while a foot supports, the CoM target moves by :data:`COM_ANCHOR` times the shift that foot
          landed with (the plan follows the footholds taken)."""
        on = foot_floor_forces(robot, d) > cfg.touch_force
        stance, pos, vel, acc = self._touchdowns(robot, cfg, d, target, on)
        if any(stance):  # the plan follows the footholds actually taken
            held = [k for k in range(2) if stance[k]]
            off = np.mean([self.landing_shift[k] for k in held], axis=0)
            com = target.com.copy()
            com[:2] += COM_ANCHOR * off
            target = replace(target, com=com)
        if stance.count(True) == 1:
            s, k = stance.index(True), stance.index(False)
            pos[k, :2] = self._landing(robot, cfg, d, s, k, pos[k, :2] + self._capture_shift(cfg, c, c_dot, target))
        for k in range(2):  # the step adjustment each foot landed with (kept while it supports)
            if not stance[k]:
                self.landing_shift[k] = pos[k, :2] - target.foot_pos[k, :2]
        return replace(target, stance=(stance[0], stance[1]), foot_pos=pos, foot_vel=vel, foot_acc=acc)

    def _touchdowns(
        self, robot: ContactSets, cfg: WBCConfig, d: mujoco.MjData, target: Target, on: np.ndarray
    ) -> tuple[list[bool], np.ndarray, np.ndarray, np.ndarray]:
        """``(stance, foot_pos, foot_vel, foot_acc)``: the schedule with early and late touchdowns applied
        (``on``: each foot presses the floor)."""
        stance = list(target.stance)
        pos, vel, acc = target.foot_pos.copy(), target.foot_vel.copy(), target.foot_acc.copy()
        sole = target.sole_height if target.sole_height is not None else np.full(2, np.inf)
        for k in range(2):
            if not stance[k] and on[k] and sole[k] < cfg.touchdown_height and target.foot_vel[k, 2] <= 0.0:
                stance[k] = True
        for k in range(2):
            if stance[k] and not on[k] and stance[1 - k] and on[1 - k]:
                stance[k] = False
                vel[k, 2], acc[k] = -cfg.descend_speed, 0.0
                pos[k, 2] = min(pos[k, 2], d.xpos[robot.feet[k]][2]) - cfg.descend_speed * self.dt
        return stance, pos, vel, acc

    @staticmethod
    def _capture_shift(cfg: WBCConfig, c: np.ndarray, c_dot: np.ndarray, target: Target) -> np.ndarray:
        """The landing point's shift: the DCM error, at most ``step_max`` long."""
        shift = dcm_error(c, c_dot, target)
        n = np.linalg.norm(shift)
        if n > cfg.step_max:
            shift *= cfg.step_max / n
        return shift

    @staticmethod
    def _landing(robot: ContactSets, cfg: WBCConfig, d: mujoco.MjData, s: int, k: int, p: np.ndarray) -> np.ndarray:
        """Swing foot ``k``'s landing point ``p`` (2,) moved sideways to at least ``min_foot_gap`` from
        stance foot ``s`` (no crossing)."""
        R = d.xmat[robot.feet[s]].reshape(3, 3)
        lateral = np.array([-R[1, 0], R[0, 0]]) / max(np.hypot(R[0, 0], R[1, 0]), 1e-9)  # the stance foot's left
        side = 1.0 if k == 0 else -1.0
        gap = side * lateral @ (p - d.xpos[robot.feet[s]][:2])
        if gap < cfg.min_foot_gap:
            p += side * (cfg.min_foot_gap - gap) * lateral
        return p
