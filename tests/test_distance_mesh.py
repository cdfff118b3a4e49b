"""Mesh fields: warp's exact closest points against trimesh's brute force, scale, grads, the cached
octree field against the exact one, numpy == torch, the disk cache, and bad mesh files."""

from __future__ import annotations

import functools

import numpy as np
import pytest
import torch
import trimesh
from mocap_paths import SHARED_MOCAP, needs_shared
from scipy.spatial.transform import Rotation

from pipeline.distance.field import ObjectField
from pipeline.distance.mesh import BOX_MARGIN, MeshShape
from pipeline.distance.octree import OctreeSpec
from pipeline.distance.warp_runtime import warp
from pipeline.errors import InputError
from pipeline.geometry import MeshGeometry

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


@functools.cache
def _winding_kernel():
    wp = warp()

    @wp.kernel
    def winding_everywhere(
        mesh: wp.uint64,
        points: wp.array(dtype=wp.vec3),
        phi: wp.array(dtype=float),
        grad: wp.array(dtype=wp.vec3),
        closest: wp.array(dtype=wp.vec3),
    ):
        i = wp.tid()
        p = points[i]
        q = wp.mesh_query_point_sign_winding_number(mesh, p, 1.0e6, 2.0, 0.5)
        c = wp.mesh_eval_position(mesh, q.face, q.u, q.v)
        phi[i] = wp.length(p - c)
        closest[i] = c
        grad[i] = wp.where(phi[i] <= 1.0e-6, wp.mesh_eval_face_normal(mesh, q.face), (p - c) * (q.sign / phi[i]))

    return winding_everywhere


def _winding_everywhere(shape: MeshShape, p: np.ndarray):
    """The exact field with the winding-number sign at every point (no bounds test): phi, grad, closest."""
    wp = warp()
    mesh = wp.Mesh(
        wp.array(shape.vertices.astype(np.float32), dtype=wp.vec3),
        wp.array(shape.faces.ravel(), dtype=wp.int32),
        support_winding_number=True,
    )
    out = [np.empty(len(p), np.float32), np.empty((len(p), 3), np.float32), np.empty((len(p), 3), np.float32)]
    arrays = [wp.array(a, dtype=t, copy=False, device="cpu") for a, t in zip(out, [wp.float32, wp.vec3, wp.vec3])]
    pts = wp.array(p.astype(np.float32), dtype=wp.vec3, device="cpu")
    wp.launch(_winding_kernel(), dim=len(p), inputs=[mesh.id, pts], outputs=arrays, device="cpu")
    return out


def _bounds_probe(mesh: trimesh.Trimesh, n: int) -> np.ndarray:
    """Points near the surface, in the bounds, just outside them (0-3 mm, across BOX_MARGIN) and far out."""
    rng = np.random.default_rng(4)
    lo, hi = mesh.bounds
    near = mesh.sample(n, seed=4) + rng.normal(size=(n, 3)) * rng.uniform(0, 0.05, (n, 1))
    box = rng.uniform(lo - 0.3, hi + 0.3, (n, 3))
    rim = rng.uniform(lo, hi, (n, 3))
    axis, side = rng.integers(0, 3, n), rng.integers(0, 2, n)
    rim[np.arange(n), axis] = np.where(side == 1, hi[axis], lo[axis]) + (2 * side - 1) * rng.uniform(0, 3e-3, n)
    return np.concatenate([near, box, rim])


def _assert_same_field_as_the_winding_number_everywhere(shape: MeshShape, mesh: trimesh.Trimesh, p: np.ndarray):
    lo, hi = mesh.bounds
    out = np.abs(np.clip(p, lo, hi) - p).max(1)
    assert (out > 2 * BOX_MARGIN).mean() > 0.2 and (out == 0).mean() > 0.2  # both branches of the bounds test
    phi, grad, closest = shape.exact(p, np)
    ref = _winding_everywhere(shape, p)
    assert (((p - ref[2]) * ref[1]).sum(1) < 0).any()  # some points are inside
    for a, b in zip((phi, np.stack(grad, 1), np.stack(closest, 1)), ref):
        np.testing.assert_allclose(a, b, rtol=0, atol=1e-9)


def test_bounds_test_keeps_the_field_on_a_mesh_with_holes(tmp_path):
    """Outside the bounds (+ margin) the winding number is skipped: the same phi, grad, closest as with it,
    on a non-watertight mesh (the bumpy sphere without its top cap and 10% of its faces)."""
    m = trimesh.creation.icosphere(subdivisions=4, radius=0.2)
    v = m.vertices * (1.0 + 0.15 * np.sin(5 * m.vertices[:, :1] / 0.2) * np.cos(3 * m.vertices[:, 1:2] / 0.2))
    keep = (m.triangles_center[:, 2] < 0.12) & (np.random.default_rng(6).uniform(size=len(m.faces)) > 0.1)
    mesh = trimesh.Trimesh(v, m.faces[keep], process=False)
    assert not mesh.is_watertight
    shape = MeshShape.from_geometry(MeshGeometry(_write(tmp_path, mesh)), cache=False)
    _assert_same_field_as_the_winding_number_everywhere(shape, mesh, _bounds_probe(mesh, 3000))


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
    poses = np.stack(
        [
            np.r_[RNG.normal(size=3) * 0.05, Rotation.random(random_state=k).as_quat(scalar_first=True)]
            for k in range(30)
        ]
    )
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


@needs_shared
@pytest.mark.parametrize("name", ["omomo/largebox.obj", "intermimic/largetable_largetable.obj"])
def test_real_scan_bounds_test_keeps_the_field(name):
    """Real scans (not watertight): the bounds test gives the field of the winding number everywhere."""
    path = SHARED_MOCAP / name
    mesh = trimesh.load(path, force="mesh", process=False)
    shape = MeshShape.from_geometry(MeshGeometry(str(path)), cache=False)
    _assert_same_field_as_the_winding_number_everywhere(shape, mesh, _bounds_probe(mesh, 4000))
