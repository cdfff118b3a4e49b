"""Distance fields of the scene's objects: phi, grad phi and the closest surface point at query points.

* :mod:`~pipeline.distance.field` -- :class:`ObjectField`, one object's exact field (the entry point);
* :mod:`~pipeline.distance.primitive` -- analytic boxes, spheres, capsules, cylinders (numpy / torch);
* :mod:`~pipeline.distance.ellipsoid` -- scaled primitives: exact distance to an ellipsoid;
* :mod:`~pipeline.distance.mesh` -- meshes: warp closest point, or :mod:`~pipeline.distance.octree`;
* :mod:`~pipeline.distance.box_warp`, :mod:`~pipeline.distance.scaled_warp`,
  :mod:`~pipeline.distance.ellipsoid_warp` -- the same fields as warp kernels (CPU or GPU);
* :mod:`~pipeline.distance.warp_runtime` -- warp start-up.

The fields are written over numpy or torch arrays alike (:mod:`pipeline.xp`).
"""
