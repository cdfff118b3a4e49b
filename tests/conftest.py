"""Shared test setup: LeRobot / huggingface_hub work offline, in a temporary home.

The environment is set at import time, before any test module imports lerobot (it reads
``HF_LEROBOT_HOME`` when imported). Each pytest process gets its own home, removed at exit.
"""

import atexit
import os
import shutil
import tempfile

_HOME = tempfile.mkdtemp(prefix="lessmimic-tests-hf-")
atexit.register(shutil.rmtree, _HOME, True)
os.environ["HF_HUB_OFFLINE"] = "1"
os.environ["HF_HOME"] = os.path.join(_HOME, "hf")
os.environ["HF_LEROBOT_HOME"] = os.path.join(_HOME, "lerobot")
os.environ.setdefault("TOKENIZERS_PARALLELISM", "false")
