"""Shared test setup: LeRobot / huggingface_hub work offline, in a temporary home.

The environment is set at import time, before any test module imports lerobot (it reads
``HF_LEROBOT_HOME`` when imported). Each pytest process gets its own home, removed at exit.
"""

import atexit
import os
import shutil
import tempfile

import pytest

_HOME = tempfile.mkdtemp(prefix="lessmimic-tests-hf-")
atexit.register(shutil.rmtree, _HOME, True)
os.environ["HF_HUB_OFFLINE"] = "1"
os.environ["HF_HOME"] = os.path.join(_HOME, "hf")
os.environ["HF_LEROBOT_HOME"] = os.path.join(_HOME, "lerobot")
os.environ.setdefault("TOKENIZERS_PARALLELISM", "false")


@pytest.fixture(scope="module")
def bc_corpus(tmp_path_factory):
    """The default chain (4 synthetic clips: retarget, physicalize, features) in a temporary datasets root named
    ``train``, and a BC policy trained on it for 30 steps: ``(episodes, policy path)``. Module scope: built once per
    test module that asks for it."""
    from features.stage import run_stage as features_stage
    from lessmimic.chain import retarget as retarget_stage
    from physicalize.stage import run_stage as physicalize_stage
    from pipeline.stage.paths import stage_dir
    from train.bc import BCConfig, train_bc
    from train.episodes import load_episodes
    from train.policy import PolicyConfig
    from train.vae import VAEConfig

    root, run = tmp_path_factory.mktemp("datasets"), tmp_path_factory.mktemp("run")
    mp = pytest.MonkeyPatch()
    mp.setenv("LESSMIMIC_DATASETS", str(root))
    retarget_stage(None, "train")
    physicalize_stage("train")
    features_stage("train")
    train_bc(stage_dir("train", "features"), run, BCConfig(steps=30, log_every=10), PolicyConfig(), VAEConfig(),
             vae_steps=30)  # fmt: skip
    yield load_episodes("train"), run / "policy.pt"
    mp.undo()
