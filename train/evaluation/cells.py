"""Which episodes a Table 2 cell runs, and which cells no episode can succeed in, decided before any rollout.

**Episodes** (:func:`cell_episodes`). Protocol ``scaled`` (the paper's): the demonstrations (an augmented corpus's
``x1`` variants; every episode of another corpus), the object scaled by the environment. Protocol ``matched``: the
augmented corpus's episodes of the cell's variant (:func:`pipeline.geometry.variant_label` of its scale and shape),
run as they are: object, placement and reference made for that geometry.

**Cells the rules rule out** (:func:`rule_window`). SitStand succeeds only with the root inside
:attr:`train.mdp.tasks.Rules.seat_height_m` while seated. A matched cell whose references all sit with the root
outside that window asks for what the rule forbids: such a cell is listed as ``infeasible`` with the figure (the
reference's median seated root height), never run, never scored 0 against the policy. A cell whose variant has no
valid episode at all is ``missing``, with the physicalize stage's yield for that variant (its rejections carry
their own figures: a reach, a motor torque).
"""

from __future__ import annotations

import json

import numpy as np

from pipeline.geometry import variant_label
from pipeline.stage.paths import logs_dir, stage_dir
from train.episodes import Episode, episode_variant
from train.mdp.tasks import Rules

SEAT_LINKS = ("pelvis",)  # the reference's seated frames: the pelvis touches the chair


def cell_episodes(episodes: list[Episode], task: str, scale: float, protocol: str, shape: str) -> tuple[list, float]:
    """The episodes a cell draws from and the scale the environment runs them at (module docstring)."""
    of_task = [e for e in episodes if e.task == task]
    if protocol == "matched":
        label = variant_label(scale, shape)
        return [e for e in of_task if episode_variant(e) == label], 1.0
    return [e for e in of_task if episode_variant(e) in (None, "x1")], scale


def seated_root_height(episode: Episode) -> float | None:
    """The median root height of the episode's reference over the frames its pelvis touches the chair [m]."""
    ref = episode.reference
    if ref.contacts is None or "pelvis" not in ref.contact_links:
        return None
    seated = ref.contacts[:, ref.contact_links.index("pelvis")]
    return float(np.median(ref.qpos[seated, 2])) if seated.any() else None


def rule_window(task: str, pool: list[Episode], rules: Rules) -> str | None:
    """Why no episode of ``pool`` can meet ``task``'s success rule, from the references alone, or None."""
    if task != "SitStand" or not pool:
        return None
    heights = [h for h in map(seated_root_height, pool) if h is not None]
    lo, hi = rules.seat_height_m
    if heights and not lo <= np.median(heights) <= hi:
        return (
            f"the references sit with the root at {np.median(heights):.2f} m (median of {len(heights)}), outside the "
            f"success rule's {lo}-{hi} m"
        )
    return None


def variant_yield(corpus: str, task: str, label: str) -> str:
    """The physicalize stage's yield for ``task``'s variant ``label`` of ``corpus``, in words ('' when unknown)."""
    path = logs_dir(stage_dir(corpus, "physicalized")) / "report.json"
    row = json.loads(path.read_text()).get("yield", {}).get(f"{task} {label}") if path.is_file() else None
    if row is None:
        return ""
    why = ", ".join(f"{k}: {v}" for k, v in {**row["rejected"], **row["failed"]}.items())
    return f"physicalize kept {row['valid']} of {row['clips']}" + (f" ({why})" if why else "")
