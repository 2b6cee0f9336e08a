"""mkdocs hook: the API reference pages, written at build time from the public modules' ``__all__``.

Each public module gets one page, ``api/<module>.md``, with one ``## `name` `` entry per name of its
``__all__`` rendered by mkdocstrings from the object the module hands out (``meshgen.mesh`` is
documented where it is defined, ``meshgen.run.request.mesh``). A name in ``__all__`` that the module
no longer has stops the build, so a renamed or removed function breaks ``mkdocs build --strict``
instead of the reader; a public module missing from ``nav`` does too (``omitted_files``).
"""

from __future__ import annotations

import importlib
import inspect

# The modules a user imports from, in the order of the reference; each is documented by its __all__.
PUBLIC_MODULES = [
    ("meshgen", "the top level: mesh, Mesh, read, write, evaluate, tfi, elliptic, load_geometry, the errors"),
    ("meshgen.errors", "the exceptions the command line turns into one-line errors"),
    ("meshgen.geometry.plugins", "geometry plugins: loading, checking, discovery"),
    ("meshgen.methods.tfi", "transfinite interpolation"),
    ("meshgen.methods.elliptic", "the Winslow equations by nonlinear multigrid"),
    ("meshgen.run.request", "a whole meshing request: output, patches, chunking"),
    ("meshgen.quality", "per-cell metrics, summaries, reports"),
    ("meshgen.formats", "the format registry, write_mesh, read_mesh"),
]
HIDDEN = {"__version__"}  # in meshgen.__all__, a string: stated on the index page


def page_path(module_name: str) -> str:
    return f"api/{module_name}.md"


def _target(module_name: str, name: str) -> str:
    """The dotted path mkdocstrings renders for ``module.name``: where a function or class is
    defined, else the module's own attribute. AttributeError when the module lacks the name."""
    obj = getattr(importlib.import_module(module_name), name)
    if inspect.isfunction(obj) or inspect.isclass(obj):
        owner = importlib.import_module(obj.__module__)
        if getattr(owner, obj.__qualname__, None) is obj:
            return f"{obj.__module__}.{obj.__qualname__}"
    return f"{module_name}.{name}"


def _homes() -> dict[str, str]:
    """Each documented object's one page (rendered once, linked from the others): the page of the
    public module that defines it and lists it, else the first page that lists it."""
    homes: dict[str, str] = {}
    for module_name, _ in PUBLIC_MODULES:
        for name in sorted(set(importlib.import_module(module_name).__all__) - HIDDEN):
            target = _target(module_name, name)
            if target.rpartition(".")[0] == module_name or target not in homes:
                homes[target] = module_name
    return homes


def module_page(module_name: str, summary: str, homes: dict[str, str]) -> str:
    module = importlib.import_module(module_name)
    names = sorted(set(module.__all__) - HIDDEN)
    lines = [f"# `{module_name}`", "", f"{summary[0].upper()}{summary[1:]}.", ""]
    lines += [f"::: {module_name}", "    options:", "      members: false", "      show_root_heading: false", ""]
    for name in names:
        target = _target(module_name, name)
        lines += [f"## `{name}`", ""]
        if homes[target] == module_name:
            lines += [f"::: {target}", "    options:", "      show_root_heading: false", ""]
        else:
            lines += [f"See [`{target}`]({homes[target]}.md#{target}).", ""]
    return "\n".join(lines)


def index_page() -> str:
    import meshgen

    lines = [
        "# API reference",
        "",
        f"meshgen {meshgen.__version__}. These pages are written when the site is built, from the `__all__` of",
        "each public module (`docs/hooks/api_reference.py`): every name listed is importable from its module.",
        "",
        "| module | what it holds |",
        "|---|---|",
    ]
    lines += [f"| [`{name}`]({page_path(name).removeprefix('api/')}) | {summary} |" for name, summary in PUBLIC_MODULES]
    return "\n".join([*lines, ""])


def api_pages() -> dict[str, str]:
    """Every page of the reference, by its path under docs/."""
    pages = {"api/index.md": index_page()}
    homes = _homes()
    pages.update({page_path(name): module_page(name, summary, homes) for name, summary in PUBLIC_MODULES})
    return pages


def on_files(files, config):
    from mkdocs.structure.files import File

    for path, content in api_pages().items():
        files.append(File.generated(config, path, content=content))
    return files
