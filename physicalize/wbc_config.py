"""The whole-body QP controller's gains and task weights (:class:`WBCConfig`, used by
:class:`physicalize.wbc.WholeBodyController`) and the base teacher's ordered gain sets
(:data:`TEACHER_GAINS`, tried per clip by :func:`physicalize.clip.physicalize_clip`)."""

from __future__ import annotations

from dataclasses import dataclass

from physicalize.object_loop import LoopGains


@dataclass(frozen=True)
class WBCConfig:
    """Gains (stiffness ``kp`` [1/s^2], damping ``kd`` [1/s]) and task weights of the QP."""

    mu: float = 0.5
    com_kp: tuple[float, float, float] = (60.0, 60.0, 100.0)
    com_kd: tuple[float, float, float] = (15.0, 15.0, 20.0)
    orient_kp: float = 200.0
    orient_kd: float = 28.0
    foot_kp: float = 400.0
    foot_kd: float = 40.0
    hand_kp: float = 100.0
    hand_kd: float = 20.0
    # a hand holding an object (omomo box lost at 2.64 s with hand_kp: the hands slid 5-15 cm up and down its faces;
    # held to 3.56 s with these, and to the end with the feasible swing clearance)
    hold_kp: float = 300.0
    hold_kd: float = 35.0
    posture_kp: float = 100.0
    posture_kd: float = 20.0
    stance_kv: float = 20.0
    stance_flat_kp: float = 100.0
    w_com: tuple[float, float, float] = (1000.0, 1000.0, 1000.0)  # per world axis x, y, z
    w_pelvis: float = 20.0
    w_torso: float = 10.0
    w_swing: float = 100.0
    w_hand: float = 5.0
    w_posture: float = 1.0
    w_seat: float = 1000.0  # a seat support point's hold (physicalize.seat)
    seated_foot_load: float = 0.1  # least share of the weight on each stance foot while seated
    w_qdd: float = 1e-4
    w_force: float = 1e-5
    # the QP's torque bounds as a fraction of the actuators' effort limits (1.0: 31% of walk frames saturated)
    effort_scale: float = 0.95
    joint_limits: bool = True  # the joint-range rows below (False: the QP knows no joint range)
    limit_rate: float = 15.0  # alpha [1/s] of the joint-range barrier (see physicalize.wbc_rows.limit_bounds)
    limit_zeta: float = 1.0  # damping ratio of the barrier (1: critically damped)
    limit_margin: float = 0.01  # the barrier keeps joints this far [rad] inside their MuJoCo range
    limit_active: float = 300.0  # a range row enters the QP when its bound on |qdd| is under this [rad/s^2]
    # m/s (0.5 fell in test_gait's -y push while walking): the swing-foot touchdown rows' descent-speed cap
    # zdd >= -a (zd + speed) (physicalize.wbc_rows.soft_rows)
    touchdown_speed: float = 0.8
    touchdown_zone: float = 0.10  # m: sole corners higher than this get no row
    # the held object in the QP (physicalize.object_loop): its gains and weights; None: the open loop (each holding
    # hand's planned force, physicalize.grasp_force, in place of its measured contacts; hand goals on the reference
    # object's track, following a lagging object beyond hand_lead)
    object_loop: LoopGains | None = None
    # m: the open loop's lead: a held object farther than this from its reference takes the hand goals along
    hand_lead: float = 0.05
    # m/(N s): a holding hand's goal moves this far into the object per second per newton the simulation's contact
    # falls short of the QP's normal force (the contact force loop), at most press_max either way
    press_gain: float = 0.005
    press_max: float = 0.03
    # a holding hand in contact moves with the object's point under it along the object's face, with this weight
    # (moving relative to it, the QP's friction would be free to push the object while the hand slides back)
    w_stick: float = 1000.0
    # m: legs keep this far from objects (their contact is never planned; 0.01: the OMOMO clip fell at 0.62 s)
    clearance: float = 0.0
    # a [1/s] of the clearance barrier (0: no rows; see physicalize.wbc_rows.clearance_rows)
    clearance_rate: float = 15.0
    clearance_zone: float = 0.05  # m: pairs farther than clearance + this get no row
    w_limit_slack: float = 1e4  # weight of the slack that keeps the QP feasible when a range row cannot hold
    # contact state from the simulation: the fraction of the weight carried by other contacts (a seat) that turns the
    # stepping logic off
    other_support: float = 0.2
    touch_force: float = 20.0  # N: a foot pressing the floor this hard is in contact
    # m: a swing foot in contact whose reference sole is this low and not rising has landed
    touchdown_height: float = 0.02
    descend_speed: float = 0.3  # m/s: a stance foot not yet on the floor is driven down at this speed
    # capture-point (DCM) step adjustment of the swing foot's landing point (physicalize.stepping)
    step_max: float = 0.2  # m, largest shift
    # m, least lateral distance of the swing foot from the stance foot (no crossing; 0.14 moved narrow footsteps
    # outward: frames 4557 -> 4877)
    min_foot_gap: float = 0.08


# The base teacher's gain sets, tried in order on a clip until one tracks it validly
# (physicalize.clip.physicalize_clip):
# heavier horizontal CoM tasks make posture, orientation and hand tasks yield to balance. Alone, (5000, 5000, 1000)
# walks 44 of the gait envelope's 50 walks (the first set 32) and the default Carry, but the OMOMO box falls and
# SitStand seeds break on joint-limit frames: no single set was best on every clip (`make bench-physicalize`).
# The open loop's sets come first, then the object loop's (physicalize.object_loop): alone, the loop lost the
# default Carry's box in the walk (the wrists at their 5 N m and the waist at 95% of its effort while lifting);
# after them it rescues what they fail (OMOMO's squeezed box lift sub3_largebox_003; a box shoved mid-push:
# tests/test_object_loop.py), and every clip the open loop made valid stays as it was, bit for bit.
TEACHER_GAINS: tuple[WBCConfig, ...] = (
    WBCConfig(),
    WBCConfig(w_com=(5000.0, 5000.0, 1000.0)),
    WBCConfig(w_com=(5000.0, 5000.0, 500.0)),
    WBCConfig(w_com=(10000.0, 10000.0, 1000.0)),
    WBCConfig(object_loop=LoopGains()),
)
