"""The LessMimic viewer's distance field: an unsigned distance sampled on a voxel grid per object, looked up by
trilinear interpolation (facts 2 of :mod:`train.export.demo_loop`: the viewer's ``sdfHelper.js`` and
``precompute_sdf.py``, read as facts), built here from our own exact fields.

**Grid** (:class:`VoxelGrid`, facts 2 "JSON format"): ``n = (nx, ny, nz)`` nodes over ``[bbox_min, bbox_max]``,
node-centred like a linspace, node ``i`` at ``bbox_min + i voxel`` with ``voxel = (bbox_max - bbox_min) / (n - 1)``;
the values are unsigned distances ``min(|phi|, max)`` (inside a solid: the depth, positive), stored x-major,
z fastest (numpy C order of an ``indexing='ij'`` meshgrid). :func:`build_grid` samples one of our objects' exact
field (:class:`pipeline.distance.field.ObjectField`, the one the CPU environment queries) at rest in its own frame
on a ``40^3`` grid over its bounding box padded by 1 m, as the viewer's ``precompute_sdf.py`` does for its assets.

**Lookup** (:meth:`VoxelGrid.lookup`, facts 2 "Lookup"): grid coordinate ``g = (p - bbox_min) / voxel``;

* outside the grid (any ``g < 0`` or ``g > n - 1``): ``(max, 0)``;
* ``d(g)`` trilinear over the 8 neighbouring nodes (integer indices clamped to ``[0, n - 1]``);
  ``d >= max``: ``(max, 0)``;
* gradient by central differences of the *interpolated* field, one voxel each way,
  ``grad_a = (d(g + e_a) - d(g - e_a)) / (2 voxel_a)`` with the two samples' coordinates clamped to
  ``[0, n - 1]`` but the divisor always ``2 voxel_a``; then ``grad / |grad|`` when ``|grad| > 1e-6``, else raw.

**Several objects** (:func:`query_objects`, facts 2 "Object pose" and "Choosing the closest object"): a world point
goes to each object's frame, ``p = R^T (x - t)`` (scale 1), its gradient back to the world, ``R grad``; every point
starts at ``(max, 0)`` and takes an object's result only when strictly smaller, objects in the given order.
:func:`body_frame` turns the world gradients into each query body's frame, ``R_body^T grad``, with ``R_body`` the
body's ``xquat`` (facts 2, interactionPolicyRunner.js:258-278).

Interpolation error: the exact distance is 1-Lipschitz, so the trilinear value (a convex combination of the 8
corner values) is within the voxel's diagonal of it anywhere, and within ``O(voxel^2 / r)`` where the field is
smooth (``r`` the distance to the surface); the kinks (the surface's edges, the inside's medial planes) are where
it is largest.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from pipeline.distance.field import ObjectField
from pipeline.geometry import Chair, MeshGeometry, ObjectGeometry, Primitive
from pipeline.terms.observations import rotation_matrix

GRID_NODES = 40  #: nodes per axis of the viewer's asset grids (facts 2, precompute_sdf.py: grid 40)
PADDING_M = 1.0  #: the bounding box's padding (facts 2: padding 1.0)
MAX_DISTANCE_M = 1.0  #: ``sdf.max_valid_distance`` (facts 2, json:25)
GRAD_EPS = 1e-6  #: below this gradient norm the gradient is left unnormalised (facts 2, sdfHelper.js:108-126)
IDENTITY_POSE = np.array([0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0])


@dataclass(frozen=True, eq=False)
class VoxelGrid:
    """One object's grid in its own frame (module docstring): ``distances`` (nx, ny, nz) float32, x-major, z
    fastest; ``bbox_min``/``bbox_max`` (3,) the first and last nodes."""

    grid_size: tuple[int, int, int]
    bbox_min: np.ndarray
    bbox_max: np.ndarray
    distances: np.ndarray

    def __post_init__(self):
        if self.distances.shape != tuple(self.grid_size) or min(self.grid_size) < 2:
            raise ValueError(f"distances {self.distances.shape} do not match grid_size {self.grid_size}")

    @property
    def voxel(self) -> np.ndarray:
        """(3,) node spacing ``(bbox_max - bbox_min) / (n - 1)``."""
        return (self.bbox_max - self.bbox_min) / (np.asarray(self.grid_size) - 1)

    def flat(self) -> np.ndarray:
        """The values as the viewer's file stores them: index ``ix ny nz + iy nz + iz``."""
        return self.distances.reshape(-1)

    def trilinear(self, g: np.ndarray) -> np.ndarray:
        """(N,) the interpolated distance at grid coordinates ``g`` (N, 3) inside ``[0, n - 1]``."""
        top = np.asarray(self.grid_size) - 1
        base = np.floor(g)
        f = g - base
        i0 = np.clip(base.astype(int), 0, top)
        i1 = np.clip(i0 + 1, 0, top)
        out = np.zeros(len(g))
        for cx in (0, 1):
            for cy in (0, 1):
                for cz in (0, 1):
                    w = (f[:, 0] if cx else 1 - f[:, 0]) * (f[:, 1] if cy else 1 - f[:, 1])
                    w = w * (f[:, 2] if cz else 1 - f[:, 2])
                    ix, iy, iz = (i1[:, a] if c else i0[:, a] for a, c in enumerate((cx, cy, cz)))
                    out += w * self.distances[ix, iy, iz]
        return out

    def lookup(self, points: np.ndarray, max_distance: float = MAX_DISTANCE_M) -> tuple[np.ndarray, np.ndarray]:
        """``(d (N,), grad (N, 3))`` at object-frame ``points`` (N, 3): the viewer's lookup (module docstring)."""
        voxel, top = self.voxel, np.asarray(self.grid_size) - 1.0
        g = (np.asarray(points, dtype=float).reshape(-1, 3) - self.bbox_min) / voxel
        inside = ((g >= 0) & (g <= top)).all(axis=1)
        d, grad = np.full(len(g), float(max_distance)), np.zeros((len(g), 3))
        if not inside.any():
            return d, grad
        gi = g[inside]
        di = self.trilinear(gi)
        gr = np.zeros((len(gi), 3))
        for a in range(3):
            plus, minus = gi.copy(), gi.copy()
            plus[:, a] = np.clip(gi[:, a] + 1.0, 0.0, top[a])
            minus[:, a] = np.clip(gi[:, a] - 1.0, 0.0, top[a])
            gr[:, a] = (self.trilinear(plus) - self.trilinear(minus)) / (2.0 * voxel[a])
        norm = np.linalg.norm(gr, axis=1, keepdims=True)
        gr = np.where(norm > GRAD_EPS, gr / np.maximum(norm, GRAD_EPS), gr)
        near = di < max_distance
        rows = np.flatnonzero(inside)[near]
        d[rows], grad[rows] = di[near], gr[near]
        return d, grad


def object_bounds(geometry: ObjectGeometry) -> tuple[np.ndarray, np.ndarray]:
    """``(lo, hi)`` (3,) the object's axis-aligned bounding box in its own frame (scale applied): a primitive's
    ``+-half_extents``; a chair's parts' union (its frame is on the floor); a mesh's scaled vertex bounds."""
    if isinstance(geometry, Primitive):
        half = np.asarray(geometry.half_extents, dtype=float)
        return -half, half
    if isinstance(geometry, Chair):
        parts = geometry.parts()
        lo = np.min([c - np.asarray(p.half_extents) for _, p, c in parts], axis=0)
        hi = np.max([c + np.asarray(p.half_extents) for _, p, c in parts], axis=0)
        return lo, hi
    if isinstance(geometry, MeshGeometry):
        from pipeline.collision_mesh import load_mesh

        bounds = np.asarray(load_mesh(geometry.path).bounds) * np.asarray(geometry.scale)
        return bounds.min(axis=0), bounds.max(axis=0)
    raise TypeError(f"no bounds for {type(geometry).__name__}")


def build_grid(
    geometry: ObjectGeometry,
    field: ObjectField,
    nodes: int = GRID_NODES,
    padding: float = PADDING_M,
    max_distance: float = MAX_DISTANCE_M,
) -> VoxelGrid:
    """The viewer's grid of one object: ``field`` (the object's exact field, at rest in its own frame) sampled on
    ``nodes^3`` nodes over :func:`object_bounds` padded by ``padding``, storing ``min(|phi|, max_distance)``."""
    lo, hi = object_bounds(geometry)
    lo, hi = lo - padding, hi + padding
    axes = [np.linspace(lo[a], hi[a], nodes) for a in range(3)]
    points = np.stack(np.meshgrid(*axes, indexing="ij"), -1).reshape(-1, 3)
    phi = np.asarray(field.query(points, IDENTITY_POSE).phi, dtype=float)
    values = np.minimum(np.abs(phi), max_distance).astype(np.float32).reshape(nodes, nodes, nodes)
    return VoxelGrid((nodes, nodes, nodes), lo, hi, values)


def query_objects(
    grids: list[VoxelGrid] | tuple[VoxelGrid, ...],
    poses: np.ndarray,
    points: np.ndarray,
    max_distance: float = MAX_DISTANCE_M,
) -> tuple[np.ndarray, np.ndarray]:
    """``(d (N,), grad (N, 3) world)`` at world ``points`` (N, 3) over the objects ``grids`` at ``poses`` (M, 7)
    (x, y, z, qw, qx, qy, qz): each point the strictly nearest object, in order, else ``(max, 0)``."""
    points = np.asarray(points, dtype=float).reshape(-1, 3)
    d, grad = np.full(len(points), float(max_distance)), np.zeros((len(points), 3))
    if not len(grids):
        return d, grad
    rots = rotation_matrix(np.asarray(poses, dtype=float)[:, 3:7])
    for grid, pose, R in zip(grids, poses, rots):
        local = (points - pose[:3]) @ R  # R^T (x - t), row by row
        dl, gl = grid.lookup(local, max_distance)
        nearer = dl < d
        d[nearer], grad[nearer] = dl[nearer], (gl @ R.T)[nearer]
    return d, grad


def body_frame(grad: np.ndarray, body_quat: np.ndarray) -> np.ndarray:
    """(N, 3) world vectors ``grad`` (N, 3) in the frames of bodies of orientation ``body_quat`` (N, 4) wxyz:
    ``R_body^T grad``."""
    return np.einsum("nji,nj->ni", rotation_matrix(np.asarray(body_quat, dtype=float)), grad)
