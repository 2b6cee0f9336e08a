"""The run folder of one ``meshgen train``: claimed for that run alone, and never a folder of
another run (design notes, "Concurrency, faults and reproducible output").

- A default name (``runs/<geometry>-<timestamp>``) is taken with ``os.mkdir``, or ``-2``, ``-3``
  ... when another run took it first (``meshgen.run.publish.make_fresh_folder``): two trainings
  started at once never share a folder.
- The folder's lock (``meshgen.run.publish.output_lock``, not waited for) is held while the run
  trains: a second training into the same ``--out`` stops with one line.
- ``--out`` onto a folder whose checkpoint is of another geometry, other parameters or another
  configuration is refused unless ``--force`` (``check_run_folder``).
"""

from __future__ import annotations

import contextlib
import signal
from pathlib import Path

from meshgen.errors import MeshgenError
from meshgen.neural.config import to_dict
from meshgen.run.publish import make_fresh_folder, output_lock
from meshgen.run.signals import TERMINATING_SIGNALS

__all__ = ["check_run_folder", "claim_run_folder", "stop_signals"]


def check_run_folder(run_dir: Path, config, geometry, force: bool) -> None:
    """Refuse (MeshgenError) to train into a folder whose checkpoint is of another geometry,
    other parameters or another configuration, unless ``force``: the two runs' files would mix.
    A run of the same geometry and configuration is repeated in place."""
    from meshgen.neural.checkpoint import CheckpointError, load_checkpoint  # imports torch

    path = Path(run_dir) / "checkpoint.pt"
    if force or not path.is_file():
        return
    try:
        checkpoint = load_checkpoint(path)
        recorded = checkpoint["geometry"]
        same = (
            recorded["name"] == geometry.name
            and dict(recorded["params"]) == dict(geometry.values)
            and checkpoint["config"] == to_dict(config)
        )
        what = f"a run of {recorded['name']} with another configuration or parameters"
    except (CheckpointError, KeyError, TypeError):
        same, what = False, "a checkpoint this meshgen cannot read"
    if not same:
        raise MeshgenError(
            f"output folder {run_dir} holds {what}: choose another --out, continue it with --resume {path}, "
            "or replace it with --force"
        )


def claim_run_folder(run) -> tuple[bool, object]:
    """Create ``run.run_dir`` (a fresh name when ``run.fresh_name``) and hold its lock; check it
    again (``check_run_folder``) now that no other training can write there. Returns (whether
    this run created the folder, the function that releases the lock)."""
    stack = contextlib.ExitStack()
    try:
        if run.fresh_name:
            run.run_dir = make_fresh_folder(run.run_dir)
            created = True
        else:
            run.run_dir.parent.mkdir(parents=True, exist_ok=True)
            created = not run.run_dir.exists()
        stack.enter_context(output_lock(run.run_dir, wait=False))
        if not run.fresh_name:
            if run.resume is None:
                check_run_folder(run.run_dir, run.config, run.geometry, run.force)
            run.run_dir.mkdir(exist_ok=True)
    except OSError as exc:
        stack.close()
        raise MeshgenError(f"cannot create the run folder {run.run_dir}: {exc.strerror or exc}") from None
    except BaseException:
        stack.close()
        raise
    return created, stack.close


def stop_signals() -> list:
    """The signals that stop a training the way Ctrl-C does (save, then stop): SIGINT, and SIGTERM
    and SIGHUP unless the parent set them to be ignored (``nohup``)."""
    return [signal.SIGINT] + [signum for signum in TERMINATING_SIGNALS if signal.getsignal(signum) is not signal.SIG_IGN]
