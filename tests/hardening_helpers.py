"""Run ``meshgen`` in a child process whose N-th write of one kind stops half-way and waits to be
killed, so that tests/test_hardening.py can signal the process at a known point of a file write
instead of at a random moment.

    python tests/hardening_helpers.py KIND MARKER N meshgen-arguments...

KIND is ``torch-save`` (the N-th ``torch.save``: a checkpoint), ``plot3d-record`` (the N-th
record of a Plot3D file), ``openfoam-polymesh`` (after the N-th polyMesh is written under its
temporary name), ``publish-rename`` (after the N-th rename of a publication, its lock held), or
``same-second`` (no stall: the clock that names run folders reads one fixed second), or
``make-mesh`` (before the N-th mesh a request computes: a compare row). The stalled write puts the first half of its bytes where the real
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
    _wait(marker, where)


def _wait(marker: str, where) -> None:
    """Write ``marker`` (holding ``where``), then wait for ``marker``.go or to be killed."""
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


def stall_openfoam_poly_mesh(marker: str, call: int) -> None:
    """Stop once the N-th polyMesh is written under its temporary name (the case folder made)."""
    from meshgen.formats import _openfoam

    real_write = _openfoam._write_poly_mesh
    calls = [0]

    def write_poly_mesh(folder, *args):
        real_write(folder, *args)
        calls[0] += 1
        if calls[0] == call:
            _wait(marker, folder)

    _openfoam._write_poly_mesh = write_poly_mesh


def stall_publish_rename(marker: str, call: int) -> None:
    """Stop after the N-th rename of a publication (meshgen.run.publish), its lock held: the mesh has
    its name, the sidecar not yet."""
    from meshgen import publish

    real_replace = publish.replace_into
    calls = [0]

    def replace_into(source, target):
        aside = real_replace(source, target)
        calls[0] += 1
        if calls[0] == call:
            _wait(marker, target)
        return aside

    publish.replace_into = replace_into


def same_second(marker: str, call: int) -> None:
    """No stall: the clock reads the same second in every process, as for two runs started at once."""
    import time

    real_strftime = time.strftime
    time.strftime = lambda text, *rest: "20260101-000000" if text == "%Y%m%d-%H%M%S" else real_strftime(text, *rest)


def stall_make_mesh(marker: str, call: int) -> None:
    import meshgen.run.request as request

    real_make_mesh = request.make_mesh
    calls = [0]

    def make_mesh(*args, **kwargs):
        calls[0] += 1
        if calls[0] == call:
            _wait(marker, "make_mesh")
        return real_make_mesh(*args, **kwargs)

    request.make_mesh = make_mesh


def main() -> None:
    kind, marker, call, *arguments = sys.argv[1:]
    stalls = {
        "torch-save": stall_torch_save,
        "plot3d-record": stall_plot3d_record,
        "openfoam-polymesh": stall_openfoam_poly_mesh,
        "publish-rename": stall_publish_rename,
        "same-second": same_second,
        "make-mesh": stall_make_mesh,
    }
    stalls[kind](marker, int(call))
    from meshgen.cli import main as meshgen_main

    sys.argv = ["meshgen", *arguments]
    meshgen_main()


if __name__ == "__main__":
    main()
