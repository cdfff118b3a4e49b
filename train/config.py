"""A ``train-bc`` run's settings (:class:`TrainConfig`), in a module of its own that imports nothing heavy: the
command line reads its defaults when it builds its parser, and every ``lessmimic`` command builds the whole parser
(importing :mod:`train.run` there cost every command, ``--help`` included, ~5 s of start-up)."""

from __future__ import annotations

from dataclasses import dataclass

from pipeline.terms.layout import HISTORY


@dataclass(frozen=True)
class TrainConfig:
    """A run's settings. The defaults are the laptop scale (~58 min on 2 CPU cores on the 100-clip corpus;
    26 DAgger iterations, the last six drawing every task equally with refits twice as long: README, Train I)."""

    name: str = "corpus"  # the corpus: datasets/<name>/{features,physicalized,retargeted}
    backbone: str = "transformer"
    history: int = HISTORY
    vae_steps: int = 2000
    bc_steps: int = 8000
    batch: int = 256
    dagger_iterations: int = 26
    dagger_episodes: int = 32
    dagger_probe: int = 8
    dagger_fit_steps: int = 1500
    envs: int = 8
    select_episodes: int = 0  # validation rollouts per candidate and task (train.evaluation.select); 0: the last one
    seed: int = 0
    device: str = "cpu"
    contract: str = (
        "lessmimic"  # the observation contract (pipeline.terms.layout.CONTRACTS): lessmimic_demo for the demo
    )
