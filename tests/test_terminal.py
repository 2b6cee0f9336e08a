"""What a person at a terminal sees: the training progress line at 80 and 100 columns, the fields a
preset uses, summary lines that break between words, the help texts and ``meshgen`` alone."""

import io
import re

import pytest
from click.testing import CliRunner
from neural_helpers import TINY
from rich.console import Console
from terminal_helpers import run_in_terminal

from meshgen.cli import cli
from meshgen.cli._text import wrapped
from meshgen.neural.config import resolve_config
from meshgen.neural.progress import FIELD_HELP, LogReporter, RichReporter, describe_row, shown_fields

ROW = {
    "stage": "adam",
    "step": 414,
    "L1": 1.58e-2,
    "L2": 1.16e-4,
    "total": 0.02,
    "a1": 0.586,
    "a2": 0.0232,
    "conflict": 1,
    "lr": 1e-4,
    "seconds": 3.0,
}
PROGRESS = re.compile(r"^\s*(TFI fit|Adam|L-BFGS) \S* *(\d+)/(\d+) +ETA (\d+:\d\d:\d\d|-:--:--)")


def drawn_line(width, total=12000, fields=shown_fields()):
    """The progress line RichReporter draws on a ``width``-column console after 415 steps."""
    console = Console(file=io.StringIO(), width=width)
    reporter = RichReporter(refresh_seconds=0, fields=fields, console=console)
    reporter.stage("adam", 0, total)
    for done in range(1, 416):
        reporter.update(ROW, done, total)
    console.print(reporter.progress.make_tasks_table(reporter.progress.tasks))
    return console.file.getvalue().rstrip("\n")


@pytest.mark.parametrize("width", [60, 80, 100, 140])
def test_progress_line_keeps_bar_step_and_eta_and_fits(width):
    line = drawn_line(width)
    assert "\n" not in line and len(line) <= width
    match = PROGRESS.match(line)
    assert match and match.group(2, 3) == ("415", "12000")  # the total is never cut
    assert "━" in line or "╸" in line  # the bar is drawn
    losses = line[match.end() :].strip()
    full = describe_row(ROW, 1.0)
    # The loss figures fill what is left: whole where they fit, else a prefix with an ellipsis.
    assert losses == full or (losses.endswith("…") and full.startswith(losses[:-1]))
    if width >= 120:
        assert losses == full


def test_fields_follow_the_preset():
    assert shown_fields(resolve_config("default")) == {"L2", "a", "conflict"}
    assert shown_fields(resolve_config("exact")) == frozenset()
    assert shown_fields(resolve_config("pinn")) == {"L2"}
    exact = describe_row(ROW, 0.0, shown_fields(resolve_config("exact")))
    assert exact == "L1 1.58e-02  lr 1.00e-04"
    full = describe_row(ROW, 0.25, shown_fields(resolve_config("default")))
    assert full == "L1 1.58e-02  L2 1.16e-04  a 0.586 0.0232  conflict 25%  lr 1.00e-04"


def test_the_fit_to_tfi_does_not_say_fit_twice():
    stream = io.StringIO()
    reporter = LogReporter(stream=stream)
    reporter.stage("pretrain", 0, 1)
    reporter.update({"step": 0, "total": 2.5e-3, "lr": 1.0, "seconds": 0.1}, 1, 1)
    text = stream.getvalue()
    assert "TFI fit: 1 steps" in text and "misfit 2.50e-03" in text
    assert not re.search(r"\b(\w+) \1\b", text)


def test_train_help_explains_every_progress_field():
    text = CliRunner().invoke(cli, ["train", "--help"], terminal_width=80).output
    for name in ("L1", "L2", "a", "conflict", "misfit", "lr"):
        assert re.search(rf"^\s+{name}\s+\S", text, re.M), name
    assert "PCGrad" in text and set(FIELD_HELP) == {"misfit", "L1", "L2", "a", "conflict", "lr"}
    assert max(len(line) for line in text.splitlines()) <= 80


@pytest.mark.parametrize("width", [20, 40, 80])
def test_summary_lines_break_between_words(width):
    line = "  quality of 27000 hexahedron cells: min angle 73 deg (worst 4.34), max angle 107.7 deg (worst 177.8)"
    parts = wrapped(line, width)
    assert all(len(part) <= width for part in parts)
    assert " ".join(part.strip() for part in parts) == line.strip()  # every word whole, in order
    assert parts[0].startswith("  q") and all(part.startswith("      ") for part in parts[1:])
    assert wrapped(line, None) == [line]


def test_meshgen_alone_prints_the_help(run_cli):
    alone, helped = run_cli(), run_cli("--help")
    assert alone.returncode == 0 and alone.stderr == ""
    assert alone.stdout == helped.stdout and alone.stdout.startswith("Usage: meshgen")


def test_help_texts_show_defaults_and_choices():
    from meshgen.methods.elliptic import DEFAULT_MAX_ITER, DEFAULT_TOL
    from meshgen.methods.registry import METHODS

    runner = CliRunner()

    def help_of(*args):
        return " ".join(runner.invoke(cli, [*args, "--help"], terminal_width=200).output.split())

    mesh, train, compare = help_of("mesh"), help_of("train"), help_of("compare")
    assert float(re.search(r"--tol FLOAT .*?\[default: ([^\]]+)\]", mesh).group(1)) == DEFAULT_TOL
    assert int(re.search(r"--max-iter INTEGER RANGE .*?\[default: ([^\]]+)\]", mesh).group(1)) == DEFAULT_MAX_ITER
    method_help = mesh.split("-m, --method")[1].split("-g,")[0]
    for name in ("auto", *(name for name, method in METHODS.items() if method.preset is None)):
        assert re.search(rf"\b{re.escape(name)}\b", method_help), name
    assert f"default preset: {resolve_config('default').adam.steps}" in train
    assert f"[default: the preset's seed, {resolve_config('default').seed}]" in train
    device = re.compile(r"--device \[auto\|cpu\|cuda\] .*?\[default: (\w+)\]")
    assert device.search(compare).group(1) == device.search(train).group(1) == "auto"
    geometries = runner.invoke(cli, ["geometries", "--help"], terminal_width=80).output
    show = next(line for line in geometries.splitlines() if line.strip().startswith("show"))
    assert not show.rstrip().endswith("...")


TRAIN = [
    "train",
    "-g",
    "semidisk",
    "--preset",
    "2d",
    *(a for item in TINY for a in ("--set", item)),
    "--set",
    "pretrain.steps=3",
    "--steps",
    "15",
    "--set",
    "lbfgs.steps=3",
    "--out",
    "run",
]


@pytest.mark.parametrize("columns", [80, 100])
def test_train_at_a_real_terminal(columns, tmp_path):
    status, raw, lines = run_in_terminal(TRAIN, columns, tmp_path)
    assert status == 0, raw
    progress = [line for line in lines if PROGRESS.match(line)]
    assert {PROGRESS.match(line).group(1) for line in progress} == {"TFI fit", "Adam", "L-BFGS"}
    assert all(PROGRESS.match(line).group(3) in ("3", "15") for line in progress)
    assert max(len(line) for line in lines) <= columns, "\n".join(lines)
    summary = [line for line in lines if not PROGRESS.match(line)]
    words = " ".join(summary).split()
    for word in ("equiangle", "skewness", "non-orthogonality", "characteristic"):
        assert word in words or word not in raw  # never split across lines


COMPARE = ["compare", "-g", "semidisk", "--dims", "8", "5"]


def test_compare_at_a_real_terminal_shows_training_and_fits_the_table(tmp_path):
    budget = [a for item in TINY for a in ("--set", item)]
    status, raw, lines = run_in_terminal([*COMPARE, "--methods", "tfi,elliptic,exact", *budget, "--steps", "30"], 100, tmp_path)
    assert status == 0, raw
    assert {PROGRESS.match(line).group(1) for line in lines if PROGRESS.match(line)} >= {"Adam", "L-BFGS"}
    assert max(len(line) for line in lines) <= 100, "\n".join(lines)
    header = next(line for line in lines if line.split()[:1] == ["method"])
    assert header.split() == ["method", "tfi", "elliptic", "exact"]  # turned: a column per method
    for label in ("min angle", "non-orth", "boundary dev", "test loss", "mesh (s)"):
        assert any(line.strip().startswith(label) for line in lines), label


def test_compare_table_keeps_its_full_width_in_a_file(run_cli):
    from meshgen.cli.comparison import COLUMNS

    result = run_cli(*COMPARE, "--methods", "tfi,elliptic")
    assert result.returncode == 0, result.stderr
    header = next(line for line in result.stdout.splitlines() if line.strip().startswith("method"))
    assert re.split(r"\s{2,}", header.strip()) == ["method", *(column.short for column in COLUMNS)]
    assert len(header.rstrip()) > 100


def test_compare_at_80_columns(tmp_path):
    status, raw, lines = run_in_terminal([*COMPARE, "--methods", "tfi,elliptic"], 80, tmp_path)
    assert status == 0, raw
    assert max(len(line) for line in lines) <= 80, "\n".join(lines)
    assert any(line.split()[:3] == ["method", "tfi", "elliptic"] for line in lines)
