"""The mjlab backend's events: the restart that starts drawn episodes in the worlds that ended."""

from __future__ import annotations

import torch
from mjlab.envs import ManagerBasedRlEnv
from mjlab.managers.event_manager import requires_model_fields

from train.envs.mjlab.object import MODEL_FIELDS
from train.envs.mjlab.worlds import Worlds


@requires_model_fields(*MODEL_FIELDS)
def start_episodes(env: ManagerBasedRlEnv, env_ids: torch.Tensor | None, worlds: Worlds) -> None:
    """Reset event: each world in ``env_ids`` starts a drawn episode (:meth:`Worlds.draw`)."""
    ids = torch.arange(env.num_envs, device=env.device) if env_ids is None else env_ids
    worlds.start(env, ids, *worlds.draw(len(ids)))
