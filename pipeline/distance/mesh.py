"""Distance field of a triangle mesh: exact closest points with warp, and the cached field for speed.

Exact: the scaled mesh (per-axis scale applied to the vertices, x_scaled = diag(scale) x, so
distances are those of the scaled surface) is a ``warp.Mesh`` (BVH over the triangles);
``mesh_query_point_sign_winding_number`` gives the closest point c and the sign s from the
generalized winding number w(p) (s = -1 where w > 1/2: inside), except outside the mesh's
bounding box grown by :data:`BOX_MARGIN`: the solid lies in its bounds, so s = +1 there and
``mesh_query_point_no_sign`` (the same closest-point search) skips the winding number (near
the surface ~5x the cost of the search; far out the search dominates). phi = |p - c|,

    grad = s (p - c) / phi    (inside, the outward direction), or
    grad = the triangle's normal where phi <= EPS_MESH (on the surface).

Cached: :class:`pipeline.distance.octree.CachedField` holds exact samples (sd, u = p - c) on an
adaptive octree; the kernel descends to the leaf and interpolates trilinearly,

    phi = |sd~|,  grad = sign(sd~) u~ / |u~|,  closest = p - phi u~ / |u~|,

and asks the BVH instead in exact leaves, outside the sampled region, and where |sd~| is
below the near tolerance (the sign, so the grad, is not certain there). Trees are cached on
disk under :func:`pipeline.collision_mesh.cache_dir`, keyed by the file's digest, the scale
and the tree spec (a 50k-face scan takes ~40 s to sample).

One warp kernel does both, in float32, on the CPU (one thread) or on CUDA next to torch
tensors; numpy and torch inputs get the same numbers. Real scans are rarely watertight, hence the
winding number: on OMOMO's largebox (27.6k faces in 303 pieces, not watertight) the local
pseudo-normal sign (warp's ``sign_normal``) put 6.4% of random points outside its bounds "inside",
the winding number 0.02%; the pseudo-normal sign also flipped between points 5 mm apart 4x as
often, and each flip made the octree refine there, down to its finest level.
"""

from __future__ import annotations

import hashlib
import os
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from pipeline.collision_mesh import cache_dir, load_mesh
from pipeline.distance.octree import CachedField, OctreeSpec
from pipeline.distance.warp_runtime import warp as _warp
from pipeline.errors import InputError
from pipeline.geometry import MeshGeometry
from pipeline.xp import as_float, is_numpy

EPS_MESH = 1e-6  # m: below this the direction (p - c)/phi is float32 noise; the face normal is used
# m: the bounds test leaves the winding number to points this near the box, where a sheet in a
# bounding plane seen from behind gives w -> 1/2 and float32 rounding decides (as before the test).
# Beyond it the surface lies in a half-space away from p, so |w| < 1/2 unless some ray from p
# crosses it twice from behind with no crossing from the front between (a closed, consistently
# oriented surface never does; a ray through two holes or stacked sheets can): w > 1/2 there is
# read as outside, as the solid's bounds say. On OMOMO's largebox and InterMimic's
# largetable (400k points each, two scales) the field is bit-identical to the winding number's.
BOX_MARGIN = 1e-3


_KERNEL = None


def _kernel():
    """The query kernel: descend the octree, interpolate a leaf, or ask the mesh BVH."""
    global _KERNEL
    if _KERNEL is not None:
        return _KERNEL
    wp = _warp()

    @wp.func
    def closest_query(mesh: wp.uint64, p: wp.vec3, lower: wp.vec3, upper: wp.vec3) -> wp.MeshQueryPoint:
        """Closest point with the winding-number sign inside [lower, upper]; outside it, no sign (0: outside)."""
        if (
            p[0] < lower[0]
            or p[1] < lower[1]
            or p[2] < lower[2]
            or p[0] > upper[0]
            or p[1] > upper[1]
            or p[2] > upper[2]
        ):
            return wp.mesh_query_point_no_sign(mesh, p, 1.0e6)
        return wp.mesh_query_point_sign_winding_number(mesh, p, 1.0e6, 2.0, 0.5)

    @wp.kernel
    def field_query(
        mesh: wp.uint64,
        lower: wp.vec3,
        upper: wp.vec3,
        points: wp.array(dtype=wp.vec3),
        use_tree: int,
        origin: wp.vec3,
        root: float,
        nx: int,
        ny: int,
        nz: int,
        child: wp.array(dtype=wp.int32),
        leaf: wp.array(dtype=wp.int32),
        values: wp.array(dtype=wp.vec4, ndim=2),
        shell: float,
        phi: wp.array(dtype=float),
        grad: wp.array(dtype=wp.vec3),
        closest: wp.array(dtype=wp.vec3),
        exact: wp.array(dtype=wp.int8),
    ):
        i = wp.tid()
        p = points[i]
        g = (p - origin) / root
        cx = int(wp.floor(g[0]))
        cy = int(wp.floor(g[1]))
        cz = int(wp.floor(g[2]))
        done = int(0)  # noqa: UP018 - a warp dynamic variable (a bare 0 is a constant inside the loop)
        if use_tree != 0 and cx >= 0 and cy >= 0 and cz >= 0 and cx < nx and cy < ny and cz < nz:
            node = (cx * ny + cy) * nz + cz
            f = wp.vec3(g[0] - float(cx), g[1] - float(cy), g[2] - float(cz))
            while child[node] >= 0:
                bx = int(f[0] >= 0.5)
                by = int(f[1] >= 0.5)
                bz = int(f[2] >= 0.5)
                node = child[node] + bx * 4 + by * 2 + bz
                f = wp.vec3(2.0 * f[0] - float(bx), 2.0 * f[1] - float(by), 2.0 * f[2] - float(bz))
            row = leaf[node]
            if row >= 0:
                s = wp.vec4(0.0)
                for k in range(8):
                    wx = wp.where((k & 4) != 0, f[0], 1.0 - f[0])
                    wy = wp.where((k & 2) != 0, f[1], 1.0 - f[1])
                    wz = wp.where((k & 1) != 0, f[2], 1.0 - f[2])
                    s = s + (wx * wy * wz) * values[row, k]
                u = wp.vec3(s[1], s[2], s[3])
                un = wp.length(u)
                if wp.abs(s[0]) > shell and un > 0.0:
                    ph = wp.abs(s[0])
                    phi[i] = ph
                    grad[i] = u * (wp.where(s[0] < 0.0, -1.0, 1.0) / un)
                    closest[i] = p - u * (ph / un)
                    done = 1
        exact[i] = wp.int8(1 - done)
        if done == 0:
            q = closest_query(mesh, p, lower, upper)
            c = wp.mesh_eval_position(mesh, q.face, q.u, q.v)
            d = p - c
            ph = wp.length(d)
            phi[i] = ph
            closest[i] = c
            if ph <= 1.0e-6:  # EPS_MESH
                grad[i] = wp.mesh_eval_face_normal(mesh, q.face)
            else:
                grad[i] = d * (wp.where(q.sign < 0.0, -1.0, 1.0) / ph)

    _KERNEL = field_query
    return _KERNEL


@dataclass(frozen=True, eq=False)
class MeshShape:
    """A mesh's field in its (scaled) object frame: exact, or cached when ``cached`` is set."""

    path: str
    vertices: np.ndarray  # (V, 3) float64, scale applied
    faces: np.ndarray  # (F, 3) int32
    cached: CachedField | None = None
    shell: float = 0.0  # interpolated phi below this goes to the exact query (sign not certain)
    _devices: dict = field(default_factory=dict, repr=False)

    @classmethod
    def from_geometry(cls, geom: MeshGeometry, cache: bool = True, spec: OctreeSpec | None = None) -> MeshShape:
        """Load (InputError naming the file for a missing, empty or NaN mesh), scale the vertices,
        and with ``cache`` build (or load from disk) the octree field."""
        mesh = load_mesh(geom.path)
        vertices = np.asarray(mesh.vertices, dtype=np.float64) * np.asarray(geom.scale)
        faces = np.asarray(mesh.faces, dtype=np.int32)
        tri = vertices[faces]
        if not (np.linalg.norm(np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0]), axis=1) > 0).any():
            raise InputError(geom.path, "mesh", "all faces are degenerate (zero area)")
        shape = cls(str(geom.path), vertices, faces)
        if not cache:
            return shape
        spec = spec or OctreeSpec()
        return cls(shape.path, vertices, faces, _load_or_build(shape, geom, spec), spec.tol_near)

    def local(self, x, y, z, xp):
        phi, grad, closest, _ = self.detail(xp.stack([x, y, z], -1), xp)
        return phi, grad, closest

    def exact(self, p, xp):
        """Exact (phi, grad columns, closest columns) at object-frame points ``p`` (N, 3)."""
        return self.detail(p, xp, exact=True)[:3]

    def detail(self, p, xp, exact: bool = False):
        """(phi, grad columns, closest columns, exact mask): the mask says which points the mesh
        BVH answered (all with ``exact`` or without a cached field)."""
        wp = _warp()
        n = len(p)
        key = "numpy" if is_numpy(xp) else str(p.device)
        if key not in self._devices:
            self._devices[key] = self._upload(wp, "cpu" if key in ("numpy", "cpu") else key)
        dev, mesh, bounds, tree = self._devices[key]
        if is_numpy(xp):
            host = [
                np.empty(n, np.float32),
                np.empty((n, 3), np.float32),
                np.empty((n, 3), np.float32),
                np.empty(n, np.int8),
            ]
            pts = wp.array(np.ascontiguousarray(p, dtype=np.float32), dtype=wp.vec3, device="cpu")
            outs = [
                wp.array(a, dtype=t, copy=False, device="cpu")
                for a, t in zip(host, [wp.float32, wp.vec3, wp.vec3, wp.int8])
            ]
        else:
            shapes = [((n,), xp.float32), ((n, 3), xp.float32), ((n, 3), xp.float32), ((n,), xp.int8)]
            host = [xp.empty(sh, dtype=dt, device=p.device) for sh, dt in shapes]
            pts = wp.from_torch(p.to(xp.float32).contiguous(), dtype=wp.vec3)
            outs = [wp.from_torch(a, dtype=t) for a, t in zip(host, [wp.float32, wp.vec3, wp.vec3, wp.int8])]
        use = 0 if exact or self.cached is None else 1
        if n:
            wp.launch(
                _kernel(), dim=n, inputs=[mesh.id, *bounds, pts, use, *tree, self.shell], outputs=outs, device=dev
            )
            wp.synchronize_device(dev)
        phi, grad, closest = (as_float(a, xp, like=p) for a in host[:3])
        return phi, (grad[:, 0], grad[:, 1], grad[:, 2]), (closest[:, 0], closest[:, 1], closest[:, 2]), host[3] != 0

    def _upload(self, wp, dev: str):
        """(device, warp mesh, its bounds grown by BOX_MARGIN, octree kernel arguments) on ``dev``."""
        vertices = self.vertices.astype(np.float32)
        bounds = [wp.vec3(*(vertices.min(0) - BOX_MARGIN).tolist()), wp.vec3(*(vertices.max(0) + BOX_MARGIN).tolist())]
        mesh = wp.Mesh(
            points=wp.array(vertices, dtype=wp.vec3, device=dev),
            indices=wp.array(self.faces.ravel(), dtype=wp.int32, device=dev),
            support_winding_number=True,
        )
        t = self.cached
        if t is None:
            tree = [
                wp.vec3(0.0, 0.0, 0.0),
                1.0,
                0,
                0,
                0,
                wp.zeros(1, dtype=wp.int32, device=dev),
                wp.zeros(1, dtype=wp.int32, device=dev),
                wp.zeros((1, 8), dtype=wp.vec4, device=dev),
            ]
        else:
            tree = [
                wp.vec3(*[float(v) for v in t.origin]),
                float(t.root),
                *[int(v) for v in t.n],
                wp.array(t.child.astype(np.int32), dtype=wp.int32, device=dev),
                wp.array(t.leaf.astype(np.int32), dtype=wp.int32, device=dev),
                wp.array(t.values.astype(np.float32), dtype=wp.vec4, device=dev),
            ]
        return dev, mesh, bounds, tree


def _digest(path: str) -> str:
    return hashlib.sha256(Path(path).read_bytes()).hexdigest()[:16]


def _load_or_build(shape: MeshShape, geom: MeshGeometry, spec: OctreeSpec) -> CachedField:
    scale = "x".join(f"{s:.6g}" for s in geom.scale)
    key = f"dfield-{_digest(geom.path)}-s{scale}-{spec.key()}.npz"
    path = cache_dir() / key
    if path.is_file():
        return CachedField.load(path)
    tree = CachedField.build(lambda p: _numpy_exact(shape, p), shape.vertices.min(0), shape.vertices.max(0), spec)
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = path.with_suffix(f".{os.getpid()}.tmp.npz")
    tree.save(tmp)
    os.replace(tmp, path)
    return tree


def _numpy_exact(shape: MeshShape, p: np.ndarray) -> tuple[Any, np.ndarray, np.ndarray]:
    out = []
    for k in range(0, len(p), 1 << 20):
        phi, g, c = shape.exact(p[k : k + (1 << 20)], np)
        out.append((phi, np.stack(g, 1), np.stack(c, 1)))
    return tuple(np.concatenate(a) for a in zip(*out))
