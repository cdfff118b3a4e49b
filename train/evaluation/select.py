"""What ``policy.pt`` is: the mean of the weights of the last three DAgger iterations (by default), or of the three
consecutive iterations whose student, acting alone, does best on its worst task in validation rollouts.

DAgger keeps every iteration's policy (``policy_dagger<i>.pt``), and refits trade tasks: in issue 27's runs the
three checkpoints before the last scored SitStand 8-33% where the last scored 67%. Candidate ``i`` is the weight
average of iterations ``i - average + 1 .. i`` (:func:`train.policy.mean_policy`; SWA, Izmailov et al. 2018).

Measured (issue 40; 48 evaluation episodes a cell at 1.0; PickUp / SitStand / Push contact / Carry in %, per
training seed 0 / 1 / 2):

- training at 4a2a036 (a fresh optimiser per refit): the single checkpoint chosen by validation scored 77 / 38 / 29,
  58 / 8 / 46, 85 / 37 / 62, 15 / 6 / 15; the last one 77 / 10 / 56, 58 / 23 / 48, 85 / 66 / 25, 15 / 15 / 2; the
  mean of the last three 48 / 50 / 81, 54 / 54 / 69, 97 / 74 / 73, 13 / 15 / 8; of the last 5 or 8, one seed lost
  PickUp or SitStand (27%, 21%): older iterations are worse students;
- training with the optimiser kept across refits (:mod:`train.dagger`): the mean of the last three scored 89.6 /
  72.9 / 58.3, 79.2 / 97.9 / 79.2, 89.2 / 89.4 / 63.8, 8.3 / 10.4 / 4.2; the candidate chosen by validation (12
  rollouts per task, the rule below) 68.8 / 41.7 / 47.9, 58.3 / 81.2 / 39.6, 83.2 / 70.8 / 82.1, 8.3 / 8.3 / 8.3.
  The validation's worst task was Carry for every candidate (1 or 2 successes of 12, the teacher 7), so its noise
  chose; a geometric mean of the ratios chose no better (SitStand 37.5% on seed 2). Hence the default:
  ``--select-episodes 0``, the last candidate, no rollouts (these rules were compared on the evaluation's own
  numbers of these six runs: a fresh 3-seed run is their confirmation).

With ``episodes > 0`` each candidate runs the same fixed validation rollouts (:func:`validation_episodes`:
:attr:`SelectConfig.episodes` draws per task from the corpus's valid episodes, held out and training alike, at
scale 1.0, the student alone, the initial joints perturbed by a seed of its own, never one of the evaluation's).
Its score is

    score = min_task  s_task / s*_task      (s: the student's success, Push its hand contact rate; s*: the QP
                                             teacher's on the same rollouts, floored at 0.05)

so no task may collapse unseen. Ties go to the higher mean ratio, then to the later iteration. Validation draws
from the training episodes too: BC's held-out split leaves one PickUp and one Carry episode and no Push one, and
twelve rollouts of one episode misled (seed 2's iteration 18 at 4a2a036: PickUp 83% on its one held-out episode,
29% in the evaluation, which draws from all the corpus's episodes as the validation now does). Every candidate's
figures are kept in ``validation.jsonl`` (a rerun takes them from there) and the choice in ``selection.json``.
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
    """``episodes`` validation rollouts per task and candidate (0: no rollouts, ``policy.pt`` is the last
    candidate); ``seed`` of their draws and joint noise (the evaluation's seeds are 0, 1, 2); ``envs`` stepped
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
    if cfg.episodes == 0:
        return _keep(run_dir, group, list(group)[-1], {"by": "the last candidate (no validation rollouts)"}, cfg)
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
    figures = {
        "by": "the worst task's success relative to the teacher's on the validation rollouts",
        "chosen_scores": ranked[best]["scores"],
        "last_scores": ranked[-1]["scores"],
        "teacher_scores": rows["teacher"]["scores"],
        "episodes_from": origin,
    }
    return _keep(run_dir, group, ranked[best]["checkpoint"], figures, cfg)


def _keep(run_dir: Path, group: dict[str, list[Path]], chosen: str, figures: dict, cfg: SelectConfig) -> dict:
    """Save candidate ``chosen`` as ``policy.pt`` and the choice as ``selection.json``; the choice."""
    choice = {"chosen": chosen, "last": list(group)[-1], **figures, "config": asdict(cfg)}
    save_policy(mean_policy(group[chosen]), run_dir / "policy.pt", chosen_from=chosen, selection=choice)
    write_json_atomic(run_dir / "selection.json", choice)
    return choice
