"""Where a training run stands and what it has done: the state a checkpoint keeps, the history
file (``history.csv``, one row per step) and the divergence guard."""

from __future__ import annotations

import copy
import csv
import math
from dataclasses import dataclass, field
from pathlib import Path

import torch

from meshgen.run.inputs import read_input_text

__all__ = [
    "HISTORY_COLUMNS",
    "history_step",
    "DivergenceGuard",
    "TrainState",
    "format_row",
    "open_history",
    "read_rows",
    "state_from_checkpoint",
    "state_to_checkpoint",
]

HISTORY_COLUMNS = ("stage", "step", "L1", "L2", "total", "a1", "a2", "conflict", "lr", "seconds")


@dataclass
class TrainState:
    """Where training stands: the part of a checkpoint that is not the network, the weights, the
    optimiser or the random state (see ``checkpoint.py`` for the whole layout)."""

    stage: str  # the stage under way, or "done"
    stage_step: int = 0  # steps done in this stage
    step: int = 0  # steps done in all stages (= history rows)
    elapsed: float = 0.0  # training seconds before this process
    lr_reductions: int = 0  # by the divergence guard, over the whole run
    last_row: dict = field(default_factory=dict)  # the last history row


def state_from_checkpoint(checkpoint: dict) -> TrainState:
    return TrainState(
        checkpoint["stage"],
        checkpoint["stage_step"],
        checkpoint["step"],
        checkpoint["elapsed_seconds"],
        checkpoint["guard"]["lr_reductions"],
        dict(checkpoint["history"].get("last", {})),  # a family checkpoint may have no last row
    )


def state_to_checkpoint(state: TrainState, seconds: float) -> dict:
    """The checkpoint entries of ``state``; ``seconds``: training seconds of this process so far."""
    return {
        "stage": state.stage,
        "stage_step": state.stage_step,
        "step": state.step,
        "elapsed_seconds": state.elapsed + seconds,
        "history": {"rows": state.step, "last": dict(state.last_row)},
        "guard": {"lr_reductions": state.lr_reductions},
    }


# ---------------------------------------------------------------------------------------------
# history file


def open_history(path: Path, keep_until_step: int | None):
    """Open ``history.csv`` for appending. A new run starts it; a resumed run keeps the rows of the
    steps its checkpoint holds: a checkpoint at step N has done rows 0 .. N-1 (rows written after
    it, by a run killed before its next checkpoint, belong to the lost part)."""
    rows = []
    if keep_until_step is not None and path.is_file():
        # A row cut short by a kill (or an edited file) is dropped: a history is data, read leniently.
        text = read_input_text(path, "history").splitlines()
        rows = [row for row in csv.DictReader(text) if history_step(row) is not None and history_step(row) < keep_until_step]
    handle = open(path, "w", newline="")
    writer = csv.DictWriter(handle, fieldnames=HISTORY_COLUMNS, extrasaction="ignore")
    writer.writeheader()
    writer.writerows(rows)
    return handle, writer


def history_step(row: dict) -> int | None:
    """The step of a history row, None for a row that is not a whole one (missing columns)."""
    try:
        return int(row["step"]) if None not in row.values() and None not in row else None
    except (KeyError, TypeError, ValueError):
        return None


def format_row(row: dict) -> dict:
    return {k: (f"{v:.6g}" if isinstance(v, float) else v) for k, v in row.items()}


def read_rows(steps: list[dict], network) -> tuple[list[dict], bool]:
    """The numbers of consecutive steps (0-d tensors on the device, or Python numbers) as Python
    numbers, and whether all of them are good (finite losses, finite weights after the last): one
    transfer from the device, the only wait for it in the loop outside L-BFGS (whose line search
    reads its losses itself)."""
    keys = [k for k, v in steps[0].items() if isinstance(v, torch.Tensor)]
    finite_weights = torch.isfinite(torch.stack([p.detach().sum() for p in network.parameters()]).sum())
    values = torch.stack(
        [numbers[k].detach().double().reshape(()) for numbers in steps for k in keys] + [finite_weights.double()]
    ).tolist()
    rows = []
    for index, numbers in enumerate(steps):
        read = values[index * len(keys) : (index + 1) * len(keys)]
        rows.append({**numbers, **{k: (int(v) if k == "conflict" else v) for k, v in zip(keys, read)}})
    return rows, bool(values[-1]) and all(math.isfinite(row["total"]) for row in rows)


# ---------------------------------------------------------------------------------------------
# the divergence guard


class DivergenceGuard:
    """Keeps the last good state of a stage; after a non-finite step, restores it with a lower
    learning rate (``guard.lr_factor``), at most ``guard.max_retries`` times in a row. The loop
    checks steps a block at a time (one step on a CPU, ``DEVICE_BLOCK`` Adam steps on a GPU): a
    non-finite step anywhere in a block sends the run back to the state before the block.
    ``training``: a ``meshgen.neural.steps.Training`` (its network and weights are restored)."""

    def __init__(self, training, optimizer, scheduler, state: TrainState):
        self.training, self.optimizer, self.scheduler, self.state = training, optimizer, scheduler, state
        self.failures = 0
        self.good = self.snapshot()

    def snapshot(self) -> dict:
        """Deep copies of everything a step changes (cheap next to a step: a few small tensors)."""
        return copy.deepcopy(
            {
                "network": self.training.network.state_dict(),
                "weights": self.training.weights.state_dict(),
                "optimizer": self.optimizer.state_dict(),
                "scheduler": self.scheduler.state_dict() if self.scheduler is not None else None,
            }
        )

    def accept(self) -> None:
        """The step was good: it becomes the state to come back to."""
        self.failures = 0
        self.good = self.snapshot()

    def reject(self, stage: str, say) -> bool:
        """The step was not finite: restore the last good state with a lower learning rate. Returns
        False when the retries are spent (the good state restored, the learning rate not lowered)."""
        config = self.training.config.guard
        self.failures += 1
        lowered = [group["lr"] * config.lr_factor for group in self.optimizer.param_groups]
        self.training.network.load_state_dict(self.good["network"])
        self.training.weights.load_state_dict(self.good["weights"])
        self.optimizer.load_state_dict(copy.deepcopy(self.good["optimizer"]))
        if self.scheduler is not None:
            self.scheduler.load_state_dict(self.good["scheduler"])
        if self.failures > config.max_retries:
            return False
        for group, lr in zip(self.optimizer.param_groups, lowered):
            group["lr"] = lr
        self.state.lr_reductions += 1
        say(
            f"non-finite loss at step {self.state.step} ({stage}): restored the last good state, "
            f"learning rate lowered to {self.optimizer.param_groups[0]['lr']:.3g}"
        )
        return True
