"""The documentation's contracts with the code: the README stays a front page whose test command is
the one CI runs, every "design notes §N" a docstring cites is a section of docs/design.md, code
and docs carry no issue numbers, every code block of the README and docs/*.md a user would run is
run here (the markers and fence languages are described in docs/contributing.md), and the API
reference lists exactly the public modules' ``__all__``."""

from __future__ import annotations

import importlib
import os
import re
import shlex
import shutil
import signal
import subprocess
import sys
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[1]
SOURCES = ["meshgen", "geometries", "presets", "benchmarks", "scripts", "tests", "docs"]
TEXT_SUFFIXES = {".py", ".yaml", ".md"}


def source_files():
    for folder in SOURCES:
        yield from (path for path in (REPO / folder).rglob("*") if path.suffix in TEXT_SUFFIXES and path.is_file())
    yield REPO / "README.md"
    yield REPO / "CHANGELOG.md"


def test_readme_is_a_front_page_whose_test_command_ci_runs():
    readme = (REPO / "README.md").read_text()
    assert len(readme.splitlines()) <= 250
    commands = re.findall(r"^(pip install .*)$", readme, flags=re.MULTILINE)
    assert len(commands) == 2, commands  # one to install and mesh, one to install and test
    ci_lines = (REPO / ".ci" / "run").read_text().splitlines()
    assert ci_lines[-1] == commands[1]  # CI ends with the README's test command, unchanged


def test_every_cited_design_section_exists():
    design = (REPO / "docs" / "design.md").read_text()
    sections = {int(number) for number in re.findall(r"^## (\d+)\. ", design, flags=re.MULTILINE)}
    assert set(range(1, 13)) <= sections
    cited = {}
    for path in source_files():
        for number in re.findall(r"design notes §(\d+)", path.read_text(errors="replace")):
            cited.setdefault(int(number), path.relative_to(REPO))
    assert cited, "no citation found: the pattern no longer matches the docstrings"
    missing = {number: str(path) for number, path in cited.items() if number not in sections}
    assert not missing


def test_no_issue_numbers_in_code_or_docs():
    pattern = re.compile(r"(?i:\bissue [0-9])|DESIGN section|DESIGN\.md")  # the design notes by another name
    this_file = Path(__file__).resolve()
    found = [
        f"{path.relative_to(REPO)}:{number}"
        for path in source_files()
        if path.resolve() != this_file
        for number, line in enumerate(path.read_text(errors="replace").splitlines(), 1)
        if pattern.search(line)
    ]
    assert not found


# --- Every code block a user would run is run -------------------------------------------------------

DOC_PAGES = ["README.md", *sorted(str(path.relative_to(REPO)) for path in (REPO / "docs").glob("*.md"))]
SHELL = {"bash", "sh", "shell", "console"}  # run: every line, or in `console` every `$ ` line
NOT_RUN = {"text", "yaml", "toml", "json", "ini"}  # output, synopses, file contents, illustrations
TOOLS = {"checkMesh", "potentialFoam", "simpleFoam", "gmsh", "cgnscheck", "paraview"}  # skip when missing
FENCE = re.compile(r"^```(?P<lang>[^\n`]*)\n(?P<body>.*?)^```[ \t]*$", re.MULTILINE | re.DOTALL)
MARKER = re.compile(r"<!--\s*docs-test:\s*(?P<what>skip|file|replace)\b(?P<args>.*?)-->", re.DOTALL)
SLOW_PAGES = {
    "README.md",
    "docs/multiblock.md",
    "docs/getting-started.md",
    "docs/methods.md",
    "docs/cli.md",
    "docs/shapes-from-files.md",
}


def code_blocks(page: str) -> list[dict]:
    """The fenced code blocks of ``page`` in order: language, body, first line, and the markers of
    the comment lines right above the fence (``skip REASON``, ``file NAME``, ``replace "OLD" "NEW"``)."""
    text = (REPO / page).read_text()
    blocks = []
    for match in FENCE.finditer(text):
        above = text[: match.start()].rstrip("\n").split("\n")
        markers = []
        while above and re.fullmatch(r"<!--.*-->", above[-1].strip()):  # other comments may name a block too
            marker = MARKER.fullmatch(above.pop().strip())
            if marker:
                markers.insert(0, (marker["what"], marker["args"].strip()))
        line = text.count("\n", 0, match.start()) + 1
        blocks.append({"lang": match["lang"].strip(), "body": match["body"], "line": line, "markers": markers})
    return blocks


def shell_commands(block: dict) -> list[str]:
    """A shell block's commands: lines joined at a trailing backslash; in `console`, the `$ ` lines."""
    lines = block["body"].replace("\\\n", " ").splitlines()
    if block["lang"] == "console":
        lines = [line[2:] for line in lines if line.startswith("$ ")]
    return [line for line in lines if line.strip() and not line.lstrip().startswith("#")]


def run_meshgen_here(arguments: list[str]) -> tuple[int, str]:
    """``meshgen ARGUMENTS`` through the command line's own entry in this process (no interpreter
    start per command): its exit status and output."""
    from click.testing import CliRunner

    from meshgen.cli import cli

    handlers = {signum: signal.getsignal(signum) for signum in (signal.SIGINT, signal.SIGTERM)}
    try:
        result = CliRunner(env={"MESHGEN_DEBUG": None}).invoke(cli, arguments, prog_name="meshgen")
    finally:
        for signum, handler in handlers.items():
            signal.signal(signum, handler)
    if result.exception is not None and not isinstance(result.exception, SystemExit):
        raise result.exception
    return result.exit_code, result.output


def run_shell(command: str, folder: Path) -> tuple[int, str]:
    command = re.sub(r"(?<![\w/.])examples/", f"{REPO}/examples/", command)  # the repository's examples, from the folder
    words = shlex.split(command, comments=True)
    if words and words[0] in TOOLS and shutil.which(words[0]) is None:
        return 0, f"skipped: {words[0]} is not installed"
    plain = not set(command.split("#")[0]) & set("|&;<>$`*")
    if words and words[0] == "meshgen" and plain:
        return run_meshgen_here(words[1:])
    environment = {**os.environ, "PYTHONPATH": os.pathsep.join([str(REPO), os.environ.get("PYTHONPATH", "")])}
    if Path("/usr/share/openfoam").is_dir():
        environment.setdefault("WM_PROJECT_DIR", "/usr/share/openfoam")  # as the docs tell a user to
    command = re.sub(r"^python ", f"{shlex.quote(sys.executable)} ", command)
    done = subprocess.run(["bash", "-c", command], cwd=folder, env=environment, capture_output=True, text=True)
    return done.returncode, done.stdout + done.stderr


def shape_files(folder: Path) -> None:
    """The files docs/shapes-from-files.md assumes its reader has: a CAD solid ``part.step`` (a
    twisted loft by the OCC kernel of gmsh), swept solids ``cylinder.step`` and ``fillet.step``
    (a box with one filleted edge), a multi-solid ASCII STL ``duct.stl`` (a bent duct) and a
    binary STL ``bend.stl`` (a disk turned 90 degrees about an axis)."""
    pytest.importorskip("gmsh")
    import numpy as np
    from shape_helpers import (
        duct_surface,
        turned_outline,
        turned_surface,
        write_ascii_stl,
        write_surface,
        write_sweep_solid,
        write_twisted_loft,
    )

    write_twisted_loft(folder / "part.step")
    write_sweep_solid("cylinder", folder / "cylinder.step")
    write_sweep_solid("fillet", folder / "fillet.step")
    write_ascii_stl(folder / "duct.stl", *duct_surface())
    write_surface(folder / "bend.stl", *turned_surface(turned_outline("torus"), np.pi / 2, 25))


PAGE_FILES = {"docs/shapes-from-files.md": shape_files}  # files a page names but does not make


@pytest.fixture(scope="module")
def docs_cache(tmp_path_factory):
    return tmp_path_factory.mktemp("cache")


@pytest.mark.parametrize(
    "page", [pytest.param(page, marks=[pytest.mark.slow] if page in SLOW_PAGES else []) for page in DOC_PAGES]
)
def test_code_blocks_run(page, tmp_path, monkeypatch, docs_cache):
    """Every block of ``page`` in order, in one temporary folder: shell lines as a user types them
    (``meshgen ...`` in this process), Python blocks in one namespace per page; a failure names the
    page and the block's line."""
    monkeypatch.chdir(tmp_path)
    monkeypatch.setenv("MESHGEN_CACHE_DIR", str(docs_cache))  # one cache for all pages, as a user has
    namespace: dict = {"__name__": "__docs__"}
    if page in PAGE_FILES:
        PAGE_FILES[page](tmp_path)
    for block in code_blocks(page):
        where = f"{page}:{block['line']}"
        markers = dict(block["markers"])
        body = block["body"]
        for what, args in block["markers"]:
            if what == "replace":
                old, new = shlex.split(args)
                assert old in body, f"{where}: replace marker's text {old!r} is not in the block"
                body = body.replace(old, new)
        if "skip" in markers:
            assert markers["skip"], f"{where}: a skip marker says why"
            continue
        if "file" in markers:
            (tmp_path / markers["file"]).write_text(body)
            continue
        assert block["lang"], f"{where}: a fence names its language (docs/contributing.md)"
        if block["lang"] == "python":
            exec(compile(body, where, "exec"), namespace)  # noqa: S102 - the page's own example
        elif block["lang"] in SHELL:
            for command in shell_commands({**block, "body": body}):
                status, output = run_shell(command, tmp_path)
                assert status == 0, f"{where}: `{command}` exited {status}:\n{output[-3000:]}"
        else:
            assert block["lang"] in NOT_RUN, f"{where}: fence language {block['lang']!r} is neither run nor listed"


# --- The API reference is the public modules' __all__ -----------------------------------------------


def api_hook():
    spec = importlib.util.spec_from_file_location("api_reference", REPO / "docs" / "hooks" / "api_reference.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def test_api_pages_list_exactly_the_public_names():
    hook = api_hook()
    pages = hook.api_pages()
    for module_name, _ in hook.PUBLIC_MODULES:
        module = importlib.import_module(module_name)
        page = pages[hook.page_path(module_name)]
        documented = re.findall(r"^## `([\w.]+)`$", page, flags=re.MULTILINE)
        assert documented == sorted(set(module.__all__) - {"__version__"}), module_name
        for name in documented:  # each name's entry renders the object the module hands out
            obj = getattr(module, name)
            entry = rf"^## `{re.escape(name)}`\n\n(?:::: |See \[`)([\w.]+)"
            target = re.search(entry, page, flags=re.MULTILINE)[1]
            owner, _, attribute = target.rpartition(".")
            assert getattr(importlib.import_module(owner), attribute) is obj, target
    listed = re.findall(r"\]\((meshgen[\w.]*\.md)\)", pages["api/index.md"])
    assert listed == [hook.page_path(name).removeprefix("api/") for name, _ in hook.PUBLIC_MODULES]


def test_api_hook_refuses_a_name_that_is_gone(monkeypatch):
    hook = api_hook()
    errors = importlib.import_module("meshgen.errors")
    monkeypatch.setattr(errors, "__all__", [*errors.__all__, "renamed_away"])
    with pytest.raises(AttributeError, match="renamed_away"):
        hook.api_pages()
