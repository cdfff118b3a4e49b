"""Mesh fields: warp's exact closest points against trimesh's brute force, scale, grads, the cached
octree field against the exact one, numpy == torch, the disk cache, and bad mesh files."""

from __future__ import annotations

import numpy as np
import pytest
import torch
import trimesh
from scipy.spatial.transform import Rotation

from pipeline.distance_field import ObjectField
from pipeline.distance_mesh import MeshShape
from pipeline.distance_octree import OctreeSpec
from pipeline.errors import InputError
from pipeline.geometry import MeshGeometry
from mocap_paths import SHARED_MOCAP, needs_shared

RNG = np.random.default_rng(5)
SMALL = OctreeSpec(margin=0.15, root=0.1, depth=4, tol_near=2e-3, tol_far=1e-2)  # builds in ~2 s
IDENTITY = np.array([0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0])


@pytest.fixture(scope="module", autouse=True)
def _cache(tmp_path_factory):
    with pytest.MonkeyPatch.context() as mp:  # trees built once for the module
        mp.setenv("LESSMIMIC_CACHE", str(tmp_path_factory.mktemp("cache")))
        yield


def _write(tmp_path, mesh: trimesh.Trimesh, name: str = "obj.obj") -> str:
    path = tmp_path / name
    mesh.export(path)
    return str(path)


@pytest.fixture(scope="module")
def bumpy(tmp_path_factory) -> tuple[str, trimesh.Trimesh]:
    """A closed, non-convex mesh: an icosphere with dents and bumps, 1280 faces."""
    m = trimesh.creation.icosphere(subdivisions=3, radius=0.2)
    v = m.vertices * (1.0 + 0.15 * np.sin(5 * m.vertices[:, :1] / 0.2) * np.cos(3 * m.vertices[:, 1:2] / 0.2))
    mesh = trimesh.Trimesh(v, m.faces, process=False)
    return _write(tmp_path_factory.mktemp("mesh"), mesh), mesh


def _inside(mesh: trimesh.Trimesh, p: np.ndarray) -> np.ndarray:
    """Winding number > 1/2 (solid angles of the triangles seen from p, Van Oosterom-Strackee)."""
    a, b, c = (mesh.triangles[None, :, k] - p[:, None] for k in range(3))
    la, lb, lc = (np.linalg.norm(x, axis=-1) for x in (a, b, c))
    num = (a * np.cross(b, c)).sum(-1)
    den = la * lb * lc + (a * b).sum(-1) * lc + (a * c).sum(-1) * lb + (b * c).sum(-1) * la
    return np.arctan2(num, den).sum(1) / (2 * np.pi) > 0.5


def _brute(mesh: trimesh.Trimesh, p: np.ndarray):
    closest, dist, _ = trimesh.proximity.closest_point_naive(mesh, p)
    return dist, closest


def test_exact_mesh_distance_matches_trimesh_with_pose_and_per_axis_scale(bumpy):
    path, mesh = bumpy
    scale = (1.5, 0.8, 0.6)
    field = ObjectField.from_geometry(MeshGeometry(path, scale), name="bumpy", cache=False)
    scaled = trimesh.Trimesh(mesh.vertices * scale, mesh.faces, process=False)  # the scale goes on the vertices
    pose = np.r_[0.3, -0.2, 0.5, Rotation.random(random_state=2).as_quat(scalar_first=True)]
    R = Rotation.from_quat(pose[3:], scalar_first=True).as_matrix()
    local = RNG.uniform(-0.3, 0.3, (300, 3)) * [1.2, 0.7, 0.6]
    s = field.query(local @ R.T + pose[:3], pose)
    dist, closest = _brute(scaled, local)
    np.testing.assert_allclose(s.phi, dist, atol=2e-6)
    c_local = (s.closest - pose[:3]) @ R  # (with two equidistant points warp and trimesh may differ)
    np.testing.assert_allclose(np.linalg.norm(local - c_local, axis=1), dist, atol=2e-6)
    assert _brute(scaled, c_local)[0].max() < 1e-6
    # grad: (x - c)/phi outside, the outward direction (c - x)/phi inside
    inside = _inside(scaled, local)
    assert 0.1 < inside.mean() < 0.9
    g_local = s.grad @ R
    u = local - c_local
    np.testing.assert_allclose(g_local[~inside] * dist[~inside, None], u[~inside], atol=2e-5)
    np.testing.assert_allclose(g_local[inside] * dist[inside, None], -u[inside], atol=2e-5)


def test_grad_on_the_mesh_surface_is_the_face_normal(bumpy):
    path, mesh = bumpy
    shape = MeshShape.from_geometry(MeshGeometry(path), cache=False)
    faces = RNG.choice(len(mesh.faces), 100, replace=False)
    bary = RNG.dirichlet([1, 1, 1], 100)
    p = (mesh.triangles[faces] * bary[:, :, None]).sum(1)
    phi, g, _ = shape.exact(p, np)
    assert phi.max() < 1e-6
    np.testing.assert_allclose(np.stack(g, 1), mesh.face_normals[faces], atol=1e-5)


def test_cached_field_meets_its_tolerances_and_falls_back_outside_the_grid(bumpy):
    path, mesh = bumpy
    cached = MeshShape.from_geometry(MeshGeometry(path), spec=SMALL)
    exact = MeshShape.from_geometry(MeshGeometry(path), cache=False)
    near = mesh.sample(2000, seed=1) + RNG.normal(size=(2000, 3)) * RNG.uniform(0, 0.05, (2000, 1))
    far = RNG.uniform(-0.35, 0.35, (2000, 3))
    away = RNG.uniform(0.6, 1.0, (50, 3))  # beyond bounds + margin
    p = np.concatenate([near, far, away])
    phi, g, c, used_exact = cached.detail(p, np)
    e_phi, e_g, _ = exact.exact(p, np)
    band = e_phi <= SMALL.band
    err = np.abs(phi - e_phi)
    assert err[band].max() <= 2 * SMALL.tol_near and err[~band].max() <= 2 * SMALL.tol_far
    assert used_exact[-50:].all() and used_exact[:-50].mean() < 0.5
    np.testing.assert_allclose(np.linalg.norm(np.stack(c, 1) - p, axis=1), phi, atol=1e-6)
    outside = ~_inside(mesh, p)
    gerr = np.linalg.norm(np.stack(g, 1) - np.stack(e_g, 1), axis=1)
    assert np.median(gerr[outside]) < 0.1  # grad is not a refinement criterion (see distance_octree)


def test_disk_cache_gives_the_same_field(bumpy, tmp_path, monkeypatch):
    monkeypatch.setenv("LESSMIMIC_CACHE", str(tmp_path / "cache"))
    path, _ = bumpy
    a = MeshShape.from_geometry(MeshGeometry(path), spec=SMALL)
    files = list((tmp_path / "cache").glob("dfield-*.npz"))
    assert len(files) == 1
    b = MeshShape.from_geometry(MeshGeometry(path), spec=SMALL)
    assert list((tmp_path / "cache").glob("dfield-*.npz")) == files
    np.testing.assert_array_equal(a.cached.values, b.cached.values)
    MeshShape.from_geometry(MeshGeometry(path, (1.0, 1.0, 2.0)), spec=SMALL)  # another scale, another tree
    assert len(list((tmp_path / "cache").glob("dfield-*.npz"))) == 2


@pytest.mark.parametrize("cache", [False, True])
def test_numpy_and_torch_agree_on_meshes(bumpy, cache):
    path, _ = bumpy
    field = ObjectField.from_geometry(MeshGeometry(path, (1.2, 1.0, 0.9)), cache=cache, spec=SMALL)
    p = RNG.uniform(-0.4, 0.4, (30, 50, 3))
    poses = np.stack([np.r_[RNG.normal(size=3) * 0.05, Rotation.random(random_state=k).as_quat(scalar_first=True)] for k in range(30)])
    a = field.query_links(p, poses)
    for dev in ["cpu"] + (["cuda"] if torch.cuda.is_available() else []):
        b = field.query_links(torch.as_tensor(p, device=dev), torch.as_tensor(poses, device=dev))
        for x, y in zip(a, b):
            np.testing.assert_allclose(y.cpu().numpy(), x, atol=1e-5)


def test_empty_or_nan_mesh_files_are_input_errors_naming_the_file(tmp_path):
    empty = tmp_path / "empty.obj"
    empty.write_text("v 0 0 0\nv 1 0 0\nv 0 1 0\nv 0 0 1\n")
    with pytest.raises(InputError, match=r"empty\.obj: mesh: object mesh is empty"):
        ObjectField.from_geometry(MeshGeometry(str(empty)))
    bad = tmp_path / "nan.obj"
    bad.write_text("v 0 0 0\nv 1 0 0\nv 0 nan 0\nv 0 0 1\nf 1 2 3\nf 1 2 4\n")
    with pytest.raises(InputError, match=r"nan\.obj: mesh vertices: contain NaN"):
        ObjectField.from_geometry(MeshGeometry(str(bad)))
    flat = tmp_path / "flat.obj"
    flat.write_text("v 0 0 0\nv 1 0 0\nv 2 0 0\nv 3 0 0\nf 1 2 3\nf 2 3 4\n")
    with pytest.raises(InputError, match=r"flat\.obj: mesh: all faces are degenerate"):
        ObjectField.from_geometry(MeshGeometry(str(flat)))


@needs_shared
def test_real_scan_exact_distance_matches_trimesh():
    path = SHARED_MOCAP / "omomo" / "largebox.obj"
    mesh = trimesh.load(path, force="mesh", process=False)
    field = ObjectField.from_geometry(MeshGeometry(str(path)), cache=False)
    p = mesh.sample(40, seed=3) + RNG.normal(size=(40, 3)) * 0.05
    dist, closest = _brute(mesh, p)
    s = field.query(p, IDENTITY)
    np.testing.assert_allclose(s.phi, dist, atol=2e-6)


@needs_shared
def test_real_scan_outside_is_outside():
    """OMOMO's largebox is not watertight (303 pieces): points 5-30 cm outside its bounds must
    still be outside (grad along p - closest). The pseudo-normal sign got 6.4% of them wrong."""
    path = SHARED_MOCAP / "omomo" / "largebox.obj"
    lo, hi = trimesh.load(path, force="mesh", process=False).bounds
    field = ObjectField.from_geometry(MeshGeometry(str(path)), cache=False)
    p = RNG.uniform(lo - 0.3, hi + 0.3, (20000, 3))
    p = p[np.abs(np.clip(p, lo, hi) - p).max(1) > 0.05]
    s = field.query(p, IDENTITY)
    assert (((p - s.closest) * s.grad).sum(1) > 0).all()
