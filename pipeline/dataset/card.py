"""The dataset card: a :class:`DatasetCard` rendered to ``README.md`` in the dataset root.

The README starts with the YAML front matter the Hugging Face hub reads (``license``, ``tags``
starting with ``LeRobot``, ``task_categories: [robotics]``, and the ``configs`` entry pointing the
dataset viewer at ``data/*/*.parquet``, as LeRobot's own card does), followed by a description,
the provenance, the robot and actuator profile, and one table row per feature (meaning, unit,
frame). :func:`pipeline.dataset.write.write_dataset` writes it; the card's fields are also kept
in ``meta/lessmimic.json`` so merged datasets can re-render it.
"""

from __future__ import annotations

import json
from collections.abc import Sequence
from dataclasses import asdict, dataclass, field
from typing import TYPE_CHECKING

if TYPE_CHECKING:
    from pipeline.dataset.schema import Feature

BASE_TAGS = ("LeRobot", "unitree-g1", "humanoid", "motion-retargeting", "human-object-interaction")


@dataclass
class DatasetCard:
    """What a person needs to know about a dataset.

    ``provenance`` lists the sources (files, datasets, upstream stages). ``feature_frames`` maps a
    feature name to the coordinate frame its values are expressed in (e.g. ``"world, z-up"``).
    ``fps`` is taken from the dataset when ``None``.
    """

    title: str
    description: str = ""
    provenance: list[str] = field(default_factory=list)
    robot: str = "Unitree G1, 29 DoF (mjlab g1.xml)"
    actuator_profile: str = ""
    fps: int | None = None
    synthetic: bool = False
    stage: str = ""
    feature_frames: dict[str, str] = field(default_factory=dict)
    notes: list[str] = field(default_factory=list)
    license: str = "apache-2.0"
    tags: list[str] = field(default_factory=list)

    def to_dict(self) -> dict:
        return asdict(self)

    @classmethod
    def from_dict(cls, d: dict) -> DatasetCard:
        known = {k: v for k, v in d.items() if k in cls.__dataclass_fields__}
        return cls(**known)

    def all_tags(self) -> list[str]:
        tags = list(BASE_TAGS) + (["synthetic"] if self.synthetic else []) + list(self.tags)
        return list(dict.fromkeys(tags))


def _yaml_str(s: str) -> str:
    return json.dumps(s, ensure_ascii=False)  # a JSON string is a valid YAML scalar


def _cell(s: str) -> str:
    return (s or "").replace("|", "\\|").replace("\n", " ")


def render_card(
    card: DatasetCard, repo_id: str, fps: int, features: Sequence[Feature], episodes: int, frames: int
) -> str:
    """Markdown with YAML front matter for ``README.md``."""
    lines = ["---", f"license: {_yaml_str(card.license)}", f"pretty_name: {_yaml_str(card.title)}", "tags:"]
    lines += [f"- {_yaml_str(t)}" for t in card.all_tags()]
    lines += [
        "task_categories:",
        "- robotics",
        "configs:",
        "- config_name: default",
        "  data_files: data/*/*.parquet",
        "---",
        "",
    ]
    lines += [f"# {card.title}", ""]
    if card.description:
        lines += [card.description.strip(), ""]
    lines += [
        "This dataset is in the [LeRobot](https://github.com/huggingface/lerobot) v3.0 format "
        f"(load it with `LeRobotDataset({repo_id!r}, root=...)`).",
        "",
        f"- **Robot:** {card.robot}",
        f"- **Actuator profile:** {card.actuator_profile or 'n/a'}",
        f"- **Frame rate:** {card.fps or fps} fps",
        f"- **Episodes / frames:** {episodes} / {frames}",
        f"- **Synthetic:** {'yes' if card.synthetic else 'no'}",
        f"- **Stage:** {card.stage or 'n/a'}",
        "",
        "Conventions: world frame z-up, metres, seconds, radians; quaternions scalar-first (w, x, y, z). "
        "Per-episode provenance is in `meta/lessmimic_episodes.jsonl`.",
        "",
    ]
    if card.provenance:
        lines += ["## Provenance", ""] + [f"- {p}" for p in card.provenance] + [""]
    lines += ["## Features", "", "| feature | dtype | size | unit | frame | meaning |", "|---|---|---|---|---|---|"]
    for f in features:
        lines.append(
            f"| `{f.name}` | {f.dtype} | {f.shape[0]} | {_cell(f.unit)} | "
            f"{_cell(card.feature_frames.get(f.name, ''))} | {_cell(f.description)} |"
        )
    lines.append("")
    lines.append("Element names of every feature are listed in `meta/info.json`.")
    if card.notes:
        lines += ["", "## Notes", ""] + [f"- {n}" for n in card.notes]
    return "\n".join(lines) + "\n"
