"""ONNX export of a trained policy, side by side with its torch checkpoint (the baseline):

* **export**: seconds of :func:`train.export.onnx_policy.export_onnx` in this process (the issue's bar: < 10 s),
  and the wall time of the whole ``lessmimic export`` command (Python and torch start-up included);
* **parity**: max and mean |onnxruntime - torch| joint target [rad] over the observation windows the torch policy
  recorded acting on ``--episodes`` corpus episodes per task (the bar: max <= 1e-5);
* **latency**: one policy call at batch 1 (a robot's control step) and batch 8 (the evaluation's environments),
  torch (1 thread) against onnxruntime (1 thread), median of ``--calls`` calls.

Run: ``make bench-export POLICY=runs/<RUN>/policy.pt [NAME=corpus]`` (a trained policy: ``make train-bc``).
"""

from __future__ import annotations

import argparse
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np
import torch

from train.episodes import load_episodes
from train.export.onnx_policy import export_onnx, load_any_policy
from train.export.parity import parity, recorded_windows
from train.export.runtime import OnnxPolicy


def _latency(act, windows, batch: int, calls: int) -> float:
    x = tuple(torch.from_numpy(w[:batch]) for w in windows)
    act(*x)  # warm-up
    times = []
    for _ in range(calls):
        t0 = time.perf_counter()
        act(*x)
        times.append(time.perf_counter() - t0)
    return float(np.median(times)) * 1e3


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--policy", required=True)
    ap.add_argument("--name", default="corpus")
    ap.add_argument("--episodes", type=int, default=2, help="recorded episodes per task")
    ap.add_argument("--calls", type=int, default=200)
    a = ap.parse_args()
    torch.set_num_threads(1)
    with tempfile.TemporaryDirectory() as tmp:
        out = Path(tmp) / "policy.onnx"
        report = export_onnx(a.policy, out)
        t0 = time.perf_counter()
        cmd = [sys.executable, "-m", "lessmimic", "export", "--policy", a.policy, "--out", str(out), "--overwrite"]
        subprocess.run(cmd, check=True, capture_output=True)
        command_s = time.perf_counter() - t0
        policy = load_any_policy(a.policy)  # a MoCap-DF policy or a vision student
        by_task: dict[str, list] = {}
        for e in load_episodes(a.name):
            by_task.setdefault(e.task, []).append(e)
        chosen = [e for eps in by_task.values() for e in eps[: a.episodes]]
        windows = recorded_windows(policy, chosen, steps=600)
        par = parity(policy, out, windows)
        onnx_policy = OnnxPolicy(out)
        print(f"policy {a.policy}: ONNX {report.bytes / 1e6:.2f} MB")
        print(f"export: {report.seconds:.1f} s in process (bar < 10 s); `lessmimic export` {command_s:.1f} s wall")
        print(
            f"parity over {par['windows']} recorded windows ({len(chosen)} episodes): max {par['max_abs']:.2e} rad, "
            f"mean {par['mean_abs']:.2e} (bar: max <= 1e-5)"
        )
        for batch in (1, 8):
            t_torch = _latency(policy.act, windows, batch, a.calls)
            t_onnx = _latency(onnx_policy.act, windows, batch, a.calls)
            print(
                f"latency at batch {batch}: torch {t_torch:.2f} ms, onnxruntime {t_onnx:.2f} ms (median of {a.calls})"
            )


if __name__ == "__main__":
    main()
