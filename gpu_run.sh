set -x
nvidia-smi -L
python -c "import torch,numpy,scipy;print(torch.__version__, torch.cuda.is_available())"
python -c "import numba; print(numba.__version__)"
export PYTHONPATH=$PWD
timeout 150 python -m pytest -q -o addopts="" -p no:cacheprovider tests/test_elliptic_torch.py -k "cuda or operator or cyclic" 2>&1 | tail -5
timeout 330 python - <<'PY'
import json, os, sys, time
sys.path.insert(0, "benchmarks")
from bench_elliptic import gpu_elliptic_row
rows = []
for n, tol, cpu3d in ((48, 1e-12, True), (100, 1e-12, False), (100, 1e-6, False)):
    t = time.perf_counter()
    row = gpu_elliptic_row(n, "cuda", tol=tol, cpu_3d=cpu3d)
    row["wall_of_row"] = time.perf_counter() - t
    rows.append(row)
    print(json.dumps({k: v for k, v in row.items() if k != "levels_3d"}), flush=True)
    json.dump(rows, open(os.environ["OUT"] + "/rows.json", "w"), indent=1)
PY
