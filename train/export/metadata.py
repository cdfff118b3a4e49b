"""What an exported policy carries beside its graph: the contract a robot stack, a viewer or another simulator needs
to run it correctly (most sim2sim failures users of peer trackers report come from a missing action scale, gains or
joint order).

:func:`policy_metadata` is one JSON-able dict, stored in the ONNX model's ``metadata_props`` under the key
:data:`METADATA_KEY` (:func:`metadata_props`). Beside it, the flat keys mjlab's exporter writes (``joint_names``,
``joint_stiffness``, ``joint_damping``, ``default_joint_pos``: comma-separated, in ``joint_names`` order) so that
tools reading mjlab's ONNX files find the gains where they look. mjlab's ``action_scale`` is deliberately absent: our
action is the absolute joint target, not ``default + scale * a``, and a reader that assumed mjlab's convention
with a scale of 1 would add the default pose twice.
"""

from __future__ import annotations

import hashlib
import json
from dataclasses import asdict
from pathlib import Path

from pipeline.robot import G1_JOINT_NAMES, actuator_profile
from pipeline.terms import layout as L

METADATA_KEY = "lessmimic"
EXPORT_FORMAT = "lessmimic.onnx_policy/1"
INPUTS = ("proprio", "root_command", "df")
VISION_INPUTS = ("proprio", "root_command", "depth")  # a vision student's (train.vision.student)
OUTPUT = "joint_targets"

TERM_MEANING = {
    "proprio": "per step: q (29) joint angles [rad]; dq (29) joint velocities [rad/s]; gravity direction in the root "
    "frame (3, unit); root angular velocity in the root frame (3) [rad/s]; the previous step's action (29) [rad], "
    "zeros at an episode's first step",
    "root_command": "per step: the root 1 s ahead seen from the root's heading frame (yaw only, z up): position delta "
    "(3) [m]; orientation as the first two columns of H^T R_target (6, column-major); its linear velocity (3) [m/s]; "
    "near the end of a motion the target is its last frame",
    "df": "per step and DF link: the nearest object's distance field phi [m], its unit gradient (3), the link "
    "velocity's normal (3) and tangential (3) parts with respect to that gradient [m/s]; all in the world frame",
}

DEMO_TERM_MEANING = {  # the released demo's contract (pipeline.terms.layout.CONTRACTS)
    "root_command": TERM_MEANING["root_command"] + "; the height delta and vertical velocity are zero and the task "
    "condition [v, v] follows (0 none, 1 carry, 2 push); only the newest step is read",
    "df": "per step and query body: min(|phi|, 1 m) of the nearest object's unsigned distance, its gradient (3) in "
    "the body's own frame, zero beyond 1 m",
}


def inputs_of(policy) -> tuple[str, str, str]:
    """The graph inputs of ``policy``: a vision student's (it has a camera) or a MoCap-DF policy's."""
    return VISION_INPUTS if getattr(policy, "camera", None) is not None else INPUTS


def camera_metadata(camera) -> dict:
    """A :class:`train.vision.camera.DepthCamera`'s intrinsics, extrinsics and range, as a robot stack sets its own."""
    fx, fy = camera.focal
    return {
        "config": asdict(camera),
        "intrinsics": {"width": camera.width, "height": camera.height, "fx": fx, "fy": fy,
                       "cx": camera.width / 2, "cy": camera.height / 2, "fov_x_deg": camera.fov_x_deg,
                       "fov_y_deg": camera.fov_y_deg},
        "extrinsics": {"body": camera.body, "pos_m": list(camera.pos), "rpy_rad": [0.0, camera.pitch, 0.0],
                       "convention": "in the body's frame: x forward, y left, z up (ROS); the optical axis is the "
                       "body x pitched down by rpy[1]; image right -y, image down -z"},
        "depth": {"kind": "z-depth along the optical axis [m], row-major (height, width), row 0 at the top",
                  "range_m": [camera.near, camera.far], "no_hit": camera.far, "invalid": 0.0},
    }  # fmt: skip


def sha256(path: str | Path) -> str:
    h = hashlib.sha256()
    with open(path, "rb") as f:
        for block in iter(lambda: f.read(1 << 20), b""):
            h.update(block)
    return h.hexdigest()


def policy_metadata(policy, checkpoint: str | Path) -> dict:
    """The contract of ``policy`` (an :class:`train.policy.InteractionPolicy` loaded from ``checkpoint``)."""
    lay, cfg = policy.layout, policy.config
    obs = lay.observation
    profile = actuator_profile(lay.actuator_profile)
    column, parts = L.CONTRACT_DF[lay.contract]
    demo = lay.contract == "lessmimic_demo"
    names = {
        "proprio": list(L.PROPRIO_NAMES),
        "root_command": list(L.ROOT_COMMAND_NAMES) + (["task_condition_0", "task_condition_1"] if demo else []),
        "df": list(L.feature_names(lay.links, parts)),
    }
    meaning = {**TERM_MEANING, **(DEMO_TERM_MEANING if demo else {})}
    inputs = inputs_of(policy)
    shapes = {k: [dim] for k, dim in zip(INPUTS, obs.step_dims)}
    camera = None
    if inputs == VISION_INPUTS:  # the vision student reads depth frames in place of the DF
        cam = policy.camera
        camera = camera_metadata(cam)
        shapes["depth"], names["depth"] = [cam.height, cam.width], []
        meaning["depth"] = "per step: the depth frame of the camera (metadata camera): " + camera["depth"]["kind"]
    return {
        "format": EXPORT_FORMAT,
        "checkpoint": {"file": Path(checkpoint).name, "sha256": sha256(checkpoint)},
        "joint_names": list(G1_JOINT_NAMES),
        "action": {
            "output": OUTPUT,
            "shape": ["batch", lay.action_dim],
            "meaning": "absolute joint position targets [rad] in joint_names order (no scale, no offset), held for "
            "one control step by the PD law",
            "pd_law": "tau = clip(kp (target - q) - kd dq, -effort_limit, effort_limit)",
        },
        "actuator": {
            "profile": profile.name,
            "description": profile.description,
            **{k: getattr(profile, k).tolist() for k in ("kp", "kd", "effort_limit", "armature", "default_joint_pos")},
        },
        "control": {
            "fps": L.CONTROL_FPS,
            "dt_s": 1.0 / L.CONTROL_FPS,
            "physics_timestep_s": L.PHYSICS_TIMESTEP,
            "substeps": L.SUBSTEPS,
        },
        "observation": {
            "history": lay.history,
            "order": "each input is (batch, history, width): oldest step first, newest last; before an episode's "
            "first step, that step is repeated",
            "inputs": {
                k: {"shape": ["batch", lay.history, *shapes[k]], "names": names[k], "meaning": meaning[k]}
                for k in inputs
            },
            "df_links": list(lay.links),
            "df_column": column,
            "contract": lay.contract,
        },
        "camera": camera,
        "policy": {"config": asdict(cfg), "layout": lay.to_dict()},
        **({"teacher": policy.teacher} if camera is not None else {}),
    }


def _csv(values) -> str:
    return ",".join(repr(float(v)) if not isinstance(v, str) else v for v in values)


def metadata_props(meta: dict) -> dict[str, str]:
    """The ONNX ``metadata_props`` of ``meta``: the whole dict as JSON, and mjlab's flat keys (module docstring)."""
    act = meta["actuator"]
    return {
        METADATA_KEY: json.dumps(meta, sort_keys=True),
        "joint_names": _csv(meta["joint_names"]),
        "joint_stiffness": _csv(act["kp"]),
        "joint_damping": _csv(act["kd"]),
        "default_joint_pos": _csv(act["default_joint_pos"]),
        "checkpoint_sha256": meta["checkpoint"]["sha256"],
    }
