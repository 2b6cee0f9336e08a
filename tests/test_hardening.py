"""Hardening: bad inputs, faults and untrusted files.

meshgen runs unattended in pipelines and on files from elsewhere. Every case below has a
test: here (``test_hardening.py::...``; ``[id]`` names a row of the BAD_INPUTS, PLUGIN_FAULTS or
FULL_DISK tables below) or in another file (``file::test[id]``). ``test_the_table_names_real_tests``
checks that every test named here exists.

Bad input: one line ``Error: ...`` naming the problem on stderr, exit status 2, no traceback,
nothing in the folder created or changed (all files compared byte for byte).

| case                                  | command           | test                                                                                                  |
|---------------------------------------|-------------------|-------------------------------------------------------------------------------------------------------|
| unknown geometry                      | mesh              | test_cli_foundation.py::test_bad_input_gives_one_line_exit_2_and_writes_nothing[unknown-geometry]     |
| unknown geometry                      | geometries show   | test_cli_foundation.py::test_bad_input_gives_one_line_exit_2_and_writes_nothing[unknown-geometry-show]|
| unknown geometry                      | train             | test_neural_cli.py::test_bad_input_is_one_line_exit_2_and_writes_nothing[-g nosuch]                   |
| unknown geometry                      | evaluate          | test_hardening.py::test_bad_input[evaluate-unknown-geometry]                                          |
| unknown geometry                      | compare           | test_hardening.py::test_bad_input[compare-unknown-geometry]                                           |
| unknown preset                        | train             | test_neural_cli.py::test_bad_input_is_one_line_exit_2_and_writes_nothing[--preset nosuch]             |
| unknown method                        | mesh              | test_cli_foundation.py::test_bad_input_gives_one_line_exit_2_and_writes_nothing[unknown-method]       |
| unknown method                        | compare           | test_compare.py::test_bad_input_is_one_line_exit_2_and_nothing_written[args0-...]                     |
| unknown metric (gate quantity)        | evaluate          | test_evaluate.py::test_gate_exit_statuses                                                             |
| unknown metric (picture colour)       | compare           | test_hardening.py::test_bad_input[compare-unknown-metric]                                             |
| malformed YAML                        | train             | test_neural_cli.py::test_bad_input_is_one_line_exit_2_and_writes_nothing[--config bad.yaml]           |
| YAML of random bytes                  | train             | test_hardening.py::test_bad_input[train-config-random-bytes]                                          |
| YAML not a mapping, missing file      | train (API)       | test_neural_config.py::test_unknown_preset_and_malformed_yaml                                         |
| unknown key (--set)                   | train             | test_neural_cli.py::test_bad_input_is_one_line_exit_2_and_writes_nothing[--set adam.stepz=3]          |
| unknown key (--config file)           | train             | test_hardening.py::test_bad_input[train-config-unknown-key]                                           |
| unknown key (--set)                   | compare           | test_hardening.py::test_bad_input[compare-set-unknown-key]                                            |
| ill-typed key (--set)                 | train             | test_neural_cli.py::test_bad_input_is_one_line_exit_2_and_writes_nothing[--set adam.steps=many]       |
| ill-typed key (--config file)         | train             | test_hardening.py::test_bad_input[train-config-ill-typed]                                             |
| ill-typed key (--set)                 | compare           | test_hardening.py::test_bad_input[compare-set-ill-typed]                                              |
| bad dims (11 kinds)                   | mesh              | test_cli_foundation.py::test_bad_input_gives_one_line_exit_2_and_writes_nothing[dims-*]               |
| bad dims: 3 for a 2D geometry         | compare           | test_compare.py::test_bad_input_is_one_line_exit_2_and_nothing_written[args6-...]                     |
| bad dims: zero                        | compare           | test_hardening.py::test_bad_input[compare-dims-zero]                                                  |
| bad --param (6 kinds)                 | mesh, show        | test_cli_foundation.py::test_bad_input_gives_one_line_exit_2_and_writes_nothing[param-*]              |
| bad --param: other parameters         | train --resume    | test_neural_cli.py::test_bad_input_is_one_line_exit_2_and_writes_nothing[--resume semidisk.pt ...]    |
| bad --param: malformed, unknown       | train             | test_hardening.py::test_bad_input[train-param-malformed], [train-param-unknown]                       |
| bad --param: malformed, unknown       | evaluate          | test_hardening.py::test_bad_input[evaluate-param-malformed], [evaluate-param-unknown]                 |
| bad --param: not a number, unknown    | compare           | test_hardening.py::test_bad_input[compare-param-not-a-number], [compare-param-unknown]                |
| bad --cluster                         | mesh              | test_mesh_neural.py::test_bad_input_is_one_line_exit_2_and_writes_nothing (malformed --cluster, ratio)|
| bad --cluster                         | compare           | test_hardening.py::test_bad_input[compare-cluster-malformed], [compare-cluster-ratio]                 |
| bad gate: unknown, malformed          | evaluate          | test_evaluate.py::test_gate_exit_statuses                                                             |
| bad gate: value not a number          | evaluate          | test_hardening.py::test_bad_input[evaluate-gate-bad-value]                                            |
| output folder missing                 | mesh, show        | test_cli_foundation.py::test_bad_input_gives_one_line_exit_2_and_writes_nothing[missing-folder*]      |
| output folder missing                 | evaluate          | test_hardening.py::test_bad_input[evaluate-json-missing-folder], [evaluate-markdown-missing-folder]   |
| output folder missing                 | compare           | test_hardening.py::test_bad_input[compare-out-missing-parent]                                         |
| output folder unwritable              | mesh              | test_cli_foundation.py::test_bad_input_gives_one_line_exit_2_and_writes_nothing[folder-not-writable]  |
| output folder unwritable              | show, evaluate    | test_hardening.py::test_bad_input[show-unwritable], [evaluate-json-unwritable], [evaluate-markdown-unwritable] |
| output folder unwritable              | compare, train    | test_hardening.py::test_bad_input[compare-out-unwritable], [train-out-unwritable], [train-out-inside-unwritable] |
| output is an existing folder          | mesh              | test_cli_foundation.py::test_bad_input_gives_one_line_exit_2_and_writes_nothing[output-is-a-folder]   |
| output is an existing folder          | evaluate          | test_hardening.py::test_bad_input[evaluate-json-is-a-folder], [evaluate-markdown-is-a-folder]         |
| output folder is a file / not a run   | compare, train    | test_hardening.py::test_bad_input[compare-out-is-a-file], [train-out-is-a-file]; test_neural_cli.py [--out occupied] |
| mesh unreadable, empty, non-finite (NaN), wrong cell type | evaluate | test_evaluate.py::test_bad_input_is_one_clear_line_and_exit_2                             |
| mesh of random bytes (.xyz .cgns .msh)| evaluate          | test_hardening.py::test_bad_input[evaluate-random-xyz], [evaluate-random-cgns], [evaluate-random-msh] |
| mesh with infinite coordinates        | evaluate          | test_hardening.py::test_bad_input[evaluate-infinite]; test_hardening.py::test_bad_input_in_a_real_process |
| mesh unreadable, empty, non-finite, wrong cell type | compare | test_hardening.py::test_bad_input[compare-random-bytes], [compare-empty], [compare-non-finite], [compare-wrong-cell-type] |
| checkpoint missing, truncated, foreign| mesh              | test_mesh_neural.py::test_bad_input_is_one_line_exit_2_and_writes_nothing                             |
| checkpoint missing, truncated, text   | train --resume    | test_neural_cli.py::test_bad_input_is_one_line_exit_2_and_writes_nothing[--resume ...]                |
| checkpoint of random bytes            | mesh, train, compare | test_hardening.py::test_bad_input[mesh-checkpoint-random], [train-resume-random], [compare-checkpoint-random] |
| checkpoint of another geometry        | mesh, train       | test_mesh_neural.py::...[trained on 'semicylinder', not on 'semidisk']; test_neural_cli.py [-g semicylinder] |
| checkpoint of another dimension       | mesh              | test_mesh_neural.py::test_bad_input_is_one_line_exit_2_and_writes_nothing (is 3D: --dims needs 3)     |
| checkpoint whose map and geometry differ in dimension | mesh, train | test_hardening.py::test_bad_input[mesh-checkpoint-dimension], [train-resume-dimension]      |
| checkpoint of a future version        | mesh, train       | test_hardening.py::test_bad_input[mesh-checkpoint-future], [train-resume-future]                      |

Untrusted files:

| case                                               | test                                                                            |
|----------------------------------------------------|---------------------------------------------------------------------------------|
| checkpoint with a pickled payload: mesh            | test_mesh_neural.py::test_a_checkpoint_carrying_code_is_refused_without_running_it |
| checkpoint with a pickled payload: train, compare  | test_hardening.py::test_bad_input[train-resume-payload], [compare-checkpoint-payload] |
| YAML safe loader: --config and --set               | test_hardening.py::test_bad_input[train-config-python-tag], [train-set-python-tag] |
| plugin files are code: the README says so          | test_hardening.py::test_readme_says_plugins_are_code                            |

Trust boundary (design notes, "Trust boundary and faults"): data, sizes, files, plugins:

| case                                                         | test |
|--------------------------------------------------------------|------|
| mesh metadata (.vtu, .cgns) names a plugin file: evaluate    | test_trust.py::test_a_mesh_naming_a_plugin_file_is_evaluated_without_running_it[vtu], [cgns] |
| .quality.json sidecar names a plugin file: evaluate          | test_trust.py::test_a_mesh_naming_a_plugin_file_is_evaluated_without_running_it[sidecar] |
| checkpoint's geometry.spec names a plugin: mesh, train       | test_trust.py::test_a_checkpoint_naming_a_plugin_file_asks_for_it |
| block-set checkpoint names a plugin or a file not given: mesh | test_shapes_sweep_yaml.py::test_training_on_the_yaml_file_and_a_checkpoint_naming_a_file |
| plugin name ../../x, /abs, a/b: never a path                 | test_trust.py::test_a_plugin_name_never_becomes_a_path |
| --dims 1e10 1, 100000^3 (mesh, compare), --in-memory         | test_trust.py::test_sizes_and_numbers_are_checked_before_anything_is_allocated[mesh-one-long-axis], [compare] |
| model.widths, points.interior too large; train memory        | test_trust.py::test_sizes_and_numbers_are_checked_before_anything_is_allocated[train-widths], [train-memory] |
| inf/NaN: --set, --fail-if, --param, --cluster, --tol, --vary | test_trust.py::test_sizes_and_numbers_are_checked_before_anything_is_allocated[train-lr-inf], [gate-nan], [tol-nan] |
| CGNS zone header claims 100001^3 nodes (or sparse data)      | test_trust.py::test_sizes_and_numbers_are_checked_before_anything_is_allocated[cgns-header], [cgns-sparse] |
| every config number bounded above and below                  | test_trust.py::test_every_number_of_the_training_configuration_has_both_bounds |
| FIFO, link to /dev/zero (mesh, config, checkpoint)           | test_trust.py::test_untrusted_files_are_refused_in_one_short_line[fifo-evaluate], [zero-config] |
| YAML alias bomb, 5000 nested brackets, 100 kB value          | test_trust.py::test_untrusted_files_are_refused_in_one_short_line[alias-bomb], [deep-nesting] |
| OpenFOAM owner / neighbour list corrupt (binary, ASCII)      | test_trust.py::test_an_openfoam_case_with_a_corrupt_owner_or_neighbour_list_is_an_error |
| checkpoint with NaN weights: mesh, train --resume            | test_trust.py::test_a_checkpoint_with_nan_weights_is_an_error_and_writes_nothing |
| network output non-finite                                    | test_trust.py::test_a_non_finite_network_output_is_an_error |
| history.csv cut mid-row: --resume                            | test_trust.py::test_resume_survives_a_truncated_history |
| checkpoint's optimiser state damaged: history kept           | test_trust.py::test_a_damaged_checkpoint_fails_before_the_run_folder_changes |
| plugin raises SystemExit, GeneratorExit, BaseException       | test_trust.py::test_a_misbehaving_plugin_is_one_line_naming_it_and_the_function[system-exit], [base-exception] |
| plugin returns complex numbers, overflows, long message      | test_trust.py::test_a_misbehaving_plugin_is_one_line_naming_it_and_the_function[complex], [overflow] |
| a tear of 1% of an edge between two faces                    | test_trust.py::test_a_tear_of_one_percent_of_an_edge_is_found |

Faults:

| case                                               | test                                                                            |
|----------------------------------------------------|---------------------------------------------------------------------------------|
| SIGINT during training: checkpoint, --resume       | test_neural_cli.py::test_ctrl_c_saves_a_checkpoint_and_resume_finishes_the_run  |
| SIGINT during a checkpoint write: saves, resumes   | test_hardening.py::test_ctrl_c_during_a_checkpoint_write_saves_and_stops        |
| SIGINT twice, during a checkpoint write            | test_hardening.py::test_second_ctrl_c_during_a_checkpoint_write_keeps_the_last_checkpoint |
| SIGKILL during training (mid checkpoint write)     | test_hardening.py::test_sigkill_during_a_checkpoint_write_keeps_the_last_periodic_checkpoint |
| kill during a mesh write: no file under the name   | test_hardening.py::test_sigkill_during_a_mesh_write_leaves_no_file_under_the_target_name |
| a writer failing midway (API)                      | test_formats.py::test_a_writer_failing_midway_keeps_the_old_file_and_leaves_no_temporary |
| full disk (writes go to /dev/full: a real ENOSPC) | test_hardening.py::test_full_disk[mesh-vtu], [mesh-xdmf], [mesh-xyz], [show-stl], [evaluate-json], [train-checkpoint] |
| full disk at a run's first file (config.yaml)      | test_hardening.py::test_full_disk_when_a_run_writes_its_first_file             |

Plugins (message names the plugin and what is wrong):

| case                                               | test                                                                            |
|----------------------------------------------------|---------------------------------------------------------------------------------|
| raises, wrong shape, non-finite, not numbers: mesh | test_cli_foundation.py::test_bad_input_gives_one_line_exit_2_and_writes_nothing[plugin-*] |
| not continuous across cube edges (checked at load) | test_cli_foundation.py::...[plugin-discontinuous]; test_geometries.py::test_discontinuous_plugin_is_rejected_with_its_name |
| raises: train, evaluate, compare                   | test_hardening.py::test_plugin_fault[raises-train], [raises-evaluate], [raises-compare] |
| calls sys.exit() in boundary() or at import        | test_hardening.py::test_plugin_fault[exits-mesh], [exits-at-import-mesh]        |
| non-finite only where the load check does not look | test_hardening.py::test_plugin_fault[late-nan-mesh], [late-nan-train], [late-nan-evaluate], [late-nan-compare] |

Repeatability (CPU, same seed):

| case                                               | test                                                                            |
|----------------------------------------------------|---------------------------------------------------------------------------------|
| same seed, same weights (in-process train())       | test_neural_train.py::test_the_same_seed_repeats_a_cpu_run_and_another_seed_does_not |
| same seed: every tensor of the checkpoint, meshes  | test_hardening.py::test_same_seed_gives_bit_identical_checkpoints_and_meshes    |

Concurrency, faults and reproducible output (design notes, "Concurrency, faults and reproducible
output"; child processes for the concurrent, signal and full-disk rows):

| case                                                        | test                                                                                  |
|-------------------------------------------------------------|---------------------------------------------------------------------------------------|
| two meshes into one file at once: mesh and sidecar of one run | test_faults.py::test_two_meshes_written_at_once_end_as_the_mesh_and_sidecar_of_one_run |
| two OpenFOAM writes into a new case: one complete case      | test_faults.py::test_two_openfoam_writes_into_a_new_case_leave_one_complete_case      |
| two trainings started at once: their own run folders        | test_faults.py::test_two_trainings_started_in_one_folder_get_their_own_run_folders    |
| train --out onto a run of another config or geometry, or in use | test_faults.py::test_training_into_a_run_of_another_configuration_refuses_unless_forced |
| a mesh without sidecar removes the previous mesh's sidecar  | test_faults.py::test_a_mesh_written_without_its_sidecar_removes_the_previous_one      |
| SIGTERM, SIGHUP during a write: old file kept, no temporary | test_faults.py::test_a_terminating_signal_during_a_write_keeps_the_old_file_and_leaves_no_temporary |
| SIGTERM during an OpenFOAM write: only its own files removed | test_faults.py::test_two_openfoam_writes_into_a_new_case_leave_one_complete_case     |
| SIGKILL: stale temporaries removed by the next run          | test_faults.py::test_stale_temporaries_of_gone_processes_are_removed_by_the_next_write |
| full disk writing CGNS (h5py OSError or RuntimeError)       | test_faults.py::test_a_full_disk_writing_cgns_is_one_line_and_leaves_nothing          |
| full disk at the sidecar: mesh and sidecar rolled back      | test_faults.py::test_a_full_disk_at_the_sidecar_keeps_the_previous_mesh_and_sidecar   |
| torch's RuntimeError writing a checkpoint                   | test_faults.py::test_a_checkpoint_write_failing_in_torch_is_one_line                  |
| a library's RuntimeError in any writer (API)                | test_formats.py::test_a_writer_failing_midway_keeps_the_old_file_and_leaves_no_temporary |
| same input, same bytes: .vtu .vts .cgns .su2 .msh, a case   | test_faults.py::test_the_same_input_gives_the_same_bytes                              |
| two seeded trainings differ only in the named timings       | test_faults.py::test_two_identical_seeded_trainings_differ_only_in_their_timings      |

Each test was checked against the protection it guards (the guard disabled, the test seen to
fail, the guard restored):
- atomic_path writing to the target itself: the SIGKILL tests and the second-Ctrl-C test fail
  (half a checkpoint under checkpoint.pt, or none at all; the old mesh changed), and so do the
  full-disk rows (the write no longer goes through the temporary name: it lands on the old file);
- train's SIGINT handler not installed: both Ctrl-C tests fail (nothing saved at step 10);
- torch.load(weights_only=False) in load_checkpoint: the payload rows fail (the marker appears);
- yaml.unsafe_load in meshgen.neural.config: the python-tag rows fail (the marker appears);
- the sampler seeded from the clock: the repeatability test fails at the first weight;
- every other row fails without the guard in meshgen/ that it covers (evaluate's report
  paths, train's run folder, random-byte YAML, sys.exit in a plugin, inf coordinates, the file
  name of a Plot3D read error, the checkpoint messages, the resumed history's duplicated row, a
  full disk under torch.save or at config.yaml, the empty run folder a failed run left), or
  documents a guard that no change has yet broken (e.g. [compare-dims-zero]).
"""

from __future__ import annotations

import csv
import os
import re
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest
import torch
from click.testing import CliRunner
from helpers import files_in as snapshot
from helpers import full_disk_temporaries
from neural_helpers import TINY, tiny_config

from meshgen.cli import cli
from meshgen.formats import write_mesh
from meshgen.geometry.plugins import load_geometry
from meshgen.methods.tfi import tfi
from meshgen.neural.train import train

REPO = Path(__file__).resolve().parents[1]
HELPERS = Path(__file__).resolve().parent / "hardening_helpers.py"
TINY_ARGS = [arg for item in TINY for arg in ("--set", item)]
TEMPORARY = re.compile(r"^\..*\.tmp-\d+")  # meshgen.run.atomic's temporary names


# ---------------------------------------------------------------------------------------------
# shared set-up


@pytest.fixture(scope="module")
def semidisk_checkpoint(tmp_path_factory) -> bytes:
    """A tiny semidisk checkpoint stopped before its first step (resumable), as bytes."""
    folder = tmp_path_factory.mktemp("semidisk-run")
    train(tiny_config(), load_geometry("semidisk"), folder, stop=lambda: True, summary=False)
    return (folder / "checkpoint.pt").read_bytes()


def invoke(*args):
    """``meshgen ARGS`` in this process (click's runner calls the console script's ``main``)."""
    return CliRunner().invoke(cli, [str(a) for a in args])


def assert_one_line_error(result, *fragments, after_progress=False):
    """Exit status 2 and one line ``Error: ...`` with ``fragments`` on stderr, no traceback.
    ``after_progress``: training's log lines may come first; the error is the last line."""
    assert result.exit_code == 2, (result.exit_code, result.stdout, result.stderr)
    lines = result.stderr.splitlines()
    if after_progress:
        lines = [line for line in lines if not line.startswith(" ")][-1:]  # log lines, then the error
        assert sum(line.startswith("Error") for line in result.stderr.splitlines()) == 1, result.stderr
    assert len(lines) == 1 and lines[0].startswith("Error: "), result.stderr
    assert "Traceback" not in result.stderr + result.stdout
    for fragment in fragments:
        assert fragment in lines[0], (fragment, lines[0])


def lock(folder: Path, monkeypatch) -> None:
    """Make ``folder`` unwritable. Permission bits do not stop root (CI runs as root): there the
    folder is also reported unwritable by ``os.access``, as it is to any other user, so that the
    commands' own checks are what the test sees."""
    folder.chmod(0o555)
    if not os.access(folder, os.W_OK):
        return
    real_access = os.access
    locked = folder.resolve()

    def access(path, mode, *args, **kwargs):
        if mode & os.W_OK and Path(path).resolve() == locked:
            return False
        return real_access(path, mode, *args, **kwargs)

    monkeypatch.setattr(os, "access", access)


class Payload:
    """Unpickling this calls open(marker, "w"): it creates the marker file."""

    def __init__(self, marker):
        self.marker = str(marker)

    def __reduce__(self):
        return (open, (self.marker, "w"))


def python_tag_yaml(marker: Path) -> str:
    """A YAML value that an unsafe loader turns into a call of open(marker, "w")."""
    return f"!!python/object/apply:builtins.open [{str(marker)!r}, w]"


def write_checkpoint_variants(folder: Path, data: bytes) -> None:
    """semidisk.pt and the damaged, foreign and hostile files derived from it."""
    (folder / "semidisk.pt").write_bytes(data)
    (folder / "random.pt").write_bytes(np.random.default_rng(9).bytes(len(data)))
    checkpoint = torch.load(folder / "semidisk.pt", weights_only=True)
    torch.save({**checkpoint, "format_version": 2}, folder / "future.pt")
    # The map is 2D, the geometry it records 3D: a file edited or stitched together by hand.
    geometry = {"name": "semicylinder", "spec": "semicylinder", "dim": 3, "params": {"radius": 1.0, "length": 2.0}}
    torch.save({**checkpoint, "geometry": geometry}, folder / "dimension.pt")
    torch.save({**checkpoint, "model": Payload(folder / "pwned")}, folder / "evil.pt")


def prepare(folder: Path, data: bytes) -> None:
    """Everything a bad-input row may need, in ``folder``."""
    import meshio

    write_mesh(folder / "m.vtu", tfi(load_geometry("semidisk"), (4, 3)), metadata={"geometry": "semidisk", "dims": [4, 3]})
    (folder / "afile").write_text("a plain file where a folder should be\n")
    (folder / "afolder").mkdir()
    (folder / "locked").mkdir()
    (folder / "empty.vtu").write_bytes(b"")
    noise = np.random.default_rng(1)
    for name in ("random.vtu", "random.xyz", "random.cgns", "random.msh"):
        (folder / name).write_bytes(noise.bytes(3000))
    hexahedron = [("hexahedron", np.arange(8)[None])]
    meshio.write(folder / "infinite.vtu", meshio.Mesh(np.full((8, 3), np.inf), hexahedron))
    meshio.write(folder / "nan.vtu", meshio.Mesh(np.full((8, 3), np.nan), hexahedron))
    meshio.write(folder / "triangles.vtu", meshio.Mesh(noise.random((4, 3)), [("triangle", np.array([[0, 1, 2], [1, 2, 3]]))]))
    (folder / "random.yaml").write_bytes(noise.bytes(500))
    (folder / "unknown-key.yaml").write_text("adam:\n  stepz: 3\n")
    (folder / "ill-typed.yaml").write_text("adam:\n  lr: fast\n")
    (folder / "python-tag.yaml").write_text(f"adam:\n  lr: {python_tag_yaml(folder / 'pwned')}\n")
    write_checkpoint_variants(folder, data)


COMPARE = ["compare", "-g", "semidisk", "--dims", 4, 3]
TRAIN = ["train", "-g", "semidisk", "--preset", "2d", *TINY_ARGS]  # tiny: a missed check costs a second, not minutes

# id -> (arguments, fragments the one-line message must contain)
BAD_INPUTS = {
    # evaluate
    "evaluate-unknown-geometry": (
        ["evaluate", "m.vtu", "-g", "semidisc"],
        ["unknown geometry 'semidisc'", "did you mean 'semidisk'"],
    ),
    "evaluate-param-malformed": (["evaluate", "m.vtu", "-g", "semidisk", "--param", "radius"], ["malformed --param 'radius'"]),
    "evaluate-param-unknown": (
        ["evaluate", "m.vtu", "-g", "semidisk", "--param", "radus=2"],
        ["no parameter 'radus'", "did you mean 'radius'"],
    ),
    "evaluate-gate-bad-value": (["evaluate", "m.vtu", "--fail-if", "valid==maybe"], ["'maybe' is not a number"]),
    "evaluate-json-missing-folder": (["evaluate", "m.vtu", "--json", "nowhere/r.json"], ["output folder nowhere does not exist"]),
    "evaluate-json-is-a-folder": (["evaluate", "m.vtu", "--json", "afolder"], ["afolder is a folder"]),
    "evaluate-json-unwritable": (["evaluate", "m.vtu", "--json", "locked/r.json"], ["locked is not writable"]),
    "evaluate-markdown-missing-folder": (
        ["evaluate", "m.vtu", "--markdown", "nowhere/r.md"],
        ["output folder nowhere does not exist"],
    ),
    "evaluate-markdown-is-a-folder": (["evaluate", "m.vtu", "--markdown", "afolder"], ["afolder is a folder"]),
    "evaluate-markdown-unwritable": (["evaluate", "m.vtu", "--markdown", "locked/r.md"], ["locked is not writable"]),
    "evaluate-random-xyz": (["evaluate", "random.xyz"], ["random.xyz", "not a Fortran unformatted file"]),
    "evaluate-random-cgns": (["evaluate", "random.cgns"], ["could not read random.cgns"]),
    "evaluate-random-msh": (["evaluate", "random.msh"], ["could not read random.msh"]),
    "evaluate-infinite": (["evaluate", "infinite.vtu"], ["infinite.vtu", "non-finite coordinates"]),
    # compare
    "compare-unknown-geometry": (
        ["compare", "-g", "semidisc", "--dims", 4, 3],
        ["unknown geometry 'semidisc'", "did you mean 'semidisk'"],
    ),
    "compare-unknown-metric": (COMPARE + ["--metric", "angles"], ["'angles' is not one of", "min_angle"]),
    "compare-dims-zero": (["compare", "-g", "semidisk", "--dims", 0, 3], ["positive integers, got 0"]),
    "compare-param-not-a-number": (COMPARE + ["--param", "radius=big"], ["'big' is not a number"]),
    "compare-param-unknown": (COMPARE + ["--param", "radus=2"], ["no parameter 'radus'"]),
    "compare-cluster-malformed": (COMPARE + ["--cluster", "eta:both"], ["malformed --cluster 'eta:both'"]),
    "compare-cluster-ratio": (COMPARE + ["--cluster", "eta:0:0.5"], ["growth ratio must be a number >= 1"]),
    "compare-set-unknown-key": (
        COMPARE + ["--methods", "pinn", "--set", "adam.stepz=3"],
        ["unknown configuration key 'adam.stepz'"],
    ),
    "compare-set-ill-typed": (COMPARE + ["--methods", "pinn", "--set", "adam.steps=many"], ["'adam.steps' must be an integer"]),
    "compare-out-is-a-file": (COMPARE + ["--out", "afile"], ["--out afile is a file"]),
    "compare-out-missing-parent": (COMPARE + ["--out", "nowhere/cmp"], ["folder nowhere does not exist"]),
    "compare-out-unwritable": (COMPARE + ["--out", "locked"], ["--out locked is not writable"]),
    "compare-empty": (["compare", "empty.vtu", "m.vtu"], ["empty.vtu is empty"]),
    "compare-random-bytes": (["compare", "random.vtu", "m.vtu"], ["could not read random.vtu"]),
    "compare-non-finite": (["compare", "nan.vtu", "m.vtu"], ["nan.vtu", "non-finite coordinates"]),
    "compare-wrong-cell-type": (["compare", "triangles.vtu", "m.vtu"], ["no hexahedra or quadrilaterals", "2 triangle"]),
    "compare-checkpoint-random": (
        COMPARE + ["--methods", "tfi,pinn", "--checkpoint", "pinn=random.pt"],
        ["random.pt", "not a meshgen checkpoint"],
    ),
    "compare-checkpoint-payload": (
        COMPARE + ["--methods", "tfi,pinn", "--checkpoint", "pinn=evil.pt"],
        ["evil.pt", "refused without running them"],
    ),
    # train
    "train-param-malformed": (TRAIN + ["--param", "radius"], ["malformed --param 'radius'"]),
    "train-param-unknown": (TRAIN + ["--param", "radus=2"], ["no parameter 'radus'"]),
    "train-config-random-bytes": (TRAIN + ["--config", "random.yaml"], ["random.yaml", "not a text file"]),
    "train-config-unknown-key": (
        TRAIN + ["--config", "unknown-key.yaml"],
        ["unknown-key.yaml: unknown configuration key 'adam.stepz'"],
    ),
    "train-config-ill-typed": (TRAIN + ["--config", "ill-typed.yaml"], ["'adam.lr' must be a number, got 'fast'"]),
    "train-config-python-tag": (
        TRAIN + ["--config", "python-tag.yaml"],
        ["python-tag.yaml is malformed YAML", "python/object/apply"],
    ),
    "train-set-python-tag": (None, ["malformed --set"]),  # arguments need the folder: see bad_input_args
    "train-out-is-a-file": (TRAIN + ["--out", "afile"], ["'--out'", "'afile' is a file"]),
    "train-out-unwritable": (TRAIN + ["--out", "locked"], ["locked is not writable"]),
    "train-out-inside-unwritable": (TRAIN + ["--out", "locked/run"], ["locked is not writable"]),
    "train-resume-random": (["train", "--resume", "random.pt"], ["random.pt", "not a meshgen checkpoint"]),
    "train-resume-future": (["train", "--resume", "future.pt"], ["format version 2, newer than this meshgen reads (1)"]),
    "train-resume-dimension": (["train", "--resume", "dimension.pt"], ["dimension.pt", "2D map", "3D geometry 'semicylinder'"]),
    "train-resume-payload": (["train", "--resume", "evil.pt"], ["evil.pt", "refused without running them"]),
    # mesh
    "mesh-checkpoint-random": (
        ["mesh", "--checkpoint", "random.pt", "--dims", 4, 4, "-o", "out.vtu"],
        ["random.pt", "not a meshgen checkpoint"],
    ),
    "mesh-checkpoint-future": (
        ["mesh", "--checkpoint", "future.pt", "--dims", 4, 4, "-o", "out.vtu"],
        ["format version 2, newer"],
    ),
    "mesh-checkpoint-dimension": (
        ["mesh", "--checkpoint", "dimension.pt", "--dims", 4, 4, "-o", "out.vtu"],
        ["2D map", "3D geometry 'semicylinder'"],
    ),
    # geometries show
    "show-unwritable": (["geometries", "show", "semidisk", "-o", "locked/s.stl"], ["locked is not writable"]),
}


def bad_input_args(row: str, folder: Path) -> list:
    if row == "train-set-python-tag":
        return TRAIN + ["--set", f"adam.lr={python_tag_yaml(folder / 'pwned')}"]
    return BAD_INPUTS[row][0]


@pytest.mark.parametrize("row", list(BAD_INPUTS))
def test_bad_input(row, tmp_path, monkeypatch, semidisk_checkpoint):
    monkeypatch.chdir(tmp_path)
    prepare(tmp_path, semidisk_checkpoint)
    lock(tmp_path / "locked", monkeypatch)
    before = snapshot(tmp_path)
    result = invoke(*bad_input_args(row, tmp_path))
    assert_one_line_error(result, *BAD_INPUTS[row][1])
    assert result.stdout == ""
    assert snapshot(tmp_path) == before  # nothing created, nothing changed
    assert not (tmp_path / "pwned").exists()  # no payload ran (payload and python-tag rows)


@pytest.mark.parametrize("row", ["evaluate-infinite", "train-resume-payload", "compare-non-finite"])
def test_bad_input_in_a_real_process(row, tmp_path, run_cli, semidisk_checkpoint):
    """A few rows as real ``python -m meshgen`` processes: what reaches the terminal is the one
    line (in-process, pytest would catch a warning printed beside it)."""
    prepare(tmp_path, semidisk_checkpoint)
    before = snapshot(tmp_path)
    result = run_cli(*bad_input_args(row, tmp_path))
    assert result.returncode == 2, result.stderr
    assert result.stderr.count("\n") == 1 and result.stderr.startswith("Error: "), result.stderr
    for fragment in BAD_INPUTS[row][1]:
        assert fragment in result.stderr
    assert result.stdout == "" and snapshot(tmp_path) == before
    assert not (tmp_path / "pwned").exists()


def test_the_payloads_are_real(tmp_path):
    """Loaded unsafely, the hostile checkpoint and YAML do run their code: the rows that refuse
    them test something."""
    import yaml

    torch.save({"format": "meshgen-checkpoint", "model": Payload(tmp_path / "pwned")}, tmp_path / "evil.pt")
    torch.load(tmp_path / "evil.pt", weights_only=False)
    assert (tmp_path / "pwned").exists()
    (tmp_path / "pwned").unlink()
    yaml.unsafe_load(f"lr: {python_tag_yaml(tmp_path / 'pwned')}")
    assert (tmp_path / "pwned").exists()


# ---------------------------------------------------------------------------------------------
# plugins

PLUGIN = """
import sys
import numpy as np
{head}
name = "faultysquare"
dim = 2
description = "The unit square, with a fault"

def boundary(points):
    points = np.array(points, dtype=float)
{body}
    return points
"""

FAULTS = {
    "raises": ("", "    1 / 0", "boundary() raised ZeroDivisionError"),
    "exits": ("", "    sys.exit(0)", "boundary() raised SystemExit"),
    "exits-at-import": ("sys.exit(0)", "", "failed to load: SystemExit"),
    # NaN inside one face only: the load check looks at the corners (2D), so this shows later.
    "late-nan": (
        "",
        "    points[(points[:, 1] == 0) & (points[:, 0] > 0.3) & (points[:, 0] < 0.7)] = np.nan",
        "non-finite values",
    ),
}

PLUGIN_COMMANDS = {
    "mesh": ["mesh", "-m", "tfi", "-g", "plugin.py", "--dims", 4, 4, "-o", "out.vtu"],
    "train": ["train", "-g", "plugin.py", "--preset", "2d", *TINY_ARGS, "--out", "run", "-q"],
    "evaluate": ["evaluate", "square.vtu", "-g", "plugin.py"],
    "compare": ["compare", "-g", "plugin.py", "--dims", 4, 4, "--methods", "tfi"],
}

PLUGIN_FAULTS = [
    "raises-train",
    "raises-evaluate",
    "raises-compare",
    "exits-mesh",
    "exits-at-import-mesh",
    "late-nan-mesh",
    "late-nan-train",
    "late-nan-evaluate",
    "late-nan-compare",
]


@pytest.mark.parametrize("row", PLUGIN_FAULTS)
def test_plugin_fault(row, tmp_path, monkeypatch):
    fault, command = row.rsplit("-", 1)
    head, body, message = FAULTS[fault]
    monkeypatch.chdir(tmp_path)
    (tmp_path / "plugin.py").write_text(PLUGIN.format(head=head, body=body))
    square = np.stack(np.meshgrid(np.linspace(0, 1, 5), np.linspace(0, 1, 5), indexing="ij"), axis=-1)
    write_mesh(tmp_path / "square.vtu", square)
    before = snapshot(tmp_path)
    result = invoke(*PLUGIN_COMMANDS[command])
    if command == "compare" and fault == "late-nan":
        # compare reports a method that fails in its row and goes on with the others: exit 1.
        assert result.exit_code == 1, result.output
        assert "tfi failed: geometry 'faultysquare'" in result.stderr and message in result.stderr
        assert "plugin.py" in result.stderr
    else:
        assert_one_line_error(result, "plugin.py", message)
        if fault != "exits-at-import":
            assert "geometry 'faultysquare'" in result.stderr
    assert snapshot(tmp_path) == before


def test_readme_says_plugins_are_code():
    readme = (REPO / "README.md").read_text()
    section = readme[readme.index("## Security") :]
    assert "plugin is code" in section and "meshgen never runs code from them" in section


# ---------------------------------------------------------------------------------------------
# full disk: the temporary file of the write is a link to /dev/full (helpers.full_disk_temporaries),
# so every write to it fails with the kernel's own ENOSPC (not a mocked exception), through the real writers.


FULL_DISK = {
    "mesh-vtu": (["mesh", "-m", "tfi", "-g", "semidisk", "--dims", 6, 5, "-o", "m.vtu"], "m.vtu"),
    "mesh-xdmf": (["mesh", "-m", "tfi", "-g", "semidisk", "--dims", 6, 5, "-o", "m.xdmf"], "m.xdmf"),
    "mesh-xyz": (["mesh", "-m", "tfi", "-g", "semidisk", "--dims", 6, 5, "-o", "m.xyz"], "m.xyz"),
    "show-stl": (["geometries", "show", "semidisk", "-o", "s.stl"], "s.stl"),
    "evaluate-json": (["evaluate", "m.vtu", "--json", "r.json"], "r.json"),
    "train-checkpoint": (["train", "--resume", "run/checkpoint.pt", "--steps", 3, "-q"], "run/checkpoint.pt"),
}


@pytest.mark.skipif(not os.path.exists("/dev/full"), reason="no /dev/full to simulate a full disk")
@pytest.mark.parametrize("row", list(FULL_DISK))
def test_full_disk(row, tmp_path, monkeypatch, semidisk_checkpoint):
    monkeypatch.chdir(tmp_path)
    args, target = FULL_DISK[row]
    target = tmp_path / target
    # The previous file: the same command run once on a disk with room.
    if row == "train-checkpoint":
        (tmp_path / "run").mkdir()
        (tmp_path / "run" / "checkpoint.pt").write_bytes(semidisk_checkpoint)
        (tmp_path / "run" / "config.yaml").write_text("# a run folder\n")
    else:
        if row == "evaluate-json":
            assert invoke("mesh", "-m", "tfi", "-g", "semidisk", "--dims", 6, 5, "-o", "m.vtu").exit_code == 0
        first = invoke(*args)
        assert first.exit_code == 0, first.output
    previous = target.read_bytes()
    before = snapshot(tmp_path)
    made = full_disk_temporaries(monkeypatch, target.name)
    result = invoke(*args)
    assert len(made) == 1, made
    temporary = made[0]
    assert_one_line_error(
        result, "No space left on device", str(target.relative_to(tmp_path)), after_progress=row == "train-checkpoint"
    )
    assert target.read_bytes() == previous
    if row != "train-checkpoint":  # (a resumed run rewrites its config.yaml and history.csv)
        assert snapshot(tmp_path) == before
    assert not temporary.exists() and not temporary.is_symlink()
    assert not [p.name for p in target.parent.iterdir() if TEMPORARY.match(p.name)]
    if row == "train-checkpoint":  # the kept checkpoint still resumes
        monkeypatch.undo()
        monkeypatch.chdir(tmp_path)
        resumed = invoke(*args)
        assert resumed.exit_code == 0, resumed.output
        assert torch.load(target, weights_only=True)["stage"] == "done"


@pytest.mark.skipif(not os.path.exists("/dev/full"), reason="no /dev/full to simulate a full disk")
def test_full_disk_when_a_run_writes_its_first_file(tmp_path, monkeypatch):
    """train writes config.yaml and history.csv in place (they are not the run's state); a full
    disk there is a one-line error too, not an internal error."""
    monkeypatch.chdir(tmp_path)
    (tmp_path / "run").mkdir()
    (tmp_path / "run" / "config.yaml").symlink_to("/dev/full")
    (tmp_path / "run" / "history.csv").write_text("stage,step\n")
    result = invoke("train", "-g", "semidisk", "--preset", "2d", *TINY_ARGS, "--out", "run", "-q")
    assert_one_line_error(result, "No space left on device")
    assert not (tmp_path / "run" / "checkpoint.pt").exists()


# ---------------------------------------------------------------------------------------------
# signals: real processes, the signal sent while a write is half done (hardening_helpers.py)


def start_stalled(children, folder: Path, kind: str, call: int, *args) -> tuple[subprocess.Popen, Path]:
    """``meshgen ARGS`` in a child process whose ``call``-th write of ``kind`` stops half-way;
    returns the process and the marker file that appears (holding the half-written file's name)
    when it does."""
    marker = folder / "stalled"
    env = {**os.environ, "PYTHONPATH": str(REPO), "OMP_WAIT_POLICY": "PASSIVE"}
    env.pop("MESHGEN_DEBUG", None)
    process = subprocess.Popen(
        [sys.executable, str(HELPERS), kind, str(marker), str(call), *map(str, args)],
        cwd=folder,
        env=env,
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
    )
    children.append(process)
    deadline = time.time() + 120
    while not marker.exists():
        if process.poll() is not None or time.time() > deadline:
            process.kill()
            stdout, stderr = process.communicate()
            pytest.fail(f"the write never stalled (exit {process.returncode}): {stdout} {stderr}")
        time.sleep(0.02)
    return process, marker


TRAIN_UNTIL_KILLED = ["train", "-g", "semidisk", "--preset", "2d", *TINY_ARGS, "--steps", 100000, "--out", "run", "-q"]


def history_steps(path: Path) -> list[int]:
    with open(path, newline="") as handle:
        return [int(row["step"]) for row in csv.DictReader(handle)]


def resume_and_finish(folder: Path, kept_step: int) -> None:
    """--resume the kept checkpoint for 3 more Adam steps: it finishes, with one history row per step."""
    adam_steps = kept_step - 2 + 3  # pretrain.steps = 2 of TINY come first
    result = invoke("train", "--resume", "run/checkpoint.pt", "--steps", adam_steps, "-q")
    assert result.exit_code == 0, result.output
    final = torch.load(folder / "run" / "checkpoint.pt", weights_only=True)
    assert final["stage"] == "done" and final["step"] == kept_step + 3 + 2  # + lbfgs.steps = 2
    assert history_steps(folder / "run" / "history.csv") == list(range(kept_step + 3 + 2))


def test_sigkill_during_a_checkpoint_write_keeps_the_last_periodic_checkpoint(tmp_path, monkeypatch, children):
    monkeypatch.chdir(tmp_path)
    # checkpoint.every = 5: the first periodic checkpoint (step 5) is written whole, the second
    # (step 10) stops half-way, and the process is killed there.
    process, marker = start_stalled(children, tmp_path, "torch-save", 2, *TRAIN_UNTIL_KILLED)
    process.send_signal(signal.SIGKILL)
    process.communicate(timeout=30)
    assert process.returncode == -signal.SIGKILL
    kept = torch.load(tmp_path / "run" / "checkpoint.pt", weights_only=True)  # plain data, whole
    assert kept["step"] == 5 and kept["stage"] == "adam"
    half_written = Path(marker.read_text())
    assert half_written.name != "checkpoint.pt"  # the half-written bytes went to a temporary name
    with pytest.raises((RuntimeError, EOFError, OSError)):  # and they are half a checkpoint: the kill hit mid-write
        torch.load(tmp_path / "run" / half_written.name, weights_only=True)
    resume_and_finish(tmp_path, kept["step"])


def test_ctrl_c_during_a_checkpoint_write_saves_and_stops(tmp_path, monkeypatch, children):
    """Ctrl-C after the first periodic checkpoint, while the second is being written: the write
    finishes whole, the run saves where it stopped, says how to go on, and --resume does."""
    monkeypatch.chdir(tmp_path)
    process, marker = start_stalled(children, tmp_path, "torch-save", 2, *TRAIN_UNTIL_KILLED)
    process.send_signal(signal.SIGINT)
    time.sleep(0.5)  # the handler has run: now let the write go on
    Path(f"{marker}.go").touch()
    stdout, stderr = process.communicate(timeout=60)
    assert process.returncode == 130, stderr
    assert "Interrupted at step 10 (adam)" in stdout and "Continue with: meshgen train --resume run/checkpoint.pt" in stdout
    assert "Traceback" not in stderr and not [p.name for p in (tmp_path / "run").iterdir() if TEMPORARY.match(p.name)]
    kept = torch.load(tmp_path / "run" / "checkpoint.pt", weights_only=True)
    assert kept["step"] == 10 and kept["stage"] == "adam"
    resume_and_finish(tmp_path, kept["step"])


def test_second_ctrl_c_during_a_checkpoint_write_keeps_the_last_checkpoint(tmp_path, monkeypatch, children):
    """The first Ctrl-C asks for a save after the step; a second one aborts at once, here in the
    middle of writing a checkpoint: the previous checkpoint stays, the partial one is removed."""
    monkeypatch.chdir(tmp_path)
    process, marker = start_stalled(children, tmp_path, "torch-save", 2, *TRAIN_UNTIL_KILLED)
    process.send_signal(signal.SIGINT)
    time.sleep(0.5)  # two signals in quick succession can arrive as one ...
    for _ in range(10):
        process.send_signal(signal.SIGINT)
        try:
            process.wait(timeout=3)
            break
        except subprocess.TimeoutExpired:  # ... so on a busy machine, once more
            continue
    stdout, stderr = process.communicate(timeout=60)
    assert process.returncode == 130, stderr
    assert "Traceback" not in stderr and "Stopping after this step" in stderr
    assert not [p.name for p in (tmp_path / "run").iterdir() if TEMPORARY.match(p.name)]
    kept = torch.load(tmp_path / "run" / "checkpoint.pt", weights_only=True)
    assert kept["step"] == 5
    resume_and_finish(tmp_path, kept["step"])


@pytest.mark.parametrize("existing", [True, False], ids=["over-an-old-file", "new-file"])
def test_sigkill_during_a_mesh_write_leaves_no_file_under_the_target_name(tmp_path, monkeypatch, children, existing):
    monkeypatch.chdir(tmp_path)
    mesh = ["mesh", "-m", "tfi", "-g", "semidisk", "--dims", 40, 30, "-o", "m.xyz", "-q"]
    if existing:
        assert invoke(*mesh[:6], 3, 2, *mesh[8:]).exit_code == 0  # an older, smaller mesh
        assert {"m.xyz", "m.xyz.quality.json"} <= set(os.listdir(tmp_path))
    else:
        assert os.listdir(tmp_path) == []
    before = snapshot(tmp_path)
    # Plot3D records: block count, dimensions, coordinates; stop after the dimensions.
    process, marker = start_stalled(children, tmp_path, "plot3d-record", 2, *mesh)
    process.send_signal(signal.SIGKILL)
    process.communicate(timeout=30)
    half_written = tmp_path / marker.read_text()  # the name the writer was given, relative to the child's folder
    after = snapshot(tmp_path)
    for extra in (marker.name, half_written.name):
        after.pop(extra, None)
    assert after == before  # the old mesh and its sidecar byte-identical, or no mesh at all
    assert half_written.name != "m.xyz" and half_written.stat().st_size > 0  # the kill did hit a write


# ---------------------------------------------------------------------------------------------
# repeatability


def assert_same(a, b, where="checkpoint"):
    """Equal plain data; tensors equal bit for bit (and in dtype and shape)."""
    if isinstance(a, torch.Tensor):
        assert isinstance(b, torch.Tensor) and a.dtype == b.dtype and a.shape == b.shape, where
        assert torch.equal(a, b), where
    elif isinstance(a, dict):
        assert isinstance(b, dict) and list(a) == list(b), where
        for key in a:
            assert_same(a[key], b[key], f"{where}[{key!r}]")
    elif isinstance(a, (list, tuple)):
        assert type(a) is type(b) and len(a) == len(b), where
        for index, (x, y) in enumerate(zip(a, b)):
            assert_same(x, y, f"{where}[{index}]")
    else:
        assert a == b or (a != a and b != b), where  # NaN equals NaN here


def test_same_seed_gives_bit_identical_checkpoints_and_meshes(tmp_path, monkeypatch):
    """Two CPU trainings with the same seed: every tensor of the two checkpoints (weights, Adam
    and L-BFGS state, reweighting, random generator states) is bit-identical, and so is every
    other entry but the wall-clock ``elapsed_seconds``; the history differs only in its seconds
    column. Meshes: the Plot3D files of the two models are byte-identical; the .vtu files of one
    model meshed twice are byte-identical (the meshing time is in their sidecars alone)."""
    import meshio

    from meshgen.formats import metadata_of

    monkeypatch.chdir(tmp_path)
    for run in ("a", "b"):
        result = invoke("train", "-g", "semidisk", "--preset", "2d", *TINY_ARGS, "--seed", 7, "--out", run, "-q")
        assert result.exit_code == 0, result.output
    a, b = (torch.load(tmp_path / run / "checkpoint.pt", weights_only=True) for run in ("a", "b"))
    assert a["step"] == 2 + 10 + 2 and a["config"]["seed"] == 7
    for checkpoint in (a, b):  # wall-clock times
        del checkpoint["elapsed_seconds"], checkpoint["history"]["last"]["seconds"]
    assert_same(a, b)
    histories = []
    for run in ("a", "b"):
        with open(tmp_path / run / "history.csv", newline="") as handle:
            histories.append([{k: v for k, v in row.items() if k != "seconds"} for row in csv.DictReader(handle)])
    assert histories[0] == histories[1] and len(histories[0]) == 14

    for run in ("a", "b"):
        result = invoke("mesh", "--checkpoint", f"{run}/checkpoint.pt", "--dims", 9, 7, "-o", f"{run}.xyz", "-q")
        assert result.exit_code == 0, result.output
    assert (tmp_path / "a.xyz").read_bytes() == (tmp_path / "b.xyz").read_bytes()
    for name in ("first", "second"):
        assert invoke("mesh", "--checkpoint", "a/checkpoint.pt", "--dims", 9, 7, "-o", f"{name}.vtu", "-q").exit_code == 0
    first, second = (tmp_path / f"{name}.vtu" for name in ("first", "second"))
    assert first.read_bytes() == second.read_bytes()
    assert len(meshio.read(first).cell_data) == 7 and "meshing_seconds" not in metadata_of(first)


# ---------------------------------------------------------------------------------------------
# the table


def test_the_table_names_real_tests():
    """Every test the docstring's tables name exists: its file defines it and, for rows of this
    file's tables, the row id is one of the table's keys."""
    tables = {"test_bad_input": BAD_INPUTS, "test_plugin_fault": PLUGIN_FAULTS, "test_full_disk": FULL_DISK}
    named = re.findall(r"(test_\w+\.py)::(test_\w+)(?:\[([^\]]+)\])?((?:, \[[^\]]+\])*)", __doc__)
    assert len(named) > 40
    for file_name, test_name, first_id, more_ids in named:
        source = (Path(__file__).parent / file_name).read_text()
        assert f"def {test_name}(" in source, (file_name, test_name)
        if file_name == Path(__file__).name and test_name in tables:
            ids = [first_id] + re.findall(r"\[([^\]]+)\]", more_ids)
            for row in ids:
                if row != "...":
                    assert row in tables[test_name], (test_name, row)
    # and every row of this file's tables is in the docstring
    for rows in tables.values():
        for row in rows:
            assert f"[{row}]" in __doc__, row
