"""Where a trained network is evaluated: ``inference_device`` picks "cpu" or "cuda" without
importing torch on a machine that has no NVIDIA GPU.

``auto`` means cuda when torch can use a GPU. Asking torch (``torch.cuda.is_available()``) costs
the import of torch, about a second; so torch is asked only when it is imported already, or when
the machine shows an NVIDIA device (``/dev/nvidia0``..., the driver's ``/proc/driver/nvidia/gpus``)
that ``CUDA_VISIBLE_DEVICES`` does not hide. Elsewhere (no such device, or a system without
``/dev``, where torch decides) the answer needs no torch on CPU-only Linux machines.
"""

from __future__ import annotations

import importlib.util
import os
import sys
from pathlib import Path

from meshgen.errors import ParameterError

__all__ = ["cuda_available", "inference_device", "nvidia_device_visible"]


def nvidia_device_visible() -> bool | None:
    """Whether this machine shows an NVIDIA GPU to this process: False when ``CUDA_VISIBLE_DEVICES``
    hides every device or Linux lists none; None where it cannot tell (no ``/dev``)."""
    visible = os.environ.get("CUDA_VISIBLE_DEVICES")
    if visible is not None and visible.strip() in ("", "-1"):
        return False
    if not Path("/dev").is_dir():
        return None
    if any(Path("/dev").glob("nvidia[0-9]*")):
        return True
    gpus = Path("/proc/driver/nvidia/gpus")
    return gpus.is_dir() and any(gpus.iterdir())


def cuda_available() -> bool:
    """Whether torch can run on a CUDA GPU here; imports torch only where a GPU may be present."""
    if "torch" not in sys.modules:
        if nvidia_device_visible() is False or importlib.util.find_spec("torch") is None:
            return False
    import torch

    return bool(torch.cuda.is_available())


def inference_device(device: str = "auto") -> str:
    """``"cpu"`` or ``"cuda"``: ``auto`` picks cuda when torch sees a GPU; cuda without one raises."""
    if device not in ("auto", "cpu", "cuda"):
        raise ParameterError("device", f"unknown {{name}} {device!r}: pick auto, cpu or cuda")
    if device == "cpu":
        return "cpu"
    available = cuda_available()
    if device == "auto":
        return "cuda" if available else "cpu"
    if not available:
        raise ParameterError("device", "{name} cuda: no CUDA device is available to torch here; use cpu")
    return device
