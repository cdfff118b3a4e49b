"""Generic keypoints (.npz / .csv), the shared unit and up-axis helpers, and the height estimate
(pipeline.body_height)."""

import numpy as np
import pytest
from mocap_paths import expect_input_error

from pipeline.body_height import estimate_height
from pipeline.clip import Skeleton
from pipeline.readers.keypoints import guess_units, read_keypoints_csv, read_keypoints_npz

NAMES = ["pelvis", "spine", "head", "left_knee", "left_ankle"]
PARENTS = [-1, 0, 1, 0, 3]
STAND = np.array([[0, 0, 0.95], [0, 0, 1.30], [0, 0, 1.58], [0, 0.1, 0.50], [0, 0.1, 0.08]])  # metres, z-up


def _frames(T=5, scale=1.0, y_up=False):
    pos = np.repeat(STAND[None], T, 0).copy()
    pos[:, :, 0] += np.linspace(0, 0.4, T)[:, None]  # walking forward
    if y_up:
        pos = pos[..., [0, 2, 1]] * [1, 1, -1]  # (x, y, z)_zup -> (x, z, -y)_yup
    return pos * scale


def test_npz_cm_y_up(tmp_path):
    p = tmp_path / "k.npz"
    np.savez(p, joint_pos=_frames(scale=100, y_up=True), joint_names=NAMES, parents=PARENTS, fps=25, units="cm", up="y")
    c = read_keypoints_npz(p)
    np.testing.assert_allclose(c.joint_pos, _frames(), atol=1e-12)
    assert c.fps == 25 and c.skeleton.parents == tuple(PARENTS)
    # head-to-ankle path 0.28 + 0.35 + 0.45 + 0.42 (+0.1 lateral) m, times the stature factor
    assert c.subject_height == pytest.approx(1.118 * (0.28 + 0.35 + np.hypot(0.45, 0.1) + 0.42), rel=1e-6)


def test_npz_auto_units_and_positions_key(tmp_path):
    p = tmp_path / "k.npz"
    np.savez(p, positions=_frames(scale=1000), joint_names=NAMES, parents=PARENTS, units="auto")
    c = read_keypoints_npz(p, fps=60)
    np.testing.assert_allclose(c.joint_pos, _frames(), atol=1e-12)  # mm guessed from the height
    assert guess_units(67.0) == "inch" and guess_units(170.0) == "cm" and guess_units(1.7) == "m"


def test_estimate_height_needs_head_and_ankle():
    assert estimate_height(_frames(), Skeleton(("a", "b", "c", "d", "e"), (-1, 0, 1, 0, 3))) is None


def _csv(tmp_path, lines, name="k.csv"):
    p = tmp_path / name
    p.write_text("\n".join(lines) + "\n")
    return p


HEADER = "frame,time," + ",".join(f"{n}_x,{n}_y,{n}_z" for n in NAMES)


def _rows(T=4, dt=0.01):
    pos = _frames(T)
    return [f"{t},{t * dt:.4f}," + ",".join(f"{v:.6f}" for v in pos[t].ravel()) for t in range(T)]


def test_csv_time_column_and_fps_argument(tmp_path):
    c = read_keypoints_csv(_csv(tmp_path, [HEADER] + _rows()))
    assert c.fps == pytest.approx(100.0) and c.skeleton.joint_names == tuple(NAMES)
    np.testing.assert_allclose(c.joint_pos, _frames(4), atol=1e-6)
    no_time = [",".join(h for h in HEADER.split(",") if h != "time")] + [
        ",".join(r.split(",")[:1] + r.split(",")[2:]) for r in _rows()
    ]
    assert read_keypoints_csv(_csv(tmp_path, no_time, "n.csv"), fps=30).fps == 30


def test_bad_keypoint_files(tmp_path):
    p = tmp_path / "nonames.npz"
    np.savez(p, joint_pos=_frames(), fps=30)
    expect_input_error(lambda: read_keypoints_npz(p), tmp_path, file=p, field="joint_names", match="missing")
    o = tmp_path / "objnames.npz"
    np.savez(o, joint_pos=_frames(), joint_names=np.array(NAMES, dtype=object), fps=30)
    expect_input_error(
        lambda: read_keypoints_npz(o), tmp_path, file=o, field="joint_names", match="pickled object array"
    )
    bad = _frames()
    bad[3, 2, 1] = np.nan
    q = tmp_path / "nan.npz"
    np.savez(q, joint_pos=bad, joint_names=NAMES, fps=30)
    expect_input_error(lambda: read_keypoints_npz(q), tmp_path, file=q, field="joint_pos[head]", frame=3, match="NaN")
    rows = _rows()
    rows[2] = rows[2].rsplit(",", 1)[0]
    r = _csv(tmp_path, [HEADER] + rows, "short.csv")
    expect_input_error(
        lambda: read_keypoints_csv(r),
        tmp_path,
        file=r,
        field="row 4",
        frame=2,
        match="has 16 columns, the header has 17",
    )
    rows = _rows()
    cells = rows[1].split(",")
    cells[5] = "nan"  # spine_x
    rows[1] = ",".join(cells)
    s = _csv(tmp_path, [HEADER] + rows, "nan.csv")
    expect_input_error(lambda: read_keypoints_csv(s), tmp_path, file=s, field="joint_pos[spine]", frame=1, match="NaN")
    no_time = [HEADER.replace("time,", "")] + [",".join(x.split(",")[:1] + x.split(",")[2:]) for x in _rows()]
    u = _csv(tmp_path, no_time, "nofps.csv")
    expect_input_error(lambda: read_keypoints_csv(u), tmp_path, file=u, field="fps", match="pass --fps N")
    assert read_keypoints_csv(u, fps=30).fps == 30  # what lessmimic retarget --fps 30 passes
    v = _csv(tmp_path, ["frame,head_x,head_y"] + ["0,1,2"], "header.csv")
    expect_input_error(lambda: read_keypoints_csv(v, fps=30), tmp_path, file=v, field="header")


def test_csv_time_column_must_increase_uniformly(tmp_path):
    rows = _rows(5)
    cells = rows[3].split(",")
    cells[1] = "0.0100"  # frame 3 goes back in time
    rows[3] = ",".join(cells)
    p = _csv(tmp_path, [HEADER] + rows, "back.csv")
    expect_input_error(lambda: read_keypoints_csv(p), tmp_path, file=p, field="time", frame=3, match="not increasing")
    rows = _rows(5)
    cells = rows[4].split(",")
    cells[1] = "0.0900"  # a dropped stretch: 0, .01, .02, .03, .09
    rows[4] = ",".join(cells)
    q = _csv(tmp_path, [HEADER] + rows, "gap.csv")
    expect_input_error(lambda: read_keypoints_csv(q), tmp_path, file=q, field="time", match="not uniformly sampled")
    assert read_keypoints_csv(q, fps=100).fps == 100  # --fps N: the rows read at N Hz, as the message says
    one = _csv(tmp_path, [HEADER] + _rows(1), "one.csv")
    expect_input_error(lambda: read_keypoints_csv(one), tmp_path, file=one, field="time", match="at least two rows")
