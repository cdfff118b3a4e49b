"""The post-training reward terms on hand-built cases with known values, in numpy and in torch alike."""

import numpy as np
import pytest
import torch

from train.mdp.rewards import (
    RewardWeights,
    action_rate,
    joint_limits,
    lsgan_reward,
    object_tracking,
    root_tracking,
    termination,
    total,
)


def _both(*arrays):
    """The same arrays as numpy and as torch (float64, bool kept)."""
    return [tuple(np.asarray(a) for a in arrays), tuple(torch.as_tensor(np.asarray(a)) for a in arrays)]


def _np(x):
    return x.numpy() if isinstance(x, torch.Tensor) else np.asarray(x)


@pytest.mark.parametrize("lib", [0, 1], ids=["numpy", "torch"])
def test_tracking_terms(lib):
    root, cmd = _both([[0.0, 0.0, 0.8], [1.0, 2.0, 0.8]], [[0.0, 0.0, 0.8], [0.0, 0.0, 0.8]])[lib]
    np.testing.assert_allclose(_np(root_tracking(root, cmd)), [0.0, -5.0])
    obj, target = _both([[1.0, 0.0, 0.5], [1.3, 0.0, 0.5]], [[1.0, 0.0, 0.5], [1.0, 0.0, 0.5]])[lib]
    np.testing.assert_allclose(_np(object_tracking(obj, target, 0.3)), [1.0, np.exp(-1.0)])


@pytest.mark.parametrize("lib", [0, 1], ids=["numpy", "torch"])
def test_penalty_terms(lib):
    a, last = _both([[0.1, 0.2], [0.0, 0.0]], [[0.1, 0.0], [0.3, -0.4]])[lib]
    np.testing.assert_allclose(_np(action_rate(a, last)), [0.04, 0.25])
    term, timeout = _both([True, True, False], [False, True, False])[lib]
    np.testing.assert_array_equal(_np(termination(term, timeout)), [1.0, 0.0, 0.0])
    # range [-1, 1] -> soft [-0.9, 0.9]; range [0, 2] -> soft [0.1, 1.9]
    q, lo, hi = _both([[0.95, 1.0], [-0.5, 0.05], [0.0, 1.95]], [-1.0, 0.0], [1.0, 2.0])[lib]
    np.testing.assert_array_equal(_np(joint_limits(q, lo, hi)), [1.0, 1.0, 1.0])
    np.testing.assert_array_equal(_np(joint_limits(q, lo, hi, soft=1.0)), [0.0, 0.0, 0.0])


@pytest.mark.parametrize("lib", [0, 1], ids=["numpy", "torch"])
def test_lsgan_reward(lib):
    (d,) = _both([1.0, 0.0, -1.0, -3.0, 2.0])[lib]
    np.testing.assert_allclose(_np(lsgan_reward(d)), [1.0, 0.75, 0.0, 0.0, 0.75])


def test_total_weights_the_table():
    w = RewardWeights()
    terms = {"root_tracking": np.array([-0.5]), "action_rate": np.array([0.1]), "termination": np.array([1.0])}
    np.testing.assert_allclose(total(terms, w), [-0.5 - 0.05 - 10.0])
    assert w.terms() == {
        "root_tracking": 1.0,
        "interaction_style": 2.0,
        "motion_style": 1.0,
        "object_tracking": 1.0,
        "action_rate": -0.5,  # the table's 5 is for other action units (RewardWeights)
        "termination": -10.0,
        "joint_limits": -5.0,
    }
    for tolerance in ("object_sigma_m", "soft_limit"):
        with pytest.raises(KeyError, match=f"unknown reward terms \\['{tolerance}'\\]"):
            total({tolerance: np.array([1.0])}, w)
