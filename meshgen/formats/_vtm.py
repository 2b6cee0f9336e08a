"""VTK multiblock (.vtm): one structured .vts file per block in the folder ``<name>/`` beside
``<name>.vtm``, which lists them (ParaView opens the .vtm and shows each block by its name).

The .vtm, VTK's XML multiblock format::

    <VTKFile type="vtkMultiBlockDataSet" version="1.0" byte_order="LittleEndian">
      <vtkMultiBlockDataSet>
        <DataSet index="0" name="core" file="pipe/core.vts"/>
        ...
"""

from __future__ import annotations

import os
import re
from pathlib import Path

from meshgen.formats._vts import write
from meshgen.formats._xml import quoteattr
from meshgen.run.atomic import atomic_path, check_pieces_folder

__all__ = ["check_target", "write_blocks_vtm"]

LISTING_BYTES = 1 << 20  # a .vtm larger than this is no listing meshgen wrote: its folder is not claimed


def _listed_pieces(path: Path) -> set[str]:
    """The file names in ``<name>/`` that the existing .vtm at ``path`` lists (empty when there is
    no such .vtm, or it is not a regular file of at most ``LISTING_BYTES``)."""
    try:
        if path.is_symlink() or not path.is_file() or path.stat().st_size > LISTING_BYTES:
            return set()
        text = path.read_text(errors="replace")
    except OSError:
        return set()
    prefix = path.with_suffix("").name + "/"
    files = re.findall(r'<DataSet\b[^>]*\bfile="([^"]*)"', text)
    return {name[len(prefix) :] for name in files if name.startswith(prefix) and "/" not in name[len(prefix) :]}


def check_target(path) -> None:
    """FormatError when ``<name>/`` beside ``path`` exists and is not the pieces folder of the
    .vtm at ``path`` (only .vts files that the existing .vtm lists): writing would replace a file
    of the user's (``meshgen.run.atomic.check_pieces_folder``, as a .pvts checks its own)."""
    listed = _listed_pieces(Path(path))
    check_pieces_folder(path, lambda entry: entry in listed and entry.endswith(".vts"), "files the .vtm lists")


def write_blocks_vtm(path, zones, metadata) -> Path:
    """Write ``zones`` [(block name, node array X, patches covering all of the block's faces)] as
    ``<folder>/<block>.vts`` each, then ``path`` (the .vtm) atomically. Returns ``path``."""

    path = Path(path)
    check_target(path)
    folder = path.with_suffix("")
    if not os.path.lexists(folder):
        os.mkdir(folder)
    lines = []
    for index, (name, X, patches) in enumerate(zones):
        target = folder / f"{name}.vts"
        with atomic_path(target) as temporary:
            write(temporary, X, {}, metadata, patches)
        lines.append(f'    <DataSet index="{index}" name={quoteattr(name)} file={quoteattr(f"{folder.name}/{name}.vts")}/>\n')
    with atomic_path(path) as temporary:
        Path(temporary).write_text(
            '<?xml version="1.0"?>\n<VTKFile type="vtkMultiBlockDataSet" version="1.0" byte_order="LittleEndian">\n'
            f"  <vtkMultiBlockDataSet>\n{''.join(lines)}  </vtkMultiBlockDataSet>\n</VTKFile>\n"
        )
    return path
