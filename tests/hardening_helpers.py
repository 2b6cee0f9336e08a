"""Run ``meshgen`` in a child process whose N-th write of one kind stops half-way and waits to be
killed, so that tests/test_hardening.py can signal the process at a known point of a file write
instead of at a random moment.

    python tests/hardening_helpers.py KIND MARKER N meshgen-arguments...

KIND is ``torch-save`` (the N-th ``torch.save``: a checkpoint) or ``plot3d-record`` (the N-th
record of a Plot3D file). The stalled write puts the first half of its bytes where the real
write would have put them (whatever file meshgen handed it: a temporary name or the target
itself), flushes them to disk, writes MARKER (holding that file's name) and waits: for the file
MARKER.go, after which it writes the rest, or to be killed. Only the timing is staged: the file,
the process and the signal are real.
"""

from __future__ import annotations

import io
import os
import sys
import time
from pathlib import Path

STALL_SECONDS = 60


def _stall(handle, marker: str, where) -> None:
    """Flush what is written, write ``marker``, then wait until the file ``marker``.go appears
    (the test lets the write finish) or the process is killed; at most ``STALL_SECONDS``."""
    handle.flush()
    os.fsync(handle.fileno())
    temporary = Path(marker + ".part")
    temporary.write_text(str(where))
    os.replace(temporary, marker)  # the marker appears whole: the test never reads half a name
    go = Path(marker + ".go")
    deadline = time.monotonic() + STALL_SECONDS
    while not go.exists() and time.monotonic() < deadline:
        time.sleep(0.02)  # a signal handler that raises (a second Ctrl-C) raises here


def stall_torch_save(marker: str, call: int) -> None:
    import torch

    real_save = torch.save
    calls = [0]

    def save(obj, destination, *args, **kwargs):
        calls[0] += 1
        if calls[0] != call:
            return real_save(obj, destination, *args, **kwargs)
        buffer = io.BytesIO()
        real_save(obj, buffer, *args, **kwargs)
        data = buffer.getvalue()
        opened = isinstance(destination, (str, os.PathLike))
        handle = open(destination, "wb") if opened else destination
        name = destination if opened else getattr(destination, "name", "?")
        try:
            handle.write(data[: len(data) // 2])
            _stall(handle, marker, name)
            handle.write(data[len(data) // 2 :])  # reached only when the test lets it run on
        finally:
            if opened:
                handle.close()

    torch.save = save


def stall_plot3d_record(marker: str, call: int) -> None:
    from meshgen.formats import _plot3d

    real_record = _plot3d._write_record
    calls = [0]

    def write_record(file, values):
        real_record(file, values)
        calls[0] += 1
        if calls[0] == call:
            _stall(file, marker, file.name)

    _plot3d._write_record = write_record


def main() -> None:
    kind, marker, call, *arguments = sys.argv[1:]
    {"torch-save": stall_torch_save, "plot3d-record": stall_plot3d_record}[kind](marker, int(call))
    from meshgen.cli import main as meshgen_main

    sys.argv = ["meshgen", *arguments]
    meshgen_main()


if __name__ == "__main__":
    main()
