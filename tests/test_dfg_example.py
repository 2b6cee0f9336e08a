"""examples/dfg/run_dfg.py end to end on a coarse mesh: meshgen's dfg-cylinder case, simpleFoam,
drag and pressure difference against Schaefer and Turek's reference values (the benchmark rows at
2.4k, 9.6k and 38k cells are in benchmarks/bench_blocks.py: too slow for the test suite)."""

import sys

from conftest import REPO
from openfoam_helpers import needs_openfoam

from meshgen.geometry.blocks import load_block_set


@needs_openfoam
def test_dfg_example_runs_and_is_near_the_reference(tmp_path):
    sys.path.insert(0, str(REPO / "examples" / "dfg"))
    try:
        from run_dfg import REFERENCE, run
    finally:
        sys.path.remove(str(REPO / "examples" / "dfg"))
    result = run((6, 4), "tfi", tmp_path / "case", quiet=True)
    assert result["cells"] == load_block_set("dfg-cylinder", None, (6, 4)).cells
    assert result["converged"] and result["drag_change_last_50"] < 1e-6  # residual controls met, forces flat
    # 324 cells: within 3% in drag and 5% in the front-back pressure difference.
    assert abs(result["drag"] / REFERENCE["drag"] - 1) < 0.03
    assert abs(result["dp"] / REFERENCE["dp"] - 1) < 0.05
