"""warp-lang, initialised quietly, and where a kernel runs for numpy arrays or torch tensors.

Kernels run on the CPU (one thread) for numpy arrays and torch CPU tensors, and on the tensor's
CUDA device for CUDA tensors, on torch's current stream (so they are ordered with torch's work).
"""

from __future__ import annotations

from pipeline.xp import is_numpy, namespace


def warp():
    """The ``warp`` module, initialised with no greeting or per-module load lines on stdout."""
    import warp as wp

    wp.config.log_level = wp.LOG_WARNING
    wp.init()
    return wp


def runs_on(a) -> bool:
    """True where a warp kernel can run next to ``a``: numpy, torch CPU, torch CUDA with a CUDA driver."""
    if is_numpy(namespace(a)):
        return True
    return a.device.type == "cpu" or (a.device.type == "cuda" and warp().is_cuda_available())
