"""Write and read time and file size of every mesh format, on the semicylinder by TFI.

    python benchmarks/formats.py [--cells 100] [--repeat 3] [--json benchmarks/formats.json]

Times are the best of ``--repeat`` runs (a cell-data array and the metadata included, as
``meshgen mesh`` and ``evaluate`` write them); "meshio vtu" is meshio's own zlib .vtu of the same
mesh, the baseline DESIGN section 9 quotes.
"""

from __future__ import annotations

import argparse
import json
import os
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from meshgen.formats import FORMATS, read_mesh, write_mesh  # noqa: E402
from meshgen.geometry import load_geometry  # noqa: E402
from meshgen.grid import cell_connectivity, flat_points  # noqa: E402
from meshgen.tfi import tfi  # noqa: E402


def best_time(function, repeat: int) -> float:
    times = []
    for _ in range(repeat):
        start = time.perf_counter()
        function()
        times.append(time.perf_counter() - start)
    return min(times)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--cells", type=int, default=100, help="cells per axis")
    parser.add_argument("--repeat", type=int, default=3)
    parser.add_argument("--json", type=Path, default=Path(__file__).with_name("formats.json"))
    args = parser.parse_args()

    dims = (args.cells,) * 3
    X = tfi(load_geometry("semicylinder"), dims)
    cell_data = {"quality": np.random.default_rng(0).random(int(np.prod(dims)))}
    metadata = {"method": "tfi", "geometry": "semicylinder", "dims": list(dims)}
    rows = []
    with tempfile.TemporaryDirectory() as folder:
        for fmt in FORMATS:
            for extension in fmt.extensions:
                path = Path(folder) / f"mesh{extension}"
                write = best_time(lambda: write_mesh(path, X, cell_data, metadata), args.repeat)
                read = best_time(lambda: read_mesh(path), args.repeat)
                rows.append({"format": extension, "write_s": write, "read_s": read, "size_mb": os.path.getsize(path) / 1e6})

        import meshio

        path = Path(folder) / "meshio.vtu"
        mesh = meshio.Mesh(flat_points(X), [("hexahedron", cell_connectivity(X.shape[:-1]))], cell_data={"quality": [cell_data["quality"]]})
        write = best_time(lambda: meshio.write(path, mesh, compression="zlib"), args.repeat)
        read = best_time(lambda: meshio.read(path), args.repeat)
        rows.append({"format": "meshio vtu", "write_s": write, "read_s": read, "size_mb": os.path.getsize(path) / 1e6})

    print(f"{' x '.join(map(str, dims))} cells, best of {args.repeat}")
    print(f"{'format':<12}{'write [s]':>10}{'read [s]':>10}{'size [MB]':>11}")
    for row in rows:
        print(f"{row['format']:<12}{row['write_s']:>10.2f}{row['read_s']:>10.2f}{row['size_mb']:>11.1f}")
    args.json.write_text(json.dumps({"cells": list(dims), "repeat": args.repeat, "results": rows}, indent=2) + "\n")
    print(f"wrote {args.json}")


if __name__ == "__main__":
    main()
