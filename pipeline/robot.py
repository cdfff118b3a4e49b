"""The Unitree G1 (29 DoF): model file, joint order, limits and actuator profiles.

The MJCF and meshes come from the ``mjlab`` wheel (Apache-2.0), located through the
installed package, never copied into this repository. The XML carries no actuators;
:mod:`pipeline.scene` adds them from an :class:`ActuatorProfile`.

Joint order is mjlab's (also the order of the ``g1.xml`` joints and of mjlab / OmniRetarget motion files; BeyondMimic's
are in Isaac Lab's breadth-first order, :mod:`pipeline.isaaclab_order`): :data:`G1_JOINT_NAMES`. ``qpos`` = root
position (3), root quaternion wxyz (4), then those 29 joints.

Two actuator profiles, both position-controlled (``tau = kp (q* - q) - kd qd``, clipped
to the effort limit):

* ``mjlab`` -- the BeyondMimic / mjlab / HDMI / ResMimic convention:
  ``kp = a w^2``, ``kd = 2 zeta a w`` with ``a`` the reflected rotor inertia (armature),
  ``w = 2 pi 10 Hz`` and ``zeta = 2``; default pose mjlab's knees-bent keyframe.
* ``lessmimic_demo`` -- the gains of the released LessMimic web demo
  (``interaction_policy.json``): legs 120/120/120/160/40/40, waist 200, arms 40,
  wrist pitch/yaw 20; damping 3/3/3/4/1/1, 5, 1, 0.5; default pose all zeros;
  actions clipped to 10.

Armature and effort limits are the motor data in mjlab's ``g1_constants.py`` (5020, 7520-14,
7520-22, 4010 actuators; the 4-bar ankles and waist roll/pitch count as two 5020s). A test
checks these numbers against the installed mjlab.
"""

from __future__ import annotations

import importlib.util
import math
from dataclasses import dataclass
from functools import lru_cache
from pathlib import Path

import mujoco
import numpy as np

G1_JOINT_NAMES: tuple[str, ...] = (
    "left_hip_pitch_joint",
    "left_hip_roll_joint",
    "left_hip_yaw_joint",
    "left_knee_joint",
    "left_ankle_pitch_joint",
    "left_ankle_roll_joint",
    "right_hip_pitch_joint",
    "right_hip_roll_joint",
    "right_hip_yaw_joint",
    "right_knee_joint",
    "right_ankle_pitch_joint",
    "right_ankle_roll_joint",
    "waist_yaw_joint",
    "waist_roll_joint",
    "waist_pitch_joint",
    "left_shoulder_pitch_joint",
    "left_shoulder_roll_joint",
    "left_shoulder_yaw_joint",
    "left_elbow_joint",
    "left_wrist_roll_joint",
    "left_wrist_pitch_joint",
    "left_wrist_yaw_joint",
    "right_shoulder_pitch_joint",
    "right_shoulder_roll_joint",
    "right_shoulder_yaw_joint",
    "right_elbow_joint",
    "right_wrist_roll_joint",
    "right_wrist_pitch_joint",
    "right_wrist_yaw_joint",
)
NUM_JOINTS = len(G1_JOINT_NAMES)

# --- The state layout (MuJoCo): the robot is a scene's first tree, free objects follow it ------------
NQ_ROBOT = 7 + NUM_JOINTS  #: 36: root position (3, world), root quaternion wxyz (4), the joints
NV_ROBOT = 6 + NUM_JOINTS  #: 35: root linear velocity (world), root angular velocity (root frame), the joints
ROOT_POS = slice(0, 3)  #: in qpos
ROOT_QUAT = slice(3, 7)  #: in qpos
ROOT_POSE = slice(0, 7)  #: position and quaternion, in qpos
JOINTS_QPOS = slice(7, NQ_ROBOT)
ROOT_LIN_VEL = slice(0, 3)  #: in qvel
ROOT_ANG_VEL = slice(3, 6)  #: in qvel
JOINTS_QVEL = slice(6, NV_ROBOT)
FREE_NQ, FREE_NV = 7, 6  #: a free body's (an object's) qpos (position, quaternion) and qvel (linear, angular) sizes

ROOT_NAMES: tuple[str, ...] = ("root_x", "root_y", "root_z", "root_qw", "root_qx", "root_qy", "root_qz")
QPOS_NAMES: tuple[str, ...] = ROOT_NAMES + G1_JOINT_NAMES

#: Bodies the DF features and inspection logs refer to (MuJoCo body names in g1.xml).
G1_LINK_NAMES: tuple[str, ...] = (
    "pelvis",
    "torso_link",
    "left_hip_pitch_link",
    "left_knee_link",
    "left_ankle_roll_link",
    "right_hip_pitch_link",
    "right_knee_link",
    "right_ankle_roll_link",
    "left_shoulder_pitch_link",
    "left_elbow_link",
    "left_wrist_yaw_link",
    "right_shoulder_pitch_link",
    "right_elbow_link",
    "right_wrist_yaw_link",
)
FOOT_BODIES: tuple[str, str] = ("left_ankle_roll_link", "right_ankle_roll_link")  #: left, right
HAND_BODIES: tuple[str, str] = ("left_wrist_yaw_link", "right_wrist_yaw_link")  #: left, right
#: The 7 query bodies of the released LessMimic demo, in its order.
LESSMIMIC_DEMO_DF_BODIES: tuple[str, ...] = (
    "left_wrist_yaw_link",
    "right_wrist_yaw_link",
    "pelvis",
    "left_ankle_roll_link",
    "right_ankle_roll_link",
    "left_shoulder_pitch_link",
    "right_shoulder_pitch_link",
)


def g1_xml_path() -> Path:
    """Path of mjlab's ``g1.xml`` inside the installed wheel (meshes in ``../assets`` beside it)."""
    spec = importlib.util.find_spec("mjlab")  # found, not imported: mjlab's __init__ imports warp and mediapy (~5 s)
    roots = list(spec.submodule_search_locations or []) if spec is not None else []
    path = Path(roots[0] if roots else "<mjlab not installed>") / "asset_zoo/robots/unitree_g1/xmls/g1.xml"
    if not path.is_file():
        raise FileNotFoundError(f"G1 model not found at {path}: is mjlab==1.6.0 installed in this environment?")
    return path


# --- Motor data (mjlab g1_constants.py): reflected inertia [kg m^2], effort limit [N m] -------------
_MOTORS: dict[str, tuple[float, float]] = {
    "5020": (0.003609725, 25.0),
    "7520_14": (0.01017752004132231, 88.0),
    "7520_22": (0.025101924999999997, 139.0),
    "4010": (0.00425, 5.0),
    "2x5020": (2 * 0.003609725, 50.0),
}


def _motor_of(joint: str) -> str:
    if any(k in joint for k in ("elbow", "shoulder", "wrist_roll")):
        return "5020"
    if any(k in joint for k in ("hip_pitch", "hip_yaw", "waist_yaw")):
        return "7520_14"
    if any(k in joint for k in ("hip_roll", "knee")):
        return "7520_22"
    if any(k in joint for k in ("wrist_pitch", "wrist_yaw")):
        return "4010"
    if any(k in joint for k in ("ankle", "waist_roll", "waist_pitch")):
        return "2x5020"
    raise KeyError(joint)


#: Rated motor speeds [rad/s] of mjlab's ``g1_constants.py`` (``velocity_limit`` of the
#: 5020, 7520-14, 7520-22 and 4010 actuators; the ankle and waist roll/pitch 4-bar pairs are
#: 5020s). Matched by joint-name substring, first match wins.
MOTOR_SPEED_RADPS: tuple[tuple[tuple[str, ...], float], ...] = (
    (("elbow", "shoulder", "wrist_roll", "ankle", "waist_roll", "waist_pitch"), 37.0),  # 5020
    (("hip_pitch", "hip_yaw", "waist_yaw"), 32.0),  # 7520-14
    (("hip_roll", "knee"), 20.0),  # 7520-22
    (("wrist_pitch", "wrist_yaw"), 22.0),  # 4010
)


def joint_velocity_limits(factor: float = 1.0) -> dict[str, float]:
    """``{joint: factor * rated motor speed}`` [rad/s] for the 29 G1 joints (:data:`MOTOR_SPEED_RADPS`)."""
    out = {}
    for j in G1_JOINT_NAMES:
        speed = next((v for keys, v in MOTOR_SPEED_RADPS if any(k in j for k in keys)), None)
        if speed is None:
            raise KeyError(f"no motor speed for joint {j}")
        out[j] = factor * speed
    return out


ARMATURE = np.array([_MOTORS[_motor_of(j)][0] for j in G1_JOINT_NAMES])
EFFORT_LIMIT = np.array([_MOTORS[_motor_of(j)][1] for j in G1_JOINT_NAMES])


@dataclass(frozen=True)
class ActuatorProfile:
    """A named PD actuator convention: per-joint ``kp``, ``kd``, effort limits, armature, default pose."""

    name: str
    kp: np.ndarray
    kd: np.ndarray
    effort_limit: np.ndarray
    armature: np.ndarray
    default_joint_pos: np.ndarray
    action_clip: float | None = None
    description: str = ""

    def __post_init__(self):
        for f in ("kp", "kd", "effort_limit", "armature", "default_joint_pos"):
            a = np.asarray(getattr(self, f), dtype=np.float64)
            if a.shape != (NUM_JOINTS,):
                raise ValueError(f"actuator profile {self.name}: {f} has shape {a.shape}, expected ({NUM_JOINTS},)")
            a.setflags(write=False)
            object.__setattr__(self, f, a)

    def torque(self, target: np.ndarray, q: np.ndarray, qd: np.ndarray) -> np.ndarray:
        """``clip(kp (target - q) - kd qd, -effort, effort)``."""
        return np.clip(self.kp * (target - q) - self.kd * qd, -self.effort_limit, self.effort_limit)


def _mjlab_profile() -> ActuatorProfile:
    w, zeta = 2.0 * math.pi * 10.0, 2.0
    default = dict.fromkeys(G1_JOINT_NAMES, 0.0)
    for j in G1_JOINT_NAMES:  # mjlab KNEES_BENT_KEYFRAME
        if "hip_pitch" in j:
            default[j] = -0.312
        elif "knee" in j:
            default[j] = 0.669
        elif "ankle_pitch" in j:
            default[j] = -0.363
        elif "elbow" in j:
            default[j] = 0.6
        elif "shoulder_pitch" in j:
            default[j] = 0.2
    default["left_shoulder_roll_joint"], default["right_shoulder_roll_joint"] = 0.2, -0.2
    return ActuatorProfile(
        name="mjlab",
        kp=ARMATURE * w**2,
        kd=2.0 * zeta * ARMATURE * w,
        effort_limit=EFFORT_LIMIT,
        armature=ARMATURE,
        default_joint_pos=np.array([default[j] for j in G1_JOINT_NAMES]),
        description="BeyondMimic/mjlab PD: kp = armature (2 pi 10 Hz)^2, kd = 2 * 2 * armature (2 pi 10 Hz)",
    )


def _lessmimic_demo_profile() -> ActuatorProfile:
    leg_kp, leg_kd = (120, 120, 120, 160, 40, 40), (3, 3, 3, 4, 1, 1)
    kp = [*leg_kp, *leg_kp, 200, 200, 200, *([40, 40, 40, 40, 40, 20, 20] * 2)]
    kd = [*leg_kd, *leg_kd, 5, 5, 5, *([1, 1, 1, 1, 1, 0.5, 0.5] * 2)]
    return ActuatorProfile(
        name="lessmimic_demo",
        kp=np.array(kp, dtype=float),
        kd=np.array(kd, dtype=float),
        effort_limit=EFFORT_LIMIT,
        armature=ARMATURE,
        default_joint_pos=np.zeros(NUM_JOINTS),
        action_clip=10.0,
        description="released LessMimic web demo gains (interaction_policy.json); default pose all zeros",
    )


ACTUATOR_PROFILES: dict[str, ActuatorProfile] = {p.name: p for p in (_mjlab_profile(), _lessmimic_demo_profile())}
DEFAULT_PROFILE = "mjlab"  # a dataset that names none was written under it


def actuator_profile(name: str) -> ActuatorProfile:
    try:
        return ACTUATOR_PROFILES[name]
    except KeyError:
        raise ValueError(f"unknown actuator profile {name!r}; known: {sorted(ACTUATOR_PROFILES)}") from None


def g1_spec():
    """``g1.xml`` as an editable ``mujoco.MjSpec`` without its visual meshes.

    The meshes are visual only (geoms with ``contype = conaffinity = 0``; every body declares its
    mass and inertia), so dropping them leaves the physics as it was, while compiling no longer
    processes ~197k mesh vertices: 1.4 ms instead of ~0.8 s per compile (and ~3 s for the first in
    a process). The stages simulate, solve IK and draw the robot from its collision primitives."""
    spec = mujoco.MjSpec.from_file(str(g1_xml_path()))
    for g in list(spec.geoms):
        if g.type == mujoco.mjtGeom.mjGEOM_MESH and g.contype == 0 and g.conaffinity == 0:
            spec.delete(g)
    used = {g.meshname for g in spec.geoms if g.type == mujoco.mjtGeom.mjGEOM_MESH}
    for mesh in list(spec.meshes):
        if mesh.name not in used:
            spec.delete(mesh)
    return spec


@lru_cache(maxsize=1)
def g1_model():
    """The compiled :func:`g1_spec` (no actuators, no floor: kinematics and dynamics of the robot alone)."""
    return g1_spec().compile()


def joint_limits() -> tuple[np.ndarray, np.ndarray]:
    """(lower, upper) joint position limits [rad] in :data:`G1_JOINT_NAMES` order, read from g1.xml."""
    m = g1_model()
    rng = np.array([m.jnt_range[m.joint(j).id] for j in G1_JOINT_NAMES])
    return rng[:, 0].copy(), rng[:, 1].copy()


def default_qpos(profile: ActuatorProfile, root_height: float = 0.76) -> np.ndarray:
    """Standing ``qpos`` (36,) at the profile's default joint pose, identity root orientation."""
    return np.concatenate([[0.0, 0.0, root_height, 1.0, 0.0, 0.0, 0.0], profile.default_joint_pos])


def g1_pinocchio_model():
    """Pinocchio model of the same ``g1.xml`` (its free joint becomes a free-flyer: nq 36, nv 35).

    Pinocchio orders the root quaternion ``xyzw`` (see :func:`pinocchio_qpos`); its free-flyer
    velocity is expressed in the root frame, MuJoCo's linear part in the world frame.
    """
    import pinocchio

    return pinocchio.buildModelFromMJCF(str(g1_xml_path()))


def pinocchio_qpos(qpos: np.ndarray) -> np.ndarray:
    """MuJoCo ``qpos`` (root quaternion wxyz) -> Pinocchio configuration (root quaternion xyzw)."""
    q = np.array(qpos, dtype=np.float64, copy=True)
    q[..., 3:7] = q[..., [4, 5, 6, 3]]
    return q


def sole_corners(model: mujoco.MjModel, body: str) -> np.ndarray:
    """(4, 3) support-polygon corners of a foot in its body frame: the extreme capsule end points
    of its collision capsules (heel-inner, heel-outer, toe-inner, toe-outer order by x then y) at
    the sole's lowest point."""
    bid = model.body(body).id
    pts, bottom = [], []
    for g in range(model.ngeom):
        if (
            model.geom_bodyid[g] != bid
            or not model.geom_contype[g]
            or model.geom_type[g] != mujoco.mjtGeom.mjGEOM_CAPSULE
        ):
            continue
        R = np.empty(9)
        mujoco.mju_quat2Mat(R, model.geom_quat[g])
        axis = R.reshape(3, 3)[:, 2] * model.geom_size[g, 1]
        for s in (-1.0, 1.0):
            pts.append(model.geom_pos[g] + s * axis)
        bottom.append(model.geom_pos[g][2] - model.geom_size[g, 0])
    if not pts:
        raise ValueError(f"foot body {body!r} has no collision capsules")
    p = np.array(pts)
    x0, x1 = p[:, 0].min(), p[:, 0].max()
    heel, toe = p[np.abs(p[:, 0] - x0) < 0.02], p[np.abs(p[:, 0] - x1) < 0.02]
    z = min(bottom)
    return np.array(
        [[x0, heel[:, 1].min(), z], [x0, heel[:, 1].max(), z], [x1, toe[:, 1].min(), z], [x1, toe[:, 1].max(), z]]
    )
