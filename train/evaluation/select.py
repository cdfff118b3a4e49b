"""Which DAgger iteration ``policy.pt`` is: the one whose student, acting alone, does best on its worst task.

DAgger keeps every iteration's policy (``policy_dagger<i>.pt``), and refits trade tasks: in issue 27's runs the
three checkpoints before the last scored SitStand 8-33% where the last scored 67%, and the next refit could have
lost it again. So the checkpoint is chosen by evidence, not by being last. Each candidate runs the same fixed
validation rollouts (:func:`validation_episodes`: per task the corpus episodes held out of BC and DAgger, the
training ones only for a task with none held out; :attr:`SelectConfig.episodes` rollouts per task at scale 1.0,
the student alone, the initial joints perturbed by a seed of its own, never one of the evaluation's). Its score is

    score = min_task  s_task / s*_task      (s: the student's success, Push its hand contact rate; s*: the QP
                                             teacher's on the same rollouts, floored at 0.05)

so a task the teacher itself rarely completes (Carry) does not always decide, and no task may collapse unseen.
Ties go to the higher mean ratio, then to the later iteration. Every candidate's figures are kept in
``validation.jsonl`` (a rerun takes them from there) and the choice in ``selection.json``.
"""

from __future__ import annotations

import json
from dataclasses import asdict, dataclass
from pathlib import Path

import numpy as np

from pipeline.stage.atomic import write_json_atomic
from train.actors import PolicyActor, TeacherActor
from train.episodes import Episode
from train.evaluation.table2 import EvalConfig, evaluate
from train.policy import load_policy, save_policy

TEACHER_FLOOR = 0.05


@dataclass(frozen=True)
class SelectConfig:
    """``episodes`` validation rollouts per task and checkpoint (0: no choice, ``policy.pt`` is the last
    iteration's); ``seed`` of their draws and joint noise (the evaluation's seeds are 0, 1, 2); ``envs`` stepped
    together."""

    episodes: int = 12
    seed: int = 1000
    envs: int = 8


def validation_episodes(held: list[Episode], train: list[Episode]) -> tuple[list[Episode], dict[str, str]]:
    """The episodes the candidates are scored on: every held-out one, and a task's training episodes only where it
    has none held out; with, per task, where its episodes come from (``held out`` or ``training``)."""
    tasks = sorted({e.task for e in held + train})
    out, origin = [], {}
    for task in tasks:
        mine = [e for e in held if e.task == task]
        origin[task] = "held out" if mine else "training"
        out += mine or [e for e in train if e.task == task]
    return out, origin


def _scores(actor, episodes: list[Episode], cfg: SelectConfig, label: str) -> dict[str, float]:
    """Per task: success (Push: contact rate) of ``actor`` over the validation rollouts at scale 1.0."""
    ecfg = EvalConfig(seeds=(cfg.seed,), episodes=cfg.episodes, envs=cfg.envs, scales=(1.0,))
    return {c["task"]: c["mean"] for c in evaluate(actor, episodes, ecfg, label)["cells"].values()}


def _rows(path: Path, cfg: SelectConfig) -> dict[str, dict]:
    """The rows of ``validation.jsonl`` scored under ``cfg`` (another config's are stale), by checkpoint."""
    rows = map(json.loads, path.open()) if path.is_file() else ()
    return {r["checkpoint"]: r for r in rows if r.get("config") == asdict(cfg)}


def _append(path: Path, row: dict) -> None:
    with path.open("a", encoding="utf-8") as f:
        f.write(json.dumps(row) + "\n")


def choose(run_dir: str | Path, held: list[Episode], train: list[Episode], cfg: SelectConfig = SelectConfig()) -> dict:
    """Score every ``policy_dagger<i>.pt`` of ``run_dir`` (module docstring), save the best as ``policy.pt`` and
    return the choice (also written to ``selection.json``)."""
    run_dir = Path(run_dir)
    candidates = sorted(run_dir.glob("policy_dagger*.pt"), key=lambda p: int(p.stem.removeprefix("policy_dagger")))
    episodes, origin = validation_episodes(held, train)
    log = run_dir / "validation.jsonl"
    rows, config = _rows(log, cfg), asdict(cfg)
    if "teacher" not in rows:
        rows["teacher"] = {"checkpoint": "teacher", "scores": _scores(TeacherActor(), episodes, cfg, "teacher")}
        _append(log, {**rows["teacher"], "config": config})
    teacher = {t: max(s, TEACHER_FLOOR) for t, s in rows["teacher"]["scores"].items()}
    for path in candidates:
        if path.name not in rows:
            scores = _scores(PolicyActor(load_policy(path)), episodes, cfg, path.stem)
            ratio = {t: s / teacher[t] for t, s in scores.items()}
            rows[path.name] = {"checkpoint": path.name, "scores": scores, "worst_ratio": min(ratio.values()),
                               "mean_ratio": float(np.mean(list(ratio.values()))), "config": config}  # fmt: skip
            _append(log, rows[path.name])
    ranked = [rows[p.name] for p in candidates]
    best = max(range(len(ranked)), key=lambda i: (ranked[i]["worst_ratio"], ranked[i]["mean_ratio"], i))
    choice = {
        "chosen": ranked[best]["checkpoint"],
        "last": ranked[-1]["checkpoint"],
        "by": "the worst task's success relative to the teacher's on the validation rollouts",
        "chosen_scores": ranked[best]["scores"],
        "last_scores": ranked[-1]["scores"],
        "teacher_scores": rows["teacher"]["scores"],
        "episodes_from": origin,
        "config": config,
    }
    policy = load_policy(run_dir / choice["chosen"])
    save_policy(policy, run_dir / "policy.pt", chosen_from=choice["chosen"], selection=choice)
    write_json_atomic(run_dir / "selection.json", choice)
    return choice
