"""The mjlab worlds' objects (:mod:`train.envs.mjlab.object`) against what MuJoCo's compiler derives for the same object
in the native scene: a box, a cylinder and chairs at drawn per-axis scales (torch on the CPU; no mjlab needed)."""

import mujoco
import numpy as np
import pytest
import torch

from pipeline.geometry import Chair, Primitive, chair_boxes, chair_scaled
from pipeline.scene import ObjectPhysics, SceneObject, build_scene
from train.envs.mjlab.object import PAD_HALF, Parts, rigid_body, slots

SCALES = [(1.0, 1.0, 1.0), (0.4, 1.6, 0.9), (1.5, 0.5, 1.3)]


def _native(geometry, mass: float) -> dict:
    """The compiled body and its free joint's constants in the native scene (pipeline.scene.build_scene)."""
    scene = build_scene([SceneObject("object", geometry, ObjectPhysics(mass=mass))])
    m, b = scene.model, scene.object_body_id["object"]
    r = np.empty(9)
    mujoco.mju_quat2Mat(r, m.body_iquat[b])
    r = r.reshape(3, 3)
    dofs = slice(m.body_dofadr[b], m.body_dofadr[b] + 6)
    return {
        "ipos": m.body_ipos[b],
        "tensor": r @ np.diag(m.body_inertia[b]) @ r.T,
        "invweight": m.body_invweight0[b],
        "dof_invweight": m.dof_invweight0[dofs],
    }


def _mine(half, centre, real, mass: float, cylinder: tuple[float, float] | None = None) -> dict:
    """:func:`rigid_body` of one world's slots (box parts, then the cylinder slot), in float64."""

    def t(a, dtype=torch.float64):
        return torch.as_tensor(np.asarray(a)[None], dtype=dtype)

    radius, length = cylinder or (0.0, 0.0)
    parts = Parts(t(half), t(centre), t(real, torch.bool), t(cylinder is not None, torch.bool), t(radius), t(length))
    geoms = slots(parts, cylinders=True)
    body = rigid_body(torch.tensor([mass], dtype=torch.float64), geoms["volume"], geoms["unit"], geoms["pos"])
    body = {k: v[0].numpy() for k, v in body.items()}
    r = np.empty(9)
    mujoco.mju_quat2Mat(r, body["iquat"])
    r = r.reshape(3, 3)
    body["tensor"] = r @ np.diag(body["inertia"]) @ r.T
    return body


@pytest.mark.parametrize("scale", SCALES)
def test_a_chair_weighs_and_turns_as_mujoco_compiles_it(scale):
    chair = Chair().scaled(scale)
    half, centre = chair_boxes(np.array([[getattr(chair, f) for f in Chair.__dataclass_fields__]]))
    mine, native = _mine(half[0], centre[0], np.ones(6, bool), 7.5), _native(chair, 7.5)
    assert abs(native["tensor"][0, 2]) > 1e-3  # the back turns the principal axes: the test is not of a diagonal
    for key in ("ipos", "tensor", "invweight", "dof_invweight"):
        np.testing.assert_allclose(mine[key], native[key], rtol=1e-6, atol=1e-9, err_msg=key)


@pytest.mark.parametrize("scale", SCALES)
def test_a_box_with_pads_is_the_box(scale):
    """A box world of a six-part object: the five pads weigh nothing and the box keeps its own axes."""
    box = Primitive("box", (0.2, 0.15, 0.1)).scaled(scale)
    half = np.concatenate([box.half_extents[None], np.full((5, 3), PAD_HALF)])
    real = np.arange(6) == 0
    mine, native = _mine(half, np.zeros((6, 3)), real, 3.0), _native(Primitive("box", tuple(box.half_extents)), 3.0)
    np.testing.assert_allclose(mine["iquat"], [1, 0, 0, 0])
    np.testing.assert_allclose(mine["inertia"], np.diag(native["tensor"]), rtol=1e-9)
    for key in ("ipos", "invweight", "dof_invweight"):
        np.testing.assert_allclose(mine[key], native[key], rtol=1e-6, atol=1e-12, err_msg=key)


def test_a_cylinder_with_pads_is_the_cylinder():
    """A box drawn as a cylinder (train.mdp.randomize.vary_shape): its box parts are pads; MuJoCo's cylinder
    primitive."""
    half = np.full((6, 3), PAD_HALF)
    mine = _mine(half, np.zeros((6, 3)), np.zeros(6, bool), 2.5, cylinder=(0.12, 0.2))
    native = _native(Primitive("cylinder", (0.12, 0.2)), 2.5)
    for key in ("ipos", "tensor", "invweight", "dof_invweight"):
        np.testing.assert_allclose(mine[key], native[key], rtol=1e-6, atol=1e-12, err_msg=key)


def test_chairs_scale_and_split_alike_in_numpy_and_torch():
    """:func:`chair_scaled` / :func:`chair_boxes` (a batch, torch) give :meth:`Chair.scaled` and :meth:`Chair.parts`."""
    rng = np.random.default_rng(0)
    scales = rng.uniform(0.4, 1.6, (5, 3))
    fields = torch.tensor([[getattr(Chair(), f) for f in Chair.__dataclass_fields__]] * 5, dtype=torch.float64)
    half, centre = chair_boxes(chair_scaled(fields, torch.as_tensor(scales)))
    for k, s in enumerate(scales):
        parts = Chair().scaled(s).parts()
        np.testing.assert_allclose(half[k].numpy(), [p.half_extents for _, p, _ in parts], rtol=1e-12)
        np.testing.assert_allclose(centre[k].numpy(), [c for _, _, c in parts], rtol=1e-12, atol=1e-15)
