"""Imports between meshgen modules run downwards (design notes, "Layers and imports").

Read from the source (the AST of every module under ``meshgen/``), nothing is imported:

- the import graph has no cycle. One node per module (a package is its ``__init__``); one edge per
  import of a meshgen module, at module top level or inside a function alike (a lazy import is a
  dependency all the same). ``import meshgen.a.b``, ``from meshgen.a.b import name`` and
  ``from meshgen.a import b`` (``b`` a submodule) are edges to ``meshgen.a.b``;
  ``from meshgen.a import name`` (``name`` not a submodule) is an edge to ``meshgen.a``.
  Edges to a package: importing ``meshgen.p.m`` from a module outside package ``meshgen.p`` is
  also an edge to ``meshgen.p`` (Python runs its ``__init__`` first, and that ``__init__`` may
  import more); from a module inside ``meshgen.p`` it is not, so a package ``__init__`` that
  re-exports names from its own submodules makes no false cycle with them. The root package
  ``meshgen`` holds every module and imports none (its lazy names are a string map);
- no module imports a ``_private`` name of another meshgen module; a ``_private`` module
  (``meshgen.formats._cgns``) is imported only from inside its own package;
- every module defines ``__all__``;
- a function-level import of a meshgen module names a module that imports a heavy optional
  library (``LAZY_LIBRARIES``) at its own top level: every other meshgen import is at top level.

The ``*_NOT_YET`` sets list what modules outside this test's owner's area still break a rule;
each entry is a debt to pay, and the set only shrinks.
"""

from __future__ import annotations

import ast
from pathlib import Path

import pytest

PACKAGE_DIR = Path(__file__).resolve().parents[1] / "meshgen"

# Libraries imported inside the functions that use them: heavy to import or optional.
LAZY_LIBRARIES = (
    "torch",
    "dask",
    "distributed",
    "scipy",
    "trimesh",
    "meshio",
    "matplotlib",
    "gmsh",
    "h5py",
    "vtk",
    "numba",
    "rich",
    "psutil",
)

# The layers of the design notes, bottom first: a module imports from its own layer or lower ones.
# A name covers the module and, for a package, every module in it (the longest name that fits wins).
LAYERS = [
    [
        "meshgen",
        "meshgen.geometry",  # the subpackages' __init__ modules import nothing (lazy string maps)
        "meshgen.methods",
        "meshgen.run",
        "meshgen.errors",
        "meshgen.run.signals",
        "meshgen.run.publish",
        "meshgen.run.atomic",
        "meshgen.geometry.cube",
        "meshgen.geometry.grid",
        "meshgen.neural.mlp_numpy",
        "meshgen.run.resources",
        "meshgen.run.scheduler",
        "meshgen.run.limits",
        "meshgen.run.inputs",
    ],
    [
        "meshgen.methods.clustering",
        "meshgen.geometry.block_nodes",
        "meshgen.methods.tfi",
        "meshgen.methods.winslow",
        "meshgen.methods.winslow_compiled",
        "meshgen.methods.winslow_compiled_2d",
        "meshgen.methods.anderson",
        "meshgen.methods.sparse_newton",
        "meshgen.geometry.layout_start",
        "meshgen.methods.orthogonal",
        "meshgen.methods.hyperbolic",
        "meshgen.geometry.patches",
        "meshgen.geometry.cyclic",
        "meshgen.geometry.surface",
        "meshgen.geometry.domain",
        "meshgen.geometry.blocks",
        "meshgen.geometry.set_surface",
        "meshgen.geometry.shapes",
        "meshgen.geometry.topology_shorthand",
        "meshgen.geometry.topology_project",
        "meshgen.geometry.topology_file",
        "meshgen.geometry.topology",
        "meshgen.run.trust",
        "meshgen.geometry.plugin_calls",
        "meshgen.geometry.plugins",
        "meshgen.methods.multigrid",
        "meshgen.methods.multigrid_torch",
        "meshgen.methods.sliding",
        "meshgen.methods.interfaces",
        "meshgen.methods.face_angles",
        "meshgen.methods.face_angles_compiled",
        "meshgen.methods.surface_sliding",
        "meshgen.geometry.airfoil_curve",
        "meshgen.geometry.airfoils",
    ],
    [
        "meshgen.geometry.layout",
        "meshgen.geometry.layout_family",
        "meshgen.methods.elliptic",
        "meshgen.methods.polish",
        "meshgen.methods.multigrid_set",
        "meshgen.geometry.extrusion",
        "meshgen.geometry.grading",
        "meshgen.geometry.wall_spacing",
        "meshgen.geometry.airfoil_spacing",
        "meshgen.quality.deviation",
    ],
    [
        "meshgen.quality.kernels",
        "meshgen.quality.pool",
        "meshgen.quality.angles",
        "meshgen.quality.compiled",
        "meshgen.quality.compiled_quad",
        "meshgen.quality.numpy_kernels",
        "meshgen.quality.structured",
        "meshgen.quality.faces",
        "meshgen.quality.faces_compiled",
        "meshgen.quality.faces_openfoam",
        "meshgen.quality.smoothness_compiled",
        "meshgen.quality.smoothness",
        "meshgen.quality.report",
        "meshgen.quality.merged",
        "meshgen.quality.worker",
        "meshgen.quality.text",
        "meshgen.quality.sketch",
        "meshgen.quality.summary",
        "meshgen.quality.torch_kernels",
    ],
    ["meshgen.formats"],
    ["meshgen.quality", "meshgen.methods.correction"],
    ["meshgen.neural"],
    [
        "meshgen.run.chunked",
        "meshgen.methods.registry",
        "meshgen.run.meshing",
        "meshgen.quality.fidelity",
        "meshgen.quality.gates",
        "meshgen.cli.tables",
        "meshgen.cli.plots",
    ],
    ["meshgen.run.request"],
    ["meshgen.api", "meshgen.cli.comparison"],
    ["meshgen.cli", "meshgen.__main__"],
]

# Modules of the request path (meshing, methods, compare, commands) and of the training loop
# (meshgen.neural) that still break a rule. Debts to pay: each set only shrinks, to empty.
PRIVATE_IMPORTS_NOT_YET: set[tuple[str, str]] = set()
MISSING_ALL_NOT_YET: set[str] = set()
LAZY_MESHGEN_IMPORTS_NOT_YET: set[str] = set()


def module_name(path: Path) -> str:
    parts = path.relative_to(PACKAGE_DIR.parent).with_suffix("").parts
    return ".".join(parts[:-1] if parts[-1] == "__init__" else parts)


def modules() -> dict[str, tuple[Path, ast.Module]]:
    found = {}
    for path in sorted(PACKAGE_DIR.rglob("*.py")):
        found[module_name(path)] = (path, ast.parse(path.read_text(), filename=str(path)))
    return found


MODULES = modules()


def is_package(name: str) -> bool:
    return MODULES[name][0].name == "__init__.py"


def package_of(name: str) -> str:
    """The package a module belongs to (a package's own __init__ belongs to that package)."""
    return name if is_package(name) else name.rpartition(".")[0]


def inside(importer: str, package: str) -> bool:
    """Whether module ``importer`` lies in package ``package`` (at any depth)."""
    own = package_of(importer)
    return own == package or own.startswith(package + ".")


def imports(tree: ast.Module):
    """(node, at top level, [(module, imported name or None)]) for each import of a meshgen module."""
    top = {id(node) for node in tree.body}
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            targets = [(alias.name, None) for alias in node.names if alias.name.split(".")[0] == "meshgen"]
        elif isinstance(node, ast.ImportFrom) and node.level == 0 and (node.module or "").split(".")[0] == "meshgen":
            targets = [(node.module, alias.name) for alias in node.names]
        else:
            continue
        if targets:
            yield node, id(node) in top, targets


def imported_module(module: str, name: str | None) -> str:
    """The meshgen module an import reaches: ``from meshgen.a import b`` with ``b`` a submodule is
    ``meshgen.a.b``; any other name is ``meshgen.a`` itself."""
    if name is not None and f"{module}.{name}" in MODULES:
        return f"{module}.{name}"
    return module


def edges(importer: str, target: str) -> set[str]:
    """The modules an import of ``target`` from ``importer`` runs: ``target`` and the __init__ of
    each package of ``target`` that ``importer`` is outside of (the root package excluded)."""
    found = {target}
    parts = target.split(".")
    for depth in range(2, len(parts)):
        package = ".".join(parts[:depth])
        if not inside(importer, package):
            found.add(package)
    return found - {importer}


def import_graph() -> dict[str, set[str]]:
    graph = {name: set() for name in MODULES}
    for importer, (_, tree) in MODULES.items():
        for _, _, targets in imports(tree):
            for module, name in targets:
                target = imported_module(module, name)
                assert target in MODULES, f"{importer} imports {target}, which is not a module under meshgen/"
                graph[importer] |= edges(importer, target)
    return graph


def find_cycle(graph: dict[str, set[str]]) -> list[str] | None:
    """One cycle of ``graph`` as [a, b, ..., a], or None (iterative depth-first search)."""
    state = dict.fromkeys(graph, 0)  # 0 new, 1 on the current path, 2 done
    for start in sorted(graph):
        if state[start]:
            continue
        path, stack = [start], [iter(sorted(graph[start]))]
        state[start] = 1
        while stack:
            following = next(stack[-1], None)
            if following is None:
                state[path.pop()] = 2
                stack.pop()
            elif state[following] == 1:
                return path[path.index(following) :] + [following]
            elif state[following] == 0:
                state[following] = 1
                path.append(following)
                stack.append(iter(sorted(graph[following])))
    return None


def test_the_cycle_finder_finds_a_cycle_and_accepts_a_tree():
    assert find_cycle({"a": {"b"}, "b": {"c"}, "c": {"a"}, "d": set()}) == ["a", "b", "c", "a"]
    assert find_cycle({"a": {"b", "c"}, "b": {"c"}, "c": set()}) is None


def test_package_edges():
    # Outside the package, importing a submodule also runs the package's __init__; inside, not.
    assert edges("meshgen.run.chunked", "meshgen.quality.structured") == {"meshgen.quality.structured", "meshgen.quality"}
    assert edges("meshgen.quality.files", "meshgen.quality.structured") == {"meshgen.quality.structured"}
    assert edges("meshgen.quality", "meshgen.quality.files") == {"meshgen.quality.files"}
    assert imported_module("meshgen.quality", "sketch") == "meshgen.quality.sketch"
    assert imported_module("meshgen.quality", "cell_metrics") == "meshgen.quality"


def test_no_import_cycle_between_meshgen_modules():
    cycle = find_cycle(import_graph())
    assert cycle is None, "import cycle: " + " -> ".join(cycle)


def test_no_private_name_is_imported_from_another_module():
    found = set()
    for importer, (_, tree) in MODULES.items():
        for _, _, targets in imports(tree):
            for module, name in targets:
                path = module.split(".") + ([name] if name is not None and f"{module}.{name}" in MODULES else [])
                for depth, part in enumerate(path):
                    if part.startswith("_") and not part.startswith("__") and not inside(importer, ".".join(path[:depth])):
                        found.add((importer, ".".join(path[: depth + 1])))
                if name is not None and f"{module}.{name}" not in MODULES and name.startswith("_") and not name.startswith("__"):
                    found.add((importer, f"{module}.{name}"))
    assert found - PRIVATE_IMPORTS_NOT_YET == set()
    assert PRIVATE_IMPORTS_NOT_YET <= found, f"fixed, remove from the list: {sorted(PRIVATE_IMPORTS_NOT_YET - found)}"


def defines_all(tree: ast.Module) -> bool:
    for node in tree.body:
        targets = node.targets if isinstance(node, ast.Assign) else [node.target] if isinstance(node, ast.AnnAssign) else []
        if any(isinstance(t, ast.Name) and t.id == "__all__" for t in targets):
            return True
    return False


def test_every_module_defines_all():
    missing = {name for name, (_, tree) in MODULES.items() if not defines_all(tree)}
    assert missing - MISSING_ALL_NOT_YET == set()
    assert MISSING_ALL_NOT_YET <= missing, f"fixed, remove from the list: {sorted(MISSING_ALL_NOT_YET - missing)}"


def imports_a_lazy_library_at_top_level(name: str) -> bool:
    """Whether importing ``name`` imports a heavy library: directly at its top level, or through a
    meshgen module it imports at its top level."""
    heavy, stack, seen = False, [name], set()
    while stack and not heavy:
        current = stack.pop()
        if current in seen or current not in MODULES:
            continue
        seen.add(current)
        tree = MODULES[current][1]
        for node in tree.body:
            if isinstance(node, ast.Import):
                roots = [alias.name.split(".")[0] for alias in node.names]
            elif isinstance(node, ast.ImportFrom) and node.level == 0:
                roots = [(node.module or "").split(".")[0]]
            else:
                continue
            heavy = heavy or any(root in LAZY_LIBRARIES for root in roots)
        stack += [imported_module(module, imported) for _, top, targets in imports(tree) if top for module, imported in targets]
    return heavy


def test_function_level_imports_of_meshgen_modules_are_of_heavy_modules_only():
    found = {}
    for importer, (_, tree) in MODULES.items():
        for node, top, targets in imports(tree):
            for module, name in targets:
                target = imported_module(module, name)
                if not top and not imports_a_lazy_library_at_top_level(target):
                    found.setdefault(importer, []).append(f"line {node.lineno}: {target}")
    unexpected = {name: lines for name, lines in found.items() if name not in LAZY_MESHGEN_IMPORTS_NOT_YET}
    assert not unexpected, f"import these at module top level: {unexpected}"
    assert LAZY_MESHGEN_IMPORTS_NOT_YET <= set(found), f"fixed, remove: {sorted(LAZY_MESHGEN_IMPORTS_NOT_YET - set(found))}"


def layer_of(name: str) -> int | None:
    """The layer of module ``name``: that of the longest name in ``LAYERS`` that is it or a package holding it."""
    best, layer = "", None
    for number, names in enumerate(LAYERS):
        for listed in names:
            fits = name == listed or (listed != "meshgen" and name.startswith(listed + "."))
            if fits and len(listed) > len(best):
                best, layer = listed, number
    return layer


def test_imports_run_down_the_layers():
    unplaced = sorted(name for name in MODULES if layer_of(name) is None)
    assert not unplaced, f"give these modules a layer in LAYERS (and the design notes): {unplaced}"
    upwards = sorted(
        f"{importer} (layer {layer_of(importer)}) imports {target} (layer {layer_of(target)})"
        for importer, targets in import_graph().items()
        for target in targets
        if layer_of(target) > layer_of(importer)
    )
    assert not upwards, "imports up the layers: " + "; ".join(upwards)


@pytest.mark.parametrize(
    "name", ["meshgen.methods.elliptic", "meshgen.geometry.layout", "meshgen.quality.files", "meshgen.run.chunked"]
)
def test_the_cycles_this_test_guards_against_are_gone(name):
    """The two cycles that once hid behind function-level imports: elliptic <-> layout, and
    quality.files -> chunked -> neural inference -> quality."""
    graph = import_graph()

    def reaches(start, goal):
        seen, todo = set(), [start]
        while todo:
            current = todo.pop()
            for following in graph[current] - seen:
                if following == goal:
                    return True
                seen.add(following)
                todo.append(following)
        return False

    assert not reaches(name, name)
