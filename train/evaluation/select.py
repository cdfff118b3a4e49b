"""What ``policy.pt`` is: the mean of three consecutive DAgger iterations' weights whose student, acting alone,
does best on its worst task.

DAgger keeps every iteration's policy (``policy_dagger<i>.pt``), and refits trade tasks: in issue 27's runs the
three checkpoints before the last scored SitStand 8-33% where the last scored 67%, and the next refit could have
lost it again. So the policy is chosen by evidence, not by being last. Candidate ``i`` is the weight average of
iterations ``i - average + 1 .. i`` (:func:`train.policy.mean_policy`; SWA, Izmailov et al. 2018): measured on the
three training seeds of issue 40 (code 4a2a036, 48 evaluation episodes a cell at 1.0), the mean of the last three
iterations scored PickUp 48 / 50 / 81, SitStand 54 / 54 / 69, Push 97 / 74 / 73, Carry 13 / 15 / 8% where the
single checkpoint chosen as below scored 77 / 38 / 29, 58 / 8 / 46, 85 / 37 / 62, 15 / 6 / 15% (worst seed per
task 48 / 54 / 73 / 8 against 29 / 8 / 37 / 6); the mean of the last 5 or 8 lost PickUp or SitStand on one seed
(27%, 21%): older iterations are worse students. Each candidate runs the same fixed validation rollouts
(:func:`validation_episodes`: :attr:`SelectConfig.episodes` draws per task from the corpus's valid episodes,
held out and training alike, at scale 1.0, the student alone, the initial joints perturbed by a seed of its own,
never one of the evaluation's). Its score is

    score = min_task  s_task / s*_task      (s: the student's success, Push its hand contact rate; s*: the QP
                                             teacher's on the same rollouts, floored at 0.05)

so a task the teacher itself rarely completes (Carry) does not always decide, and no task may collapse unseen.
Ties go to the higher mean ratio, then to the later iteration. Validation draws from the training episodes too:
BC's held-out split leaves one PickUp and one Carry episode and no Push one, and twelve rollouts of one episode
misled (seed 2's iteration 18: PickUp 83% on its one held-out episode, 29% in the evaluation, which draws from
all the corpus's episodes as the validation now does). Every candidate's figures are kept in ``validation.jsonl``
(a rerun takes them from there) and the choice in ``selection.json``.
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
from train.policy import mean_policy, save_policy

TEACHER_FLOOR = 0.05


@dataclass(frozen=True)
class SelectConfig:
    """``episodes`` validation rollouts per task and candidate (0: no choice, ``policy.pt`` is the last
    iteration's); ``seed`` of their draws and joint noise (the evaluation's seeds are 0, 1, 2); ``envs`` stepped
    together; ``average``: the consecutive iterations whose weights a candidate averages (1: single checkpoints)."""

    episodes: int = 12
    seed: int = 1000
    envs: int = 8
    average: int = 3


def validation_episodes(held: list[Episode], train: list[Episode]) -> tuple[list[Episode], dict[str, str]]:
    """The episodes the candidates' rollouts draw from: all of them, held out first; with, per task, how many of
    each kind (e.g. ``1 held out, 20 training``)."""
    tasks = sorted({e.task for e in held + train})
    count = {t: (sum(e.task == t for e in held), sum(e.task == t for e in train)) for t in tasks}
    return held + train, {t: f"{h} held out, {n} training" for t, (h, n) in count.items()}


def candidates(run_dir: Path, average: int) -> list[tuple[str, list[Path]]]:
    """Per DAgger iteration ``i`` of ``run_dir``: its label and the checkpoints of iterations
    ``max(0, i - average + 1) .. i``."""
    paths = sorted(run_dir.glob("policy_dagger*.pt"), key=lambda p: int(p.stem.removeprefix("policy_dagger")))
    out = []
    for i, path in enumerate(paths):
        group = paths[max(0, i - average + 1) : i + 1]
        out.append((path.name if len(group) == 1 else f"mean of {group[0].name}..{path.name}", group))
    return out


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
    """Score every candidate of ``run_dir`` (module docstring), save the best as ``policy.pt`` and return the
    choice (also written to ``selection.json``)."""
    run_dir = Path(run_dir)
    group = dict(candidates(run_dir, cfg.average))
    episodes, origin = validation_episodes(held, train)
    log = run_dir / "validation.jsonl"
    rows, config = _rows(log, cfg), asdict(cfg)
    if "teacher" not in rows:
        rows["teacher"] = {"checkpoint": "teacher", "scores": _scores(TeacherActor(), episodes, cfg, "teacher")}
        _append(log, {**rows["teacher"], "config": config})
    teacher = {t: max(s, TEACHER_FLOOR) for t, s in rows["teacher"]["scores"].items()}
    for label, paths in group.items():
        if label not in rows:
            scores = _scores(PolicyActor(mean_policy(paths)), episodes, cfg, label)
            ratio = {t: s / teacher[t] for t, s in scores.items()}
            rows[label] = {"checkpoint": label, "scores": scores, "worst_ratio": min(ratio.values()),
                           "mean_ratio": float(np.mean(list(ratio.values()))), "config": config}  # fmt: skip
            _append(log, rows[label])
    ranked = [rows[label] for label in group]
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
    policy = mean_policy(group[choice["chosen"]])
    save_policy(policy, run_dir / "policy.pt", chosen_from=choice["chosen"], selection=choice)
    write_json_atomic(run_dir / "selection.json", choice)
    return choice
