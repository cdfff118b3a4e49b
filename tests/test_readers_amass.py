"""AMASS reader: the body-model requirement, file validation, SMPL-H skeleton and orientations.

The licensed SMPL+H / SMPL-X model is not available here and is not faked: the path that runs
``smplx`` is exercised only up to finding the model file.
"""

import numpy as np
import pytest
from mocap_paths import SHARED_MOCAP, expect_input_error, needs_shared
from scipy.spatial.transform import Rotation

from pipeline.readers.amass import SMPLH_JOINT_NAMES, SMPLH_PARENTS, global_orientations, read_amass
from pipeline.rotations import rotation_from_wxyz

SAMPLE = SHARED_MOCAP / "amass" / "amass_sample.npz"


@needs_shared
def test_sample_without_model_says_what_to_pass():
    e = expect_input_error(lambda: read_amass(SAMPLE), SAMPLE.parent, file=SAMPLE, field="body_model")
    assert "--body-model PATH" in str(e) and "SMPL+H" in str(e)


def _npz(tmp_path, name="clip.npz", T=4, **overrides):
    d = dict(
        poses=np.zeros((T, 156)),
        trans=np.zeros((T, 3)),
        betas=np.zeros(16),
        gender=np.array("female"),
        mocap_framerate=np.array(120.0),
    )
    d.update(overrides)
    d = {k: v for k, v in d.items() if v is not None}
    p = tmp_path / name
    np.savez(p, **d)
    return p


@pytest.mark.parametrize(
    "overrides, field, frame, match",
    [
        (dict(trans=None), "trans", None, r"missing \(keys are betas, gender, mocap_framerate, poses\)"),
        (dict(mocap_framerate=None), "mocap_framerate", None, "missing"),
        (dict(poses=np.zeros((0, 156)), trans=np.zeros((0, 3))), "poses", None, "zero frames"),
        (dict(poses=np.zeros((4, 72))), "poses", None, r"\(4, 72\) is not \(T, 156\)"),
        (dict(poses=np.where(np.arange(4)[:, None] == 2, np.nan, np.zeros((4, 156)))), "poses", 2, "NaN"),
        (dict(trans=np.zeros((3, 3))), "trans", None, r"does not match \(4, 3\)"),
        (dict(gender=np.array("robot")), "gender", None, "'robot' is not male"),
    ],
)
def test_bad_files(tmp_path, overrides, field, frame, match):
    p = _npz(tmp_path, **overrides)
    expect_input_error(
        lambda: read_amass(p, body_model=tmp_path), tmp_path, file=p, field=field, frame=frame, match=match
    )


def test_model_path_errors(tmp_path):
    p = _npz(tmp_path)
    missing = tmp_path / "no_such_model"
    expect_input_error(
        lambda: read_amass(p, body_model=missing),
        tmp_path,
        file=p,
        field="body_model",
        match=f"{missing} does not exist",
    )
    empty = tmp_path / "models"
    empty.mkdir()
    expect_input_error(
        lambda: read_amass(p, body_model=empty),
        tmp_path,
        file=p,
        field="body_model",
        match=r"no SMPL\+H female model in .*SMPLH_FEMALE\.pkl",
    )
    expect_input_error(lambda: read_amass(p), tmp_path, file=p, field="body_model", match="--body-model PATH")


def test_smplh_skeleton_is_the_standard_one():
    assert len(SMPLH_JOINT_NAMES) == 52 and SMPLH_JOINT_NAMES[20:23] == ("left_wrist", "right_wrist", "left_index1")
    expected = [-1, 0, 0, 0, 1, 2, 3, 4, 5, 6, 7, 8, 9, 9, 9, 12, 13, 14, 16, 17, 18, 19]
    for wrist, first in ((20, 22), (21, 37)):
        for f in range(5):
            base = first + 3 * f
            expected += [wrist, base, base + 1]
    assert list(SMPLH_PARENTS) == expected
    assert SMPLH_JOINT_NAMES[36] == "left_thumb3" and SMPLH_JOINT_NAMES[51] == "right_thumb3"


def test_global_orientations_compose_down_the_tree():
    poses = np.zeros((2, 156))
    poses[:, 0:3] = Rotation.from_euler("z", 90, degrees=True).as_rotvec()  # root
    poses[1, 3:6] = Rotation.from_euler("x", 30, degrees=True).as_rotvec()  # left_hip (joint 1), frame 1 only
    q = global_orientations(poses)
    root = Rotation.from_euler("z", 90, degrees=True)
    assert (rotation_from_wxyz(q[0, 18])[0].inv() * root).magnitude() < 1e-9  # left_elbow = root at frame 0
    want = root * Rotation.from_euler("x", 30, degrees=True)
    for j in (1, 4, 7, 10):  # left_hip, left_knee, left_ankle, left_foot inherit the hip rotation
        assert (rotation_from_wxyz(q[1, j])[0].inv() * want).magnitude() < 1e-9
    assert (rotation_from_wxyz(q[1, 2])[0].inv() * root).magnitude() < 1e-9  # right_hip does not
