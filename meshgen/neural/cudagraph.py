"""One CUDA graph for the device part of a training step (design notes §9).

The networks are small: a step of the ``paper`` preset launches about 600 kernels that keep an
H100 busy for 2 ms, while launching them from Python takes about 19 ms. Captured once into a
CUDA graph, the step is replayed by one launch. What is captured must be a function of tensors
whose addresses never change: the network's weights and the reweighting parameters (updated in
place by the optimiser, outside the graph), and the step's inputs, copied into the graph's own
input tensors before each replay. Its outputs live in the graph's memory and are overwritten by
the next replay.

Only the gradients are captured; the optimiser and the learning-rate schedule stay eager, as on
the CPU, so checkpoints, resuming and the divergence guard work the same on every device.
"""

from __future__ import annotations

from collections.abc import Callable

import torch

__all__ = ["WARMUP_RUNS", "CapturedFunction"]


WARMUP_RUNS = 2  # eager runs on a side stream before the capture (cuBLAS workspaces, autograd's state)


class CapturedFunction:
    """``function(inputs) -> outputs`` (dicts of CUDA tensors) run as one CUDA graph.

    The first call runs ``function`` ``WARMUP_RUNS`` times on a side stream (it must have no side
    effects: the runs are thrown away) and captures it; every call then copies its ``inputs``
    (CPU or CUDA tensors of the first call's shapes and types) into the graph's input tensors,
    without waiting for the device, and replays the graph. Returns the graph's output tensors,
    valid until the next call."""

    def __init__(self, function: Callable[[dict], dict], device: torch.device):
        self.function, self.device = function, device
        self.graph = None
        self.inputs: dict[str, torch.Tensor] = {}
        self.outputs: dict[str, torch.Tensor] = {}

    def __call__(self, inputs: dict) -> dict:
        if self.graph is None:
            self._capture(inputs)
        else:
            for name, value in inputs.items():
                self.inputs[name].copy_(value, non_blocking=True)
        self.graph.replay()
        return self.outputs

    def _capture(self, inputs: dict) -> None:
        self.inputs = {name: value.to(self.device, copy=True) for name, value in inputs.items()}
        side = torch.cuda.Stream(self.device)
        side.wait_stream(torch.cuda.current_stream(self.device))
        with torch.cuda.stream(side):
            for _ in range(WARMUP_RUNS):
                self.function(self.inputs)
        torch.cuda.current_stream(self.device).wait_stream(side)
        graph = torch.cuda.CUDAGraph()
        with torch.cuda.graph(graph):
            self.outputs = self.function(self.inputs)
        self.graph = graph
