"""The package's layering, checked on the source (docs/architecture.md).

Every ``import`` counts, the ones inside functions and under ``if
TYPE_CHECKING:`` included: a lazy import may defer loading a heavy library,
never hide a cycle between frictionlab modules.
"""

from __future__ import annotations

import ast
import sys
from pathlib import Path

import pytest

SRC = Path(__file__).resolve().parents[1] / "src" / "frictionlab"
#: What the model may import besides itself.
MODEL_ALLOWED = {"numpy", "scipy", "numba"}


def _module_name(path: Path) -> str:
    parts = ["frictionlab", *path.relative_to(SRC).with_suffix("").parts]
    if parts[-1] == "__init__":
        parts.pop()
    return ".".join(parts)


def _modules() -> dict[str, Path]:
    return {_module_name(p): p for p in sorted(SRC.rglob("*.py"))}


def _imports(name: str, path: Path, modules: dict[str, Path]) -> set[str]:
    """Every module ``name`` imports at run time, at module level or inside a
    function (absolute names; frictionlab submodules resolved to the module,
    third-party ones to their top-level package)."""
    tree = ast.parse(path.read_text(), str(path))
    package = name if path.name == "__init__.py" else name.rpartition(".")[0]
    found: set[str] = set()
    for node in _runtime_nodes(tree):
        if isinstance(node, ast.Import):
            for alias in node.names:
                found.add(_resolve(alias.name, modules))
        elif isinstance(node, ast.ImportFrom):
            if node.level:
                base = package.split(".")[: len(package.split(".")) - node.level + 1]
                target = ".".join(base + ([node.module] if node.module else []))
            else:
                target = node.module
            sub = [f"{target}.{a.name}" for a in node.names if f"{target}.{a.name}" in modules]
            found.update(sub)
            if len(sub) < len(node.names):
                found.add(_resolve(target, modules))
    found.discard(name)
    return found


def _runtime_nodes(tree: ast.AST):
    """Every node, those under ``if TYPE_CHECKING:`` included: a type-only
    import closes a cycle for a type checker and a reader as much as any."""
    return ast.walk(tree)


def _resolve(target: str, modules: dict[str, Path]) -> str:
    if target.split(".")[0] != "frictionlab":
        return target.split(".")[0]
    while target not in modules:
        target = target.rpartition(".")[0]
    return target


def _graph() -> dict[str, set[str]]:
    modules = _modules()
    return {name: _imports(name, path, modules) for name, path in modules.items()}


def _cycles(graph: dict[str, set[str]]) -> list[list[str]]:
    """Strongly connected components with more than one module (Tarjan)."""
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    stack: list[str] = []
    on: set[str] = set()
    out: list[list[str]] = []

    def visit(v: str) -> None:
        index[v] = low[v] = len(index)
        stack.append(v)
        on.add(v)
        for w in graph.get(v, ()):
            if w not in graph:
                continue
            if w not in index:
                visit(w)
                low[v] = min(low[v], low[w])
            elif w in on:
                low[v] = min(low[v], index[w])
        if low[v] == index[v]:
            comp = []
            while True:
                w = stack.pop()
                on.discard(w)
                comp.append(w)
                if w == v:
                    break
            if len(comp) > 1:
                out.append(sorted(comp))

    sys.setrecursionlimit(10000)
    for v in sorted(graph):
        if v not in index:
            visit(v)
    return out


@pytest.mark.slow
def test_the_import_graph_is_acyclic_counting_function_level_imports():
    assert _cycles(_graph()) == []


@pytest.mark.slow
def test_the_model_imports_only_numpy_scipy_numba_and_the_standard_library():
    bad = {}
    for name, targets in _graph().items():
        if not name.startswith("frictionlab.model"):
            continue
        wrong = {t for t in targets
                 if not t.startswith("frictionlab.model")
                 and t not in MODEL_ALLOWED and t not in sys.stdlib_module_names
                 and t != "__future__"}
        if wrong:
            bad[name] = sorted(wrong)
    assert bad == {}


def _unresolved(name: str, path: Path, modules: dict[str, Path]) -> set[str]:
    """The frictionlab modules ``name`` imports that do not exist at their path
    (a former module path, say, that no longer exists)."""
    tree = ast.parse(path.read_text(), str(path))
    package = name if path.name == "__init__.py" else name.rpartition(".")[0]
    out: set[str] = set()
    for node in _runtime_nodes(tree):
        if isinstance(node, ast.Import):
            targets = [a.name for a in node.names]
        elif isinstance(node, ast.ImportFrom):
            if node.level:
                base = package.split(".")[: len(package.split(".")) - node.level + 1]
                targets = [".".join(base + ([node.module] if node.module else []))]
            else:
                targets = [node.module or ""]
        else:
            continue
        out.update(t for t in targets if t.split(".")[0] == "frictionlab" and t not in modules)
    return out


@pytest.mark.slow
def test_the_package_imports_its_modules_by_their_current_paths():
    # a module merged in at a former path, or an import of a former path, shows here:
    # move the module into its layer (docs/architecture.md) and import the new path
    modules = _modules()
    bad = {name: sorted(u) for name, path in modules.items()
           if (u := _unresolved(name, path, modules))}
    assert bad == {}


def test_the_checker_sees_a_cycle_hidden_in_a_function():
    graph = {"frictionlab.a": {"frictionlab.b"}, "frictionlab.b": {"frictionlab.a"},
             "frictionlab.c": {"frictionlab.a"}}
    assert _cycles(graph) == [["frictionlab.a", "frictionlab.b"]]


def test_the_checker_reads_function_level_and_relative_imports(tmp_path):
    modules = {"frictionlab": Path(), "frictionlab.x": Path(), "frictionlab.x.y": Path(),
               "frictionlab.z": Path()}
    path = tmp_path / "y.py"
    path.write_text("from typing import TYPE_CHECKING\nif TYPE_CHECKING:\n"
                    "    from .. import x\n"
                    "def f():\n    from ..z import g\n    from . import y\n    import numba\n")
    assert _imports("frictionlab.x.y", path, modules) == {"frictionlab.x", "frictionlab.z", "numba",
                                                          "typing"}
    path.write_text("from .old import f\nfrom ..z import g\n")
    assert _unresolved("frictionlab.x.y", path, modules) == {"frictionlab.x.old"}


@pytest.mark.parametrize("name", sorted(_modules()))
def test_every_module_parses(name):
    ast.parse(_modules()[name].read_text())


def _own_imports(path: Path):
    """``(node, in_function)`` for every import of a frictionlab module in ``path``."""
    tree = ast.parse(path.read_text(), str(path))
    parents = {child: node for node in ast.walk(tree) for child in ast.iter_child_nodes(node)}
    for node in ast.walk(tree):
        own = (isinstance(node, ast.ImportFrom)
               and (node.level > 0 or (node.module or "").startswith("frictionlab"))) or (
            isinstance(node, ast.Import)
            and any(a.name.startswith("frictionlab") for a in node.names))
        if not own:
            continue
        up, in_function = parents.get(node), False
        while up is not None and not in_function:
            in_function = isinstance(up, ast.FunctionDef | ast.AsyncFunctionDef)
            up = parents.get(up)
        yield node, in_function


def test_no_source_file_is_over_800_lines():
    long = {str(p.relative_to(SRC)): n for p in SRC.rglob("*.py")
            if (n := p.read_text().count("\n")) > 800}
    assert long == {}


def test_no_private_name_is_imported_across_modules():
    private = [f"{p.relative_to(SRC)}:{node.lineno} {a.name}"
               for p in SRC.rglob("*.py") for node, _ in _own_imports(p)
               if isinstance(node, ast.ImportFrom)
               for a in node.names if a.name.startswith("_") and not a.name.startswith("__")]
    assert private == []


def test_function_level_imports_of_own_modules_are_few_and_say_why():
    # outside cli/ (whose subcommands load what they run on first use), an own
    # module is imported inside a function only where start-up time needs it,
    # with a comment saying so just above it
    lazy = []
    for p in SRC.rglob("*.py"):
        if p.relative_to(SRC).parts[0] == "cli":
            continue
        lines = p.read_text().splitlines()
        for node, in_function in _own_imports(p):
            if in_function:
                above = lines[max(0, node.lineno - 4):node.lineno]
                lazy.append((f"{p.relative_to(SRC)}:{node.lineno}",
                             any("#" in line for line in above)))
    assert len(lazy) <= 10, lazy
    assert [where for where, commented in lazy if not commented] == []
