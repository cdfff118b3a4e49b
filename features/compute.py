"""Per-clip features of a simulated clip: DF interaction features, root command and proprioception.

For every frame of a :class:`pipeline.clip.PhysicalizedClip`, the links of :class:`FeatureConfig`
are placed by MuJoCo forward kinematics of the simulated ``(qpos, qvel)``
(:func:`pipeline.terms.link_motion.link_motion`), the objects' exact distance fields are queried at the
link origins with the simulated object poses (:class:`pipeline.distance.field.ObjectFields`: the
nearest object per link), and the terms of :mod:`pipeline.terms.interaction` and
:mod:`pipeline.terms.observations` are evaluated.
"""

from __future__ import annotations

import json
from dataclasses import dataclass

import numpy as np

from pipeline.clip import PhysicalizedClip
from pipeline.distance.field import ObjectField, ObjectFields
from pipeline.errors import InputError
from pipeline.geometry import MeshGeometry, geometry_to_dict
from pipeline.terms.interaction import demo_features, interaction_features, surface_point_velocity
from pipeline.terms.layout import DEMO_LINKS, DEMO_MAX_DISTANCE_M, DF_LINKS, HISTORY, ROOT_HORIZON_S
from pipeline.terms.link_motion import link_motion
from pipeline.terms.observations import previous_actions, proprioception, root_command


@dataclass(frozen=True)
class FeatureConfig:
    """``links``: the DF feature links; ``demo_links`` / ``demo_max_distance_m``: the released demo's 7 query bodies
    and distance clip; ``root_horizon_s``: how far ahead the root command's target lies; ``history``: the window
    length ``l`` of ``I_t`` the dataset card tells loaders to use. The defaults are the observation contract's
    (:mod:`pipeline.terms.layout`)."""

    links: tuple[str, ...] = DF_LINKS
    demo_links: tuple[str, ...] = DEMO_LINKS
    demo_max_distance_m: float = DEMO_MAX_DISTANCE_M
    root_horizon_s: float = ROOT_HORIZON_S
    history: int = HISTORY

    @property
    def query_links(self) -> tuple[str, ...]:
        """Every link the fields are queried at: ``links`` then the ``demo_links`` not among them."""
        return tuple(dict.fromkeys(self.links + self.demo_links))

    def __post_init__(self):
        if not self.links or len(set(self.links)) != len(self.links):
            raise InputError(None, "links", f"need distinct link names, got {list(self.links)}")
        if self.root_horizon_s <= 0 or self.history < 1 or self.demo_max_distance_m <= 0:
            raise InputError(
                None, "features config", "root_horizon_s and demo_max_distance_m must be > 0 and history >= 1"
            )


@dataclass(frozen=True)
class ClipFeatures:
    """Per frame: ``df``/``df_relative`` (T, K, 10), ``df_demo`` (T, 7, 4), ``object_index`` (T, K) of the
    nearest object per link, ``root_command`` (T, 12), ``proprio`` (T, 93)."""

    df: np.ndarray
    df_relative: np.ndarray
    df_demo: np.ndarray
    object_index: np.ndarray
    root_command: np.ndarray
    proprio: np.ndarray


class FieldCache:
    """Distance fields by object geometry, built once per run. Meshes are queried exactly (warp BVH,
    ~0.5 M link-queries per CPU-second on 50k faces: a clip's few thousand queries take milliseconds);
    the cached octree field is for online use at millions of queries, and costs ~35 CPU-s to build
    per mesh and scale (far more on a scan that is not watertight)."""

    def __init__(self):
        self._fields: dict[str, ObjectField] = {}

    def fields(self, clip: PhysicalizedClip) -> ObjectFields:
        out = []
        for o in clip.robot.objects:
            key = json.dumps(geometry_to_dict(o.geometry), sort_keys=True) + o.name
            if key not in self._fields:
                try:
                    field = ObjectField.from_geometry(
                        o.geometry, o.name, **({"cache": False} if isinstance(o.geometry, MeshGeometry) else {})
                    )
                    field.query(np.zeros((1, 3)), np.array([0.0, 0, 0, 1, 0, 0, 0]))  # loads the query kernels now
                    self._fields[key] = field
                except InputError as exc:
                    raise InputError(clip.robot.source, f"object {o.name}", str(exc)) from None
            out.append(self._fields[key])
        return ObjectFields(tuple(out))


def clip_features(clip: PhysicalizedClip, cfg: FeatureConfig, cache: FieldCache | None = None) -> ClipFeatures:
    """Every feature of one clip (see the module docstring); a clip without objects is an :class:`InputError`."""
    robot = clip.robot
    if not robot.objects:
        raise InputError(robot.source, "objects", "no object tracks: distance-field features need at least one object")
    fields = (cache or FieldCache()).fields(clip)
    links = cfg.query_links
    motion = link_motion(robot.qpos, clip.qvel, links, robot.source)
    poses = np.stack([o.pose for o in robot.objects], axis=1)  # (T, M, 7)
    near = fields.query_links(motion.pos, poses)
    k_df = [links.index(n) for n in cfg.links]
    k_demo = [links.index(n) for n in cfg.demo_links]
    phi, grad, vel = near.phi[:, k_df], near.grad[:, k_df], motion.vel[:, k_df]
    v_surface = surface_point_velocity(
        near.closest[:, k_df], near.object_index[:, k_df], poses, np.stack(clip.object_vel, axis=1)
    )
    return ClipFeatures(
        df=interaction_features(phi, grad, vel),
        df_relative=interaction_features(phi, grad, vel - v_surface),
        df_demo=demo_features(
            near.phi[:, k_demo], near.grad[:, k_demo], motion.rot[:, k_demo], cfg.demo_max_distance_m
        ),
        object_index=near.object_index[:, k_df],
        root_command=root_command(robot.qpos, clip.qvel, robot.fps, cfg.root_horizon_s),
        proprio=proprioception(robot.qpos, clip.qvel, previous_actions(clip.action)),
    )
