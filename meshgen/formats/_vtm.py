"""VTK multiblock (.vtm): one structured .vts file per block in the folder ``<name>/`` beside
``<name>.vtm``, which lists them (ParaView opens the .vtm and shows each block by its name).

The .vtm, VTK's XML multiblock format::

    <VTKFile type="vtkMultiBlockDataSet" version="1.0" byte_order="LittleEndian">
      <vtkMultiBlockDataSet>
        <DataSet index="0" name="core" file="pipe/core.vts"/>
        ...
"""

from __future__ import annotations

from pathlib import Path
from xml.sax.saxutils import quoteattr

from meshgen.formats._vts import write
from meshgen.run.atomic import atomic_path

__all__ = ["write_blocks_vtm"]


def write_blocks_vtm(path, zones, metadata) -> Path:
    """Write ``zones`` [(block name, node array X, patches covering all of the block's faces)] as
    ``<folder>/<block>.vts`` each, then ``path`` (the .vtm) atomically. Returns ``path``."""

    path = Path(path)
    folder = path.with_suffix("")
    folder.mkdir(exist_ok=True)
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
