"""The stage runner: one training loop for a geometry's set of networks (one block or several,
``meshgen.neural.train``) and for a family of shapes (``meshgen.neural.family_train``), design notes §6.

A run is a table of :class:`Stage` rows (optimiser, fixed points, one step, what to do first, how
many steps to take between two reads from the device); :func:`run_stages` goes through it: resume
where a checkpoint stopped, one history row per step (``history.csv``), the divergence guard,
progress lines, a checkpoint every ``checkpoint.every`` steps, on Ctrl-C (``stop``) and at the end.
What differs between a shape and a family (network, problem, losses, the checkpoint's description
of the model) comes in through the table and the :class:`CheckpointWriter`'s ``describe``.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

import torch

from meshgen import __version__
from meshgen.errors import MeshgenError
from meshgen.neural import checkpoint as checkpoints
from meshgen.neural.config import to_dict, to_yaml
from meshgen.neural.history import DivergenceGuard, TrainState, format_row, open_history, read_rows, state_to_checkpoint
from meshgen.neural.steps import Training

__all__ = [
    "CONFIG_HEADER",
    "OPTIMIZER_KEYS",
    "CheckpointWriter",
    "Job",
    "Stage",
    "TrainResult",
    "TrainingDiverged",
    "check_optimizer_state",
    "check_resumable",
    "run_stages",
]

CONFIG_HEADER = "# meshgen train: the resolved configuration of this run (repeat it with --config FILE)\n"


class TrainingDiverged(MeshgenError):
    """The loss stayed non-finite after every allowed learning-rate reduction."""


@dataclass(frozen=True)
class Stage:
    """One stage of training: how to make its optimiser, the fixed points it uses, one step, and
    what to do before its first step. The runner never branches on a stage's name."""

    name: str
    optimizer: Callable  # (Training) -> (optimizer, scheduler or None)
    points: Callable  # (Training, TrainState) -> the stage's fixed points (or a step object)
    step: Callable  # (Training, optimizer, scheduler, points) -> the history row's numbers
    start: Callable = lambda training, say: None  # (Training, say) before the stage's first step
    # (Training) -> steps taken between two reads of their rows (one wait for the device)
    block: Callable = lambda training: 1
    total: Callable | None = None  # (Training) -> the stage's steps; None: the configuration's <name>.steps
    title: str | None = None  # what the progress shows (None: ``meshgen.neural.progress.STAGE_TITLES``)


@dataclass
class Job:
    """A run set up for the runner (``meshgen.neural.train.train``): the Training and its
    TrainState, the stage table, ``describe()`` (what the checkpoint records of the model, the
    geometry and the held-out loss) and ``summary(checkpoint, run_dir)`` (the end-of-run quality
    summary, written to ``summary.json``)."""

    training: Training
    state: TrainState
    table: tuple
    describe: Callable[[], dict]
    summary: Callable


@dataclass
class TrainResult:
    checkpoint_path: Path
    stage: str  # "done", or where an interrupted run stopped
    step: int
    interrupted: bool
    seconds: float
    test_loss: dict
    checkpoint: dict
    summary: dict | None  # the final quality summary (None when interrupted or not asked for)

    @classmethod
    def of_run(cls, saver, state, interrupted: bool, checkpoint: dict, summary: dict | None) -> TrainResult:
        """The result of a run that ``run_stages`` ended with ``checkpoint``."""
        path, seconds, loss = saver.path, checkpoint["elapsed_seconds"], checkpoint["test_loss"]
        return cls(path, state.stage, state.step, interrupted, seconds, loss, checkpoint, summary)


class CheckpointWriter:
    """Saves the whole checkpoint of a run (layout: ``checkpoint.py``) atomically: what
    ``describe()`` gives (``model``, ``geometry``, ``test_loss`` and whatever else the kind of run
    records), the configuration, the TrainState, the current stage's optimiser and the random
    state. Keeps the clock of this process's training seconds."""

    def __init__(self, training: Training, describe: Callable[[], dict], path: Path, state: TrainState):
        self.training, self.describe, self.path, self.state = training, describe, path, state
        self.optimizer = self.scheduler = None
        self.started = time.perf_counter()

    def seconds(self) -> float:
        """Training seconds so far, earlier processes of a resumed run included."""
        return self.state.elapsed + time.perf_counter() - self.started

    def save(self, history_file) -> dict:
        history_file.flush()
        t = self.training
        checkpoint = {
            "format": checkpoints.FORMAT,
            "format_version": checkpoints.FORMAT_VERSION,
            "meshgen_version": __version__,
            **self.describe(),
            "config": to_dict(t.config),
            **state_to_checkpoint(self.state, time.perf_counter() - self.started),
            "optimizer": self.optimizer.state_dict() if self.optimizer is not None else {},
            "scheduler": self.scheduler.state_dict() if self.scheduler is not None else {},
            "rng": {"sampler": t.generator.get_state(), "torch": torch.get_rng_state()},
            "device": str(t.problem.device),
        }
        checkpoints.save_checkpoint(self.path, checkpoint)
        return checkpoint


def check_resumable(stage_table, training: Training, resume: dict) -> None:
    """CheckpointError unless the optimiser and scheduler states of ``resume`` load into its stage's
    own and fit its network (``check_optimizer_state``): a damaged or stitched checkpoint fails
    here, before the run folder is written."""
    for stage in stage_table:
        if stage.name != resume["stage"] or not resume.get("optimizer"):
            continue
        optimizer, scheduler = stage.optimizer(training)
        try:
            optimizer.load_state_dict(resume["optimizer"])
            if scheduler is not None:
                scheduler.load_state_dict(resume["scheduler"])
        except (KeyError, TypeError, ValueError, RuntimeError, IndexError, AttributeError) as exc:
            raise checkpoints.CheckpointError(
                f"the checkpoint's optimiser state does not fit its stage '{stage.name}' ({type(exc).__name__}): the file is damaged"
            ) from None
        check_optimizer_state(optimizer, stage.name)


# The entries of one parameter's state that each optimiser needs to take a step.
OPTIMIZER_KEYS = {torch.optim.Adam: ("step", "exp_avg", "exp_avg_sq"), torch.optim.LBFGS: ("func_evals", "n_iter")}


def check_optimizer_state(optimizer, stage: str) -> None:
    """CheckpointError unless every parameter's loaded state has the entries its optimiser needs
    (``OPTIMIZER_KEYS``) and every tensor in it the parameter's shape (Adam's moments), a scalar
    (its step), or (L-BFGS, state on the first parameter) one flat vector of all of them."""
    flat = sum(p.numel() for group in optimizer.param_groups for p in group["params"])
    needed = OPTIMIZER_KEYS.get(type(optimizer), ())
    for group in optimizer.param_groups:
        for parameter in group["params"]:
            state = optimizer.state.get(parameter)
            if not state:
                continue
            missing = [key for key in needed if key not in state]
            values = [v for value in state.values() for v in (value if isinstance(value, (list, tuple)) else [value])]
            wrong = [
                tuple(v.shape)
                for v in values
                if isinstance(v, torch.Tensor)
                and v.dim() > 0
                and tuple(v.shape) != tuple(parameter.shape)
                and not (v.dim() == 1 and v.numel() == flat)
            ]
            if missing or wrong:
                what = (
                    f"lacks {', '.join(missing)}"
                    if missing
                    else f"holds a tensor of shape {wrong[0]} for a parameter of shape {tuple(parameter.shape)}"
                )
                raise checkpoints.CheckpointError(
                    f"the checkpoint's optimiser state of stage '{stage}' {what}: the file is damaged, it cannot be resumed"
                )


def run_stages(
    stage_table, training: Training, state: TrainState, saver: CheckpointWriter, run_dir, *, resume=None, reporter=None, stop=None
):
    """Run the stages of ``stage_table`` from where ``state`` stands to the end (or until ``stop()``
    returns True), writing ``config.yaml`` and ``history.csv`` in ``run_dir`` and checkpoints
    through ``saver``. ``resume``: the loaded checkpoint the run goes on from (its optimiser state
    is restored for the stage it stopped in). ``reporter``: ``stage(name, done, total)``,
    ``update(row, done, total)``, ``message(text)`` (``meshgen.neural.progress``), or None.
    Returns (the last checkpoint, whether the run was interrupted); raises TrainingDiverged when
    the divergence guard gives up (the last good state saved)."""
    config, run_dir, stop = training.config, Path(run_dir), stop or (lambda: False)
    say = reporter.message if reporter is not None else (lambda text: None)
    names = [stage.name for stage in stage_table]
    if resume is not None:
        check_resumable(stage_table, training, resume)  # before config.yaml and history.csv are touched
    (run_dir / "config.yaml").write_text(CONFIG_HEADER + to_yaml(config))
    history_file, history = open_history(run_dir / "history.csv", state.step if resume is not None else None)
    threads = torch.get_num_threads()
    if training.terms.pool is not None:  # the two terms run side by side, torch single-threaded
        torch.set_num_threads(1)
    interrupted = False
    try:
        for stage in stage_table[names.index(state.stage) :] if state.stage != "done" else ():
            total = stage.total(training) if stage.total is not None else getattr(config, stage.name).steps
            state.stage = stage.name
            if state.stage_step >= total:
                state.stage_step = 0
                continue
            optimizer, scheduler = stage.optimizer(training)
            saver.optimizer, saver.scheduler = optimizer, scheduler
            if resume is not None and resume["stage"] == stage.name and resume["optimizer"]:
                optimizer.load_state_dict(resume["optimizer"])
                if scheduler is not None:
                    scheduler.load_state_dict(resume["scheduler"])
            points = stage.points(training, state)
            if state.stage_step == 0:
                stage.start(training, say)
            if reporter is not None:
                reporter.stage(stage.title or stage.name, state.stage_step, total)
            guard = DivergenceGuard(training, optimizer, scheduler, state)
            block = stage.block(training)
            every = config.checkpoint.every
            while state.stage_step < total and not (interrupted := stop()):
                # a block of steps, read back at once: on a GPU the host runs ahead of the device
                # instead of waiting for it at every step; it ends at a checkpoint and the stage's end
                count = min(block, total - state.stage_step, every - state.step % every)
                steps = [(stage.step(training, optimizer, scheduler, points), saver.seconds()) for _ in range(count)]
                rows, good = read_rows([numbers for numbers, _ in steps], training.network)
                if not good:  # the whole block is taken again from the last good state
                    if not guard.reject(stage.name, say):
                        saver.save(history_file)
                        raise TrainingDiverged(
                            f"training diverged: the loss stayed non-finite at step {state.step} after "
                            f"{config.guard.max_retries} learning-rate reductions; the last good state is "
                            f"saved in {saver.path}"
                        )
                    continue
                guard.accept()
                for row, (_, seconds) in zip(rows, steps):
                    row = {"stage": stage.name, "step": state.step, **row, "seconds": seconds}
                    row.setdefault("lr", optimizer.param_groups[0]["lr"])
                    row.setdefault("a1", training.weights.a()[0].item())  # the TFI fit leaves them as they are
                    row.setdefault("a2", training.weights.a()[1].item())
                    history.writerow(format_row(row))
                    state.last_row, state.stage_step, state.step = row, state.stage_step + 1, state.step + 1
                    if reporter is not None:
                        reporter.update(row, state.stage_step, total)
                if state.step % every == 0:
                    saver.save(history_file)
            if interrupted:
                break
            state.stage_step = 0
        if not interrupted:
            state.stage = "done"
            # a finished run resumes in no stage, so no optimiser state is ever read back (the
            # L-BFGS history of a block set's networks was 20 MB of a 20.1 MB checkpoint)
            saver.optimizer = saver.scheduler = None
        checkpoint = saver.save(history_file)
    finally:
        history_file.close()
        training.terms.close()
        torch.set_num_threads(threads)
    return checkpoint, interrupted
