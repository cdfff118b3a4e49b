"""Support from the simulation and capture-point stepping for the whole-body controller
(:class:`physicalize.wbc.WholeBodyController`): which feet support this control step and where the
swing foot lands, given the scheduled target and the measured state.

With the divergent component of motion ``xi = c + c_dot / omega``, ``omega = sqrt(g / z_c)``, a
swing foot's landing point moves by ``step_gain (xi - xi_ref)`` so it lands where the DCM can be
caught; the CoM target follows the footholds taken by ``com_anchor`` times their landing shift.
"""

from __future__ import annotations

from dataclasses import replace
from typing import TYPE_CHECKING

import mujoco
import numpy as np

if TYPE_CHECKING:
    from physicalize.target import Target
    from physicalize.wbc import WholeBodyController


def foot_floor_forces(m: mujoco.MjModel, d: mujoco.MjData, feet: list[int], floor: int) -> np.ndarray:
    """(2,) normal force of the floor on each of the ``feet`` bodies, measured in the simulation [N]
    (the floor is a plane: its contact normals are vertical)."""
    out, f6 = np.zeros(2), np.zeros(6)
    for i in range(d.ncon):
        c = d.contact[i]
        if floor not in (c.geom1, c.geom2):
            continue
        b = m.geom_bodyid[c.geom2 if c.geom1 == floor else c.geom1]
        if b in feet:
            mujoco.mj_contactForce(m, d, i, f6)
            out[feet.index(b)] += f6[0]
    return out


def dcm_error(ctrl: WholeBodyController, d: mujoco.MjData, target: Target) -> np.ndarray:
    """Horizontal divergent-component-of-motion error ``xi - xi_ref`` with ``xi = c + c_dot / omega``,
    ``omega = sqrt(g / z_c)`` (``z_c``: the target CoM height)."""
    c, _, _, cd = ctrl.com(d)
    omega = np.sqrt(9.81 / max(float(target.com[2]), 0.3))
    return (c[:2] + cd[:2] / omega) - (target.com[:2] + target.com_vel[:2] / omega)


class Stepping:
    """The stepping state of one rollout: the capture-point shift each foot last landed with."""

    def __init__(self, dt: float):
        self.dt = dt
        self.landing_shift = np.zeros((2, 2))

    def adapt(self, ctrl: WholeBodyController, d: mujoco.MjData, target: Target) -> Target:
        """The target with its support taken from the simulation and the swing foot's landing point
        moved by the capture-point error:

        * a scheduled stance foot that does not press the floor (< ``touch_force``) while the other
          foot supports becomes a swing foot driven down onto its footstep (late touchdown);
        * a scheduled swing foot pressing the floor whose reference sole is low (< ``touchdown_height``)
          and not rising becomes a stance foot (early touchdown);
        * a swing foot's target moves horizontally by ``step_gain (xi - xi_ref)`` (at most ``step_max``,
          never closer than ``min_foot_gap`` sideways to the stance foot): where the robot's DCM runs
          ahead of or beside the plan, the foot lands where the DCM can be caught;
        * while a foot supports, the CoM target moves by ``com_anchor`` times the shift that foot landed
          with (the plan follows the footholds taken: without it the plan kept pulling the CoM toward the
          reference footsteps, the next landing was shifted further, and a 20 N side push diverged)."""
        cfg = ctrl.cfg
        force = foot_floor_forces(ctrl.m, d, ctrl.feet, ctrl.floor)
        on = force > cfg.touch_force
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
                pos[k, 2] = min(pos[k, 2], d.xpos[ctrl.feet[k]][2]) - cfg.descend_speed * self.dt
        com = target.com
        if cfg.com_anchor > 0 and any(stance):  # the plan follows the footholds actually taken
            held = [k for k in range(2) if stance[k]]
            if held:
                off = np.mean([self.landing_shift[k] for k in held], axis=0)
                com = target.com.copy()
                com[:2] += cfg.com_anchor * off
                target = replace(target, com=com)
        if stance.count(True) == 1 and cfg.step_gain > 0:
            s, k = stance.index(True), stance.index(False)
            shift = cfg.step_gain * dcm_error(ctrl, d, target)
            n = np.linalg.norm(shift)
            if n > cfg.step_max:
                shift *= cfg.step_max / n
            p = pos[k, :2] + shift
            R = d.xmat[ctrl.feet[s]].reshape(3, 3)
            lateral = np.array([-R[1, 0], R[0, 0]]) / max(np.hypot(R[0, 0], R[1, 0]), 1e-9)  # the stance foot's left
            side = 1.0 if k == 0 else -1.0
            gap = side * lateral @ (p - d.xpos[ctrl.feet[s]][:2])
            if gap < cfg.min_foot_gap:
                p += side * (cfg.min_foot_gap - gap) * lateral
            pos[k, :2] = p
        for k in range(2):  # the step adjustment each foot landed with (kept while it supports)
            if not stance[k]:
                self.landing_shift[k] = pos[k, :2] - target.foot_pos[k, :2]
        return replace(target, stance=(stance[0], stance[1]), foot_pos=pos, foot_vel=vel, foot_acc=acc)
