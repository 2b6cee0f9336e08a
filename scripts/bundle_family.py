"""Train the family of airfoil sections that meshgen ships and record how it was made.

    python scripts/bundle_family.py [--from RUN_FOLDER]

1. ``meshgen train -g airfoil --vary camber=0:0.04 --vary camber_position=0.2:0.6 --vary
   thickness=0.08:0.18 --out <temporary run folder> -q`` (the README's command; ``--from``: a
   finished run of it instead, its command and times taken from its files);
2. the checkpoint, less its optimiser and scheduler state (only a resumed run needs them), saved
   with meshgen's own ``save_checkpoint`` to ``meshgen/_models/families/airfoil/checkpoint.pt``,
   where ``meshgen mesh -g airfoil --method neural --param thickness=T ...`` finds it;
3. ``model.json`` beside it: the command, versions, date, training seconds, size, and the
   training's own check of its grid of members (``summary.json``'s ``family``).
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))
sys.path.insert(1, str(REPO / "scripts"))  # bundle_model: what every bundled model records
COMMAND = ["train", "-g", "airfoil", "--vary", "camber=0:0.04", "--vary", "camber_position=0.2:0.6",
           "--vary", "thickness=0.08:0.18"]  # fmt: skip


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--from", dest="run", help="a finished run folder of the command (else one is trained now)")
    args = parser.parse_args()

    from bundle_model import bundle

    from meshgen.neural.checkpoint import load_checkpoint
    from meshgen.neural.models import MODELS_DIR

    folder = MODELS_DIR / "families" / "airfoil"
    folder.mkdir(parents=True, exist_ok=True)
    with tempfile.TemporaryDirectory() as scratch:
        run, wall = Path(args.run) if args.run else Path(scratch) / "run", None
        if not args.run:
            started = time.perf_counter()
            subprocess.run([sys.executable, "-m", "meshgen", *COMMAND, "--out", str(run), "-q"], check=True,
                           env={**os.environ, "PYTHONPATH": str(REPO)})  # fmt: skip
            wall = time.perf_counter() - started
        checkpoint = load_checkpoint(run / "checkpoint.pt")
        summary = json.loads((run / "summary.json").read_text())
    if checkpoint.get("stage") != "done":
        raise SystemExit(f"{run} holds an unfinished run")
    _, saved = bundle(checkpoint, folder, wall)
    record = {
        "command": "meshgen " + " ".join(COMMAND) + " --out <run folder> -q",
        "configuration": checkpoint["config"],
        **saved,
        "family": {k: checkpoint["model"]["family"][k] for k in ("ranges", "train_dims", "free")},
        "made_by": "python scripts/bundle_family.py " + " ".join(sys.argv[1:]),
        "check": summary["family"],
    }
    (folder / "model.json").write_text(json.dumps(record, indent=2) + "\n")
    print(json.dumps({k: record[k] for k in ("command", "training_seconds", "bytes", "sha256")}, indent=2))
    print(f"checked members: worst gap {record['check']['worst_gap']:.2f} deg, failed {len(record['check']['failed'])}")


if __name__ == "__main__":
    main()
