"""Concurrency, faults and reproducible output (design notes, "Concurrency, faults and
reproducible output"), driven through the real command line: concurrent runs, signals and full
disks in child processes (``hardening_helpers.py`` stops a child at a known point of a write),
the rest in this process. The table of these classes is in tests/test_hardening.py's docstring.
"""

from __future__ import annotations

import json
import os
import re
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest
from click.testing import CliRunner
from helpers import files_in as snapshot
from helpers import full_disk_temporaries
from neural_helpers import TINY

from meshgen.cli import cli
from meshgen.formats import metadata_of, read_mesh
from meshgen.run.publish import output_lock

REPO = Path(__file__).resolve().parents[1]
HELPERS = Path(__file__).resolve().parent / "hardening_helpers.py"
LEFTOVER = re.compile(r"^\..*\.(tmp|old)-\d+|^\..*\.lock$")  # temporaries, set-aside files, locks
# The smallest training that writes a whole run folder.
QUICK = [*TINY, "pretrain.steps=1", "adam.steps=1", "lbfgs.steps=0"]
QUICK_ARGS = [arg for item in QUICK for arg in ("--set", item)]


def invoke(*args):
    return CliRunner().invoke(cli, [str(a) for a in args])


def environment() -> dict:
    env = {**os.environ, "PYTHONPATH": str(REPO), "OMP_WAIT_POLICY": "PASSIVE"}
    env.pop("MESHGEN_DEBUG", None)
    return env


def start(folder: Path, *args, helper: tuple = (), preexec_fn=None) -> subprocess.Popen:
    """``meshgen ARGS`` in a child process; ``helper``: (kind, marker, call) of hardening_helpers.py."""
    command = [sys.executable, str(HELPERS), *map(str, helper)] if helper else [sys.executable, "-m", "meshgen"]
    return subprocess.Popen(
        [*command, *map(str, args)],
        cwd=folder,
        env=environment(),
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
        preexec_fn=preexec_fn,
    )


def start_stalled(children, folder: Path, kind: str, call: int, *args) -> tuple[subprocess.Popen, Path]:
    """A child whose ``call``-th step of ``kind`` stops and waits; returns it once it waits."""
    marker = folder / f"stalled-{len(children)}"
    process = start(folder, *args, helper=(kind, marker, call))
    children.append(process)
    deadline = time.time() + 120
    while not marker.exists():
        if process.poll() is not None or time.time() > deadline:
            process.kill()
            pytest.fail(f"the child never stalled: {process.communicate()}")
        time.sleep(0.02)
    return process, marker


def leftovers(folder: Path) -> list[str]:
    return sorted(str(p.relative_to(folder)) for p in folder.rglob("*") if LEFTOVER.match(p.name))


def one_line(stderr: str, *fragments) -> str:
    lines = stderr.splitlines()
    assert len(lines) == 1 and "Traceback" not in stderr, stderr
    for fragment in fragments:
        assert fragment in lines[0], (fragment, lines[0])
    return lines[0]


def dead_pid() -> int:
    """The pid of a process that has ended."""
    process = subprocess.Popen([sys.executable, "-c", "pass"])
    process.wait()
    return process.pid


# ---------------------------------------------------------------------------------------------
# concurrent runs lose nothing


def test_two_meshes_written_at_once_end_as_the_mesh_and_sidecar_of_one_run(tmp_path, children):
    """The first run stops between renaming its mesh and its sidecar, its lock held; the second
    (another method and size) must wait for it, so each run's pair takes its names together."""
    first, _ = start_stalled(
        children, tmp_path, "publish-rename", 1, "mesh", "-m", "tfi", "-g", "semidisk", "--dims", 8, 6, "-o", "x.vtu", "-q"
    )
    second = start(tmp_path, "mesh", "-m", "elliptic", "-g", "semidisk", "--dims", 5, 9, "-o", "x.vtu", "-q")
    children.append(second)
    staged = [rf"\.x\.tmp-{second.pid}-[0-9a-f]+\.vtu", rf"\.x\.vtu\.quality\.tmp-{second.pid}-[0-9a-f]+\.json"]

    def all_staged():
        names = os.listdir(tmp_path)
        return all(any(re.fullmatch(pattern, name) for name in names) for pattern in staged)

    deadline = time.time() + 60
    while not all_staged() and second.poll() is None and time.time() < deadline:
        time.sleep(0.02)
    time.sleep(0.5)
    assert second.poll() is None, second.communicate()  # waits for the first run's lock
    (tmp_path / "stalled-0.go").touch()
    for process in (first, second):
        assert process.wait(timeout=60) == 0, process.communicate()
    recorded = metadata_of(tmp_path / "x.vtu")
    sidecar = json.loads((tmp_path / "x.vtu.quality.json").read_text())
    assert recorded["method"] == sidecar["method"] == "elliptic" and recorded["dims"] == sidecar["dims"] == [5, 9]
    assert len(read_mesh(tmp_path / "x.vtu").cells[0].data) == sidecar["cells"] == 45
    assert leftovers(tmp_path) == []


def test_two_openfoam_writes_into_a_new_case_leave_one_complete_case(tmp_path, children):
    """The first run makes the case and stops with its polyMesh half published; the second writes
    its whole case there; SIGTERM ends the first, which removes what it wrote and nothing else."""
    args = ["mesh", "-m", "tfi", "-g", "semicylinder", "--format", "openfoam", "-o", "case", "-q", "--dims"]
    first, _ = start_stalled(children, tmp_path, "openfoam-polymesh", 1, *args, 4, 3, 5)
    assert (tmp_path / "case" / "constant").is_dir()  # made by the first run
    second = start(tmp_path, *args, 5, 4, 3)
    assert second.wait(timeout=120) == 0, second.communicate()
    first.send_signal(signal.SIGTERM)
    _, stderr = first.communicate(timeout=60)
    assert first.returncode == 128 + signal.SIGTERM
    one_line(stderr, "Terminated (SIGTERM)")
    mesh = read_mesh(tmp_path / "case")
    assert len(mesh.points) == 6 * 5 * 4 and metadata_of(mesh)["dims"] == [5, 4, 3]
    assert {"controlDict", "fvSchemes", "fvSolution"} <= set(os.listdir(tmp_path / "case" / "system"))
    assert leftovers(tmp_path) == []


@pytest.fixture(scope="module")
def two_runs(tmp_path_factory) -> Path:
    """Two ``meshgen train`` started at once in one folder, their clock on the same second."""
    folder = tmp_path_factory.mktemp("together")
    args = ["train", "-g", "semidisk", "--preset", "2d", *QUICK_ARGS, "-q"]
    processes = [start(folder, *args, helper=("same-second", "-", 0)) for _ in range(2)]
    for process in processes:
        stdout, stderr = process.communicate(timeout=300)
        assert process.returncode == 0, stderr
    return folder


def test_two_trainings_started_in_one_folder_get_their_own_run_folders(two_runs):
    runs = sorted(p.name for p in (two_runs / "runs").iterdir())
    assert runs == ["semidisk-20260101-000000", "semidisk-20260101-000000-2"]
    for run in runs:
        folder = two_runs / "runs" / run
        assert {"checkpoint.pt", "config.yaml", "history.csv", "summary.json"} <= set(os.listdir(folder))
        rows = (folder / "history.csv").read_text().splitlines()
        assert len(rows) == 1 + 2  # a header and one row per step: no run wrote into the other's history
    assert leftovers(two_runs) == []


def same_data(a, b) -> bool:
    """Equal plain data; tensors equal bit for bit."""
    import torch

    if isinstance(a, torch.Tensor):
        return isinstance(b, torch.Tensor) and a.dtype == b.dtype and a.shape == b.shape and torch.equal(a, b)
    if isinstance(a, dict):
        return isinstance(b, dict) and list(a) == list(b) and all(same_data(a[key], b[key]) for key in a)
    if isinstance(a, (list, tuple)):
        return type(a) is type(b) and len(a) == len(b) and all(same_data(x, y) for x, y in zip(a, b))
    return a == b or (a != a and b != b)


def test_two_identical_seeded_trainings_differ_only_in_their_timings(two_runs):
    """The two runs above had the same seed and configuration: their run folders are the same
    but for the wall-clock timings the design notes name ("Same input, same bytes"): config.yaml
    byte for byte, the checkpoint's every tensor and entry, the history but
    its ``seconds`` column, the summary but its ``*_seconds`` keys."""
    import csv

    import torch

    from meshgen.formats.metadata import without_timings

    a, b = (two_runs / "runs" / name for name in ("semidisk-20260101-000000", "semidisk-20260101-000000-2"))
    assert (a / "config.yaml").read_bytes() == (b / "config.yaml").read_bytes()
    checkpoints = [torch.load(run / "checkpoint.pt", weights_only=True) for run in (a, b)]
    for checkpoint in checkpoints:
        assert checkpoint["elapsed_seconds"] > 0
        del checkpoint["elapsed_seconds"], checkpoint["history"]["last"]["seconds"]
    assert same_data(*checkpoints)
    histories = []
    for run in (a, b):
        with open(run / "history.csv", newline="") as handle:
            histories.append([{k: v for k, v in row.items() if k != "seconds"} for row in csv.DictReader(handle)])
    assert histories[0] == histories[1]
    summaries = [json.loads((run / "summary.json").read_text()) for run in (a, b)]
    assert without_timings(summaries[0]) == without_timings(summaries[1])


def test_training_into_a_run_of_another_configuration_refuses_unless_forced(two_runs, tmp_path):
    run = two_runs / "runs" / "semidisk-20260101-000000"
    before = snapshot(run)
    for other in (["--set", "adam.lr=5e-4"], ["--param", "radius=2"]):
        result = invoke("train", "-g", "semidisk", "--preset", "2d", *QUICK_ARGS, *other, "--out", run, "-q")
        assert result.exit_code == 2, result.output
        one_line(result.stderr, f"output folder {run} holds a run of semidisk", "--force", "--resume")
    assert snapshot(run) == before
    # The same geometry and configuration repeats the run in place; --force replaces another one.
    with output_lock(run):  # ... but never while another training holds the folder
        result = invoke("train", "-g", "semidisk", "--preset", "2d", *QUICK_ARGS, "--out", run, "--force", "-q")
    assert result.exit_code == 2
    one_line(result.stderr, f"{run} is in use by another meshgen process")
    assert snapshot(run) == before


# ---------------------------------------------------------------------------------------------
# every fault is one line and leaves nothing behind


@pytest.mark.parametrize("signum", [signal.SIGTERM, signal.SIGHUP], ids=["SIGTERM", "SIGHUP"])
def test_a_terminating_signal_during_a_write_keeps_the_old_file_and_leaves_no_temporary(tmp_path, children, signum):
    mesh = ["mesh", "-m", "tfi", "-g", "semidisk", "--dims", 40, 30, "-o", "m.xyz", "-q"]
    assert invoke(*mesh[:6], 3, 2, *mesh[8:]).exit_code == 0  # an older, smaller mesh and its sidecar
    before = snapshot(tmp_path)
    process, marker = start_stalled(children, tmp_path, "plot3d-record", 2, *mesh)
    assert (tmp_path / Path(marker.read_text()).name).stat().st_size > 0  # the signal hits a half-written file
    process.send_signal(signum)
    _, stderr = process.communicate(timeout=60)
    assert process.returncode == 128 + signum
    one_line(stderr, f"Terminated ({signal.Signals(signum).name})")
    assert snapshot(tmp_path) == before


def test_stale_temporaries_of_gone_processes_are_removed_by_the_next_write(tmp_path, children, run_cli_process):
    """SIGKILL (no cleanup can run) during a Plot3D write and during an OpenFOAM write: their
    temporaries stay until the next run that writes there removes them; a temporary whose
    process is alive (this test's) is kept."""
    xyz = ["mesh", "-m", "tfi", "-g", "semidisk", "--dims", 40, 30, "-o", "m.xyz", "-q"]
    case = ["mesh", "-m", "tfi", "-g", "semicylinder", "--dims", 4, 3, 5, "--format", "openfoam", "-o", "case", "-q"]
    assert invoke(*case).exit_code == 0
    for kind, args in (("plot3d-record", xyz), ("openfoam-polymesh", case)):
        process, _ = start_stalled(children, tmp_path, kind, 2 if kind == "plot3d-record" else 1, *args)
        process.send_signal(signal.SIGKILL)
        process.wait(timeout=30)
    stale = leftovers(tmp_path)
    assert ".m.tmp-" in " ".join(stale) and "case/constant/.polyMesh.tmp-" in " ".join(stale), stale
    gone = dead_pid()
    for name in (f"case/.0.tmp-{gone}", f"case/system/.controlDict.tmp-{gone}", f".m.xyz.quality.tmp-{gone}.json"):
        (tmp_path / name).write_text("left by a killed run\n")
    alive = tmp_path / f".m.tmp-{os.getpid()}.xyz"
    alive.write_text("being written\n")
    for args in (xyz, case):
        result = run_cli_process(*args)  # another process: the live temporary is not its own
        assert result.returncode == 0, result.stderr
    assert leftovers(tmp_path) == [alive.name]
    assert len(read_mesh(tmp_path / "m.xyz").points) == 41 * 31 and len(read_mesh(tmp_path / "case").points) == 5 * 4 * 6


def small_disk(folder: Path, size: int):
    """(folder, preexec_fn): a tmpfs of ``size`` bytes mounted at ``folder`` (a real full disk,
    ENOSPC) where this user may mount, else a plain folder and a child limit on file sizes
    (RLIMIT_FSIZE: EFBIG, "File too large")."""
    folder.mkdir()
    mounted = subprocess.run(["mount", "-t", "tmpfs", "-o", f"size={size}", "tmpfs", str(folder)], capture_output=True)
    if mounted.returncode == 0:
        return True, None

    def limit():
        import resource

        signal.signal(signal.SIGXFSZ, signal.SIG_IGN)
        resource.setrlimit(resource.RLIMIT_FSIZE, (size, size))

    return False, limit


@pytest.fixture
def full_disk(tmp_path):
    folder = tmp_path / "disk"
    mounted, limit = small_disk(folder, 1024 * 1024)
    yield folder, limit
    if mounted:
        subprocess.run(["umount", str(folder)], check=False)


def test_a_full_disk_writing_cgns_is_one_line_and_leaves_nothing(full_disk, children):
    """The nodes fit the disk (the free-space check passes), the per-cell arrays do not: h5py
    reports the full disk as an OSError or a RuntimeError, depending on where the write stops;
    either is one line, exit 2, and the folder is left as it was (empty)."""
    folder, limit = full_disk
    process = start(
        folder, "mesh", "-m", "tfi", "-g", "semicylinder", "--dims", 30, 30, 30, "-o", "m.cgns", "-q", preexec_fn=limit
    )
    children.append(process)
    _, stderr = process.communicate(timeout=300)
    assert process.returncode == 2, stderr
    one_line(stderr, "Error: could not write m.cgns", "No space left on device" if limit is None else "File too large")
    assert os.listdir(folder) == []


def test_a_full_disk_at_the_sidecar_keeps_the_previous_mesh_and_sidecar(tmp_path, monkeypatch):
    """The mesh is written whole, then its sidecar hits a full disk (/dev/full: the kernel's
    ENOSPC): neither takes its name, and the previous pair stays byte for byte."""
    mesh = ["mesh", "-m", "tfi", "-g", "semidisk", "-o", "m.vtu", "-q", "--dims"]
    assert invoke(*mesh, 3, 2).exit_code == 0
    before = snapshot(tmp_path)
    made = full_disk_temporaries(monkeypatch, "m.vtu.quality.json")
    result = invoke(*mesh, 6, 5)
    assert len(made) == 1 and not os.path.lexists(made[0])
    assert result.exit_code == 2, result.output
    one_line(result.stderr, "m.vtu.quality.json", "No space left on device")
    assert snapshot(tmp_path) == before


def test_a_checkpoint_write_failing_in_torch_is_one_line(tmp_path, monkeypatch):
    """torch reports a write it could not finish as a RuntimeError (on a full tmpfs: "unexpected
    pos"); it is the checkpoint's one-line error and the previous checkpoint stays."""
    import torch

    from meshgen.neural.checkpoint import CheckpointError, save_checkpoint

    path = tmp_path / "checkpoint.pt"
    save_checkpoint(path, {"step": 1})
    before = path.read_bytes()

    def short_write(*args, **kwargs):
        raise RuntimeError("[enforce fail at inline_container.cc:672] . unexpected pos 8256 vs 8144")

    monkeypatch.setattr(torch, "save", short_write)
    with pytest.raises(CheckpointError, match=r"could not write checkpoint .*unexpected pos .*previous checkpoint there is kept"):
        save_checkpoint(path, {"step": 2})
    assert path.read_bytes() == before and os.listdir(tmp_path) == ["checkpoint.pt"]


@pytest.mark.parametrize("chunked", [False, True], ids=["vtu", "cgns-chunked"])
def test_a_mesh_written_without_its_sidecar_removes_the_previous_one(tmp_path, chunked):
    """``--no-quality`` publishes the mesh alone: the sidecar of the previous mesh under that name
    goes with it (it would describe, and time, another mesh)."""
    name = "m.cgns" if chunked else "m.vtu"
    mesh = ["mesh", "-m", "tfi", "-g", "semidisk", "-o", name, "-q", *(["--chunked"] if chunked else []), "--dims"]
    assert invoke(*mesh, 3, 2).exit_code == 0 and (tmp_path / f"{name}.quality.json").is_file()
    result = invoke(*mesh, 6, 5, "--no-quality")
    assert result.exit_code == 0, result.output
    assert sorted(os.listdir(tmp_path)) == [name] and metadata_of(tmp_path / name)["dims"] == [6, 5]


# ---------------------------------------------------------------------------------------------
# same input, same bytes

SAME_BYTES = {
    ".vtu": ["-m", "elliptic", "-o", "m.vtu"],
    ".vts": ["-m", "elliptic", "-o", "m.vts"],
    ".cgns": ["-m", "elliptic", "-o", "m.cgns"],
    ".cgns-chunked": ["-m", "tfi", "--chunked", "-o", "m.cgns"],
    ".su2": ["-m", "elliptic", "-o", "m.su2"],
    ".msh": ["-m", "elliptic", "-o", "m.msh"],
    "openfoam": ["-m", "elliptic", "--format", "openfoam", "-o", "case"],
}


@pytest.mark.parametrize("row", list(SAME_BYTES))
def test_the_same_input_gives_the_same_bytes(row, tmp_path, monkeypatch):
    """Two identical runs write byte-identical mesh files (every file of a case); the timings
    live in the sidecar alone, which evaluate and compare still read."""
    from meshgen.quality import recorded_metadata

    for run in ("a", "b"):
        (tmp_path / run).mkdir()
        monkeypatch.chdir(tmp_path / run)
        result = invoke("mesh", "-g", "semicylinder", "--dims", 5, 4, 6, *SAME_BYTES[row], "-q")
        assert result.exit_code == 0, result.output
    a, b = (snapshot(tmp_path / run) for run in ("a", "b"))
    sidecars = [name for name in a if name.endswith(".quality.json")]
    assert len(sidecars) == 1
    for name in sidecars:
        del a[name], b[name]
    assert a == b and len(a) >= 1
    output = tmp_path / "a" / SAME_BYTES[row][-1]
    sidecar = json.loads((tmp_path / "a" / sidecars[0]).read_text())
    recorded = metadata_of(output)
    assert recorded["method"] == SAME_BYTES[row][1] and "seconds" not in json.dumps(recorded)
    assert "quality_seconds" in sidecar
    if row != ".cgns-chunked":  # (the chunked path records its timings on the terminal)
        assert recorded_metadata(output, read_mesh(output))["meshing_seconds"] == sidecar["meshing_seconds"]
