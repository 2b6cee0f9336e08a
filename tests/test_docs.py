"""The documentation's contracts with the code: the README stays a front page whose test command is
the one CI runs, every "design notes §N" a docstring cites is a section of docs/design.md, and code
and docs carry no issue numbers."""

from __future__ import annotations

import re
from pathlib import Path

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
    commands = re.findall(r"^    (pip install .*)$", readme, flags=re.MULTILINE)
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
