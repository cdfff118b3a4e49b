"""OMOMO / InterMimic reader: body order, global quaternions, contacts against the mesh, bad files."""

import shutil

import numpy as np
import pytest
import torch
from mocap_paths import SHARED_MOCAP, expect_input_error, needs_shared
from scipy.spatial import cKDTree

from pipeline.readers.amass import SMPLH_JOINT_NAMES
from pipeline.readers.omomo import COLUMNS, CONCAVITY_GAP, collision_kind, hull_gap_ratio, parse_name, read_omomo
from pipeline.rotations import rotation_from_wxyz

BOX = SHARED_MOCAP / "omomo" / "sub3_largebox_003.pt"
TABLE = SHARED_MOCAP / "intermimic" / "sub2_largetable_000.pt"


def _distances_to_mesh(clip, joints, samples=200_000):
    """Distance of each listed joint to the object's surface, every frame (surface sampled
    densely: error below ~3 mm; trimesh's exact query needs rtree, which is not installed)."""
    import trimesh

    obj = clip.objects[0]
    mesh = trimesh.load(obj.geometry.path, force="mesh", process=False)
    pts, _ = trimesh.sample.sample_surface(mesh, samples, seed=0)
    tree = cKDTree(np.vstack([pts, mesh.vertices]))
    idx = [clip.skeleton.index(j) for j in joints]
    rot = rotation_from_wxyz(obj.pose[:, 3:])
    local = np.einsum("tji,tkj->tki", rot.as_matrix(), clip.joint_pos[:, idx] - obj.pose[:, None, :3])  # R^T (p - o)
    return tree.query(local.reshape(-1, 3))[0].reshape(clip.frames, len(idx))


@pytest.fixture(scope="module")
def box_clip():
    if not BOX.is_file():
        pytest.skip(f"{BOX} not found")
    return read_omomo(BOX)


@needs_shared
def test_box_clip_layout(box_clip):
    c = box_clip
    assert c.frames == 196 and c.fps == 30.0 and c.skeleton.joint_names == SMPLH_JOINT_NAMES
    assert c.subject_height == pytest.approx(1.941, abs=1e-3)  # height_dict.pkl beside the clip
    obj = c.objects[0]
    assert obj.name == "largebox" and obj.geometry.path.endswith("largebox.obj") and obj.geometry.collision == "hull"
    assert obj.contact.mean() == pytest.approx(164 / 196)
    p = c.joint_pos
    # SMPL-H order after the permutation: left_foot (10) is at the floor, head (15) on top.
    assert np.median(p[:, 10, 2]) < 0.15 and np.all(p[:, 15, 2] > p[:, 0, 2])


@needs_shared
def test_body_quaternions_are_global(box_clip):
    """With global orientations, every bone expressed in its parent's frame is constant in time."""
    c = box_clip
    for j, parent in enumerate(c.skeleton.parents):
        if parent < 0:
            continue
        local = rotation_from_wxyz(c.joint_quat[:, parent]).inv().apply(c.joint_pos[:, j] - c.joint_pos[:, parent])
        assert local.std(axis=0).max() < 1e-4, c.skeleton.joint_names[j]
    # ... whereas the world-frame bone vectors move (the test could fail).
    assert np.ptp(c.joint_pos[:, 4] - c.joint_pos[:, 1], axis=0).max() > 0.1


@needs_shared
def test_hands_touch_the_box_when_flagged(box_clip):
    c = box_clip
    d = _distances_to_mesh(c, ["left_middle3", "right_middle3"])
    for side, col in (("left", 0), ("right", 1)):
        flag = c.contacts[:, c.skeleton.index(f"{side}_middle3")]
        assert flag.sum() > 100
        near, far = np.median(d[flag, col]), np.median(d[~flag, col])
        print(f"{side} fingertip to box surface: {near * 100:.1f} cm in contact frames, {far * 100:.1f} cm otherwise")
        assert near < 0.05 and far > 0.1


@needs_shared
def test_feet_on_the_floor(box_clip):
    p = box_clip.joint_pos
    lowest = p[:, :, 2].min(axis=1)
    assert np.all(lowest > 0.0) and np.median(lowest) < 0.12  # joint centres a few cm above the sole
    toes = p[:, [SMPLH_JOINT_NAMES.index("left_foot"), SMPLH_JOINT_NAMES.index("right_foot")], 2]
    assert toes.min() < 0.08


@needs_shared
def test_intermimic_table():
    c = read_omomo(TABLE)
    obj = c.objects[0]
    assert c.frames == 153 and obj.name == "largetable" and obj.geometry.path.endswith("largetable_largetable.obj")
    assert obj.geometry.collision == "decomposition"
    assert obj.contact.mean() == pytest.approx(0.75, abs=0.01)
    from pipeline.readers.keypoints import load_numpy_pickle

    true = float(load_numpy_pickle(SHARED_MOCAP / "omomo" / "height_dict.pkl")["sub2"])
    assert c.subject_height == pytest.approx(true, rel=0.02)  # no height_dict here: skeleton estimate
    d = _distances_to_mesh(c, ["left_middle3", "right_middle3"])
    touching = obj.contact
    print(
        f"fingertips to table: {np.median(d[touching]) * 100:.1f} cm in contact frames, "
        f"{np.median(d[~touching]) * 100:.1f} cm otherwise"
    )
    assert np.median(d[touching].min(axis=1)) < 0.06 and np.median(d[~touching].min(axis=1)) > 0.15


@needs_shared
def test_geometric_rule_agrees_with_names():
    import trimesh

    box = trimesh.load(SHARED_MOCAP / "omomo" / "largebox.obj", force="mesh", process=False)
    table = trimesh.load(SHARED_MOCAP / "intermimic" / "largetable_largetable.obj", force="mesh", process=False)
    assert hull_gap_ratio(box) < CONCAVITY_GAP < hull_gap_ratio(table)


def test_parse_name_and_collision_rule():
    assert parse_name("a/sub3_largebox_003.pt") == ("sub3", "largebox")
    assert parse_name("sub10_largebox_003_080_080_080.pt") == ("sub10", "largebox")
    assert parse_name("sub2_large_table_000.pt") == ("sub2", "large_table")
    assert parse_name("walk.pt") == (None, None)
    import trimesh

    cube, cylinder = trimesh.creation.box([1, 1, 1]), trimesh.creation.cylinder(0.3, 1.0)
    slab = lambda size, at: trimesh.creation.box(size).apply_translation(at)  # noqa: E731
    trough = trimesh.util.concatenate(
        [slab([1, 1, 0.05], [0, 0, -0.475]), slab([0.05, 1, 1], [-0.475, 0, 0]), slab([0.05, 1, 1], [0.475, 0, 0])]
    )
    assert collision_kind("thing", cube) == "hull" and collision_kind("thing", cylinder) == "hull"
    assert collision_kind("thing", trough) == "decomposition"
    assert collision_kind("smallbox", trough) == "hull" and collision_kind("woodchair", cube) == "decomposition"


def _tensor(T=6):
    a = np.zeros((T, COLUMNS), np.float32)
    a[:, 162:318] = np.tile(np.linspace(0, 1.7, 52), 3)  # any finite positions
    a[:, 321:325] = [0, 0, 0, 1]
    a[:, 383:591] = np.tile([0, 0, 0, 1], 52)
    return a


def _save(tmp_path, a, name="sub1_box_001.pt"):
    p = tmp_path / name
    torch.save(torch.from_numpy(np.asarray(a)), p)
    return p


def test_bad_tensors(tmp_path):
    p = _save(tmp_path, np.zeros((5, 100), np.float32))
    expect_input_error(lambda: read_omomo(p), tmp_path, file=p, field="tensor", match=r"\(5, 100\) is not \(T, 591\)")
    p = _save(tmp_path, np.zeros((0, COLUMNS), np.float32), "sub1_box_002.pt")
    expect_input_error(lambda: read_omomo(p), tmp_path, file=p, field="tensor", match="zero frames")
    a = _tensor()
    a[3, 200] = np.nan
    p = _save(tmp_path, a, "sub1_box_003.pt")
    expect_input_error(lambda: read_omomo(p), tmp_path, file=p, field="body positions (columns 162:318)", frame=3)
    p = tmp_path / "sub1_box_004.pt"
    torch.save({"not": "a tensor"}, p)
    expect_input_error(lambda: read_omomo(p), tmp_path, file=p, field="file", match="holds a dict")


def test_missing_and_empty_mesh(tmp_path):
    p = _save(tmp_path, _tensor())
    expect_input_error(
        lambda: read_omomo(p), tmp_path, file=p, field="mesh", match=r"no mesh for object 'box'.*box\.obj"
    )
    (tmp_path / "box.obj").write_text("")
    expect_input_error(lambda: read_omomo(p), tmp_path, file=p, field="mesh", match=r"box\.obj")
    expect_input_error(
        lambda: read_omomo(p, mesh=tmp_path / "nope.obj"), tmp_path, file=p, field="mesh", match="does not exist"
    )


@needs_shared
def test_explicit_mesh_and_renamed_clip(tmp_path):
    clip = tmp_path / "myclip.pt"
    shutil.copy(BOX, clip)
    c = read_omomo(clip, mesh=SHARED_MOCAP / "omomo" / "largebox.obj")
    assert c.objects[0].name == "largebox"  # no object in the file name: the mesh's name
    assert c.subject_height is not None and 1.85 < c.subject_height < 2.0  # estimated: 1.947 vs 1.941 true
