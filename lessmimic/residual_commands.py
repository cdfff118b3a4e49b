"""``lessmimic physicalize-residual``: the physicalize teacher's learned residual, kept apart from the per-stage
commands of :mod:`lessmimic.cli`."""

from __future__ import annotations

import argparse
from pathlib import Path

from pipeline.errors import InputError


def _cmd_physicalize_residual(a: argparse.Namespace) -> int:
    from physicalize.residual import ResidualConfig, train_residual
    from pipeline.dataset.clips import episodes_to_robot_clips
    from pipeline.stage.paths import stage_dir

    src = stage_dir(a.name, "retargeted")
    if not (src / "meta" / "info.json").is_file():
        raise InputError(
            src, "meta/info.json", "no retargeted dataset here: run `lessmimic retarget --name NAME` first"
        )
    clips = episodes_to_robot_clips(src)
    if not 0 <= a.episode < len(clips):
        raise InputError(src, "--episode", f"episode {a.episode} out of range: the dataset has {len(clips)} episode(s)")
    cfg = ResidualConfig(profile=a.profile)
    out = train_residual(clips[a.episode], a.iterations, a.envs, a.seed, Path(a.out), config=cfg, verbose=True)
    print(f"residual trained on {clips[a.episode].source} ({a.iterations} iterations x {a.envs} envs) -> {out}")
    print(f"use it: lessmimic physicalize --name {a.name} --teacher base+residual:{out}")
    return 0


def add_residual(sub) -> None:
    p = sub.add_parser(
        "physicalize-residual",
        help="train the physicalize teacher's learned residual (PPO, CPU) on one retargeted clip",
    )
    p.add_argument(
        "--name", default="default", help="dataset name: trains on datasets/<NAME>/retargeted/ (default: default)"
    )
    p.add_argument("--episode", type=int, default=0, help="episode index of the clip to train on (default 0)")
    p.add_argument("--iterations", type=int, default=20, help="PPO iterations (default 20: smoke scale)")
    p.add_argument("--envs", type=int, default=8, help="parallel simulated environments (default 8)")
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--profile", default="mjlab", help="actuator profile (default mjlab)")
    p.add_argument("--out", required=True, help="checkpoint path (.pt)")
    # it reads datasets/<NAME>/retargeted/ (and `make train-residual` writes its checkpoint there): one writer at a time
    p.set_defaults(func=_cmd_physicalize_residual, writes="name")
