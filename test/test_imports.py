"""No import cycle among the modules of ``dualarm_control`` and ``dualarm_sim``.

The graph is built statically: every module's source is parsed with :mod:`ast` (nothing is
imported), and each ``import`` / ``from ... import`` naming one of the two packages, absolute or
relative, becomes an edge to the module it runs:

- ``import a.b.c`` and ``from a.b.c import name`` run ``a/__init__``, ``a/b/__init__`` and ``a/b/c``:
  an edge to each. The edge to a package that contains the importing module itself is left out:
  Python has started that package's ``__init__`` before the module (it is its parent), so the edge
  adds no ordering, only a spurious cycle (``solvers/__init__`` imports ``solvers.base``, which
  imports ``dualarm_control.errors``: ``dualarm_control/__init__`` is already running).
- ``from a.b import c`` where ``a.b.c`` is a module: an edge to ``a.b.c`` (and to ``a.b`` under the
  rule above). Where ``c`` is a name, not a module, the edge is to ``a.b`` (its ``__init__``), even
  from inside ``a.b``: that name must have been defined by the time it is asked for.

Which imports count, per kind:

- module-level (``MODULE``): statements that run when the module is imported, including those in
  class bodies, ``try`` and ``if`` blocks; these must form an acyclic graph, since a cycle of them is
  what breaks on a partially initialised module, depending on which module is imported first.
- function-level (``LAZY``): imports inside a function or lambda run when it is called, after every
  module involved has finished loading, so they can not fail that way. They are still dependencies,
  and they are held to the same rule: the graph of module-level and lazy imports together must be
  acyclic as well (a lazy import is there to defer a heavy or optional dependency, not to hide a
  cycle).
- ``if TYPE_CHECKING:`` blocks (``TYPING``) never run; they are checked too (all three kinds together
  acyclic), so that the layering mypy sees is the one the code runs with.

Dynamic imports (``importlib.import_module`` of message packages in ``ros/graph.py``) name no module
of these packages and are not followed.
"""

from __future__ import annotations

import ast
from collections.abc import Iterable, Iterator, Mapping
from itertools import pairwise
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
PACKAGES = ("dualarm_control", "dualarm_sim")

MODULE, LAZY, TYPING = "module", "lazy", "typing"

Graph = Mapping[str, Iterable[str]]


def module_files(root: Path = ROOT, packages: Iterable[str] = PACKAGES) -> dict[str, Path]:
    """Every module of ``packages`` under ``root``: dotted name -> file (a package is its ``__init__.py``)."""
    out: dict[str, Path] = {}
    for package in packages:
        for path in sorted((root / package).rglob("*.py")):
            parts = path.relative_to(root).with_suffix("").parts
            if parts[-1] == "__init__":
                parts = parts[:-1]
            out[".".join(parts)] = path
    return out


def _is_type_checking(test: ast.expr) -> bool:
    return (isinstance(test, ast.Name) and test.id == "TYPE_CHECKING") or (
        isinstance(test, ast.Attribute) and test.attr == "TYPE_CHECKING")


def _imports(tree: ast.AST) -> Iterator[tuple[ast.Import | ast.ImportFrom, str]]:
    """Every import statement of ``tree`` with its kind (MODULE, LAZY or TYPING)."""

    def walk(node: ast.AST, kind: str) -> Iterator[tuple[ast.Import | ast.ImportFrom, str]]:
        for child in ast.iter_child_nodes(node):
            if isinstance(child, (ast.Import, ast.ImportFrom)):
                yield child, kind
            elif isinstance(child, (ast.FunctionDef, ast.AsyncFunctionDef, ast.Lambda)):
                yield from walk(child, TYPING if kind == TYPING else LAZY)
            elif isinstance(child, ast.If) and _is_type_checking(child.test):
                for stmt in child.body:
                    yield from walk(ast.Module(body=[stmt], type_ignores=[]), TYPING)
                for stmt in child.orelse:
                    yield from walk(ast.Module(body=[stmt], type_ignores=[]), kind)
            else:
                yield from walk(child, kind)

    yield from walk(tree, MODULE)


def _with_parents(name: str, importer: str, modules: Mapping[str, Path]) -> set[str]:
    """``name`` and the packages Python initialises to import it, less those containing ``importer``."""
    parts = name.split(".")
    out = set()
    for k in range(1, len(parts) + 1):
        prefix = ".".join(parts[:k])
        if prefix in modules and not (importer + ".").startswith(prefix + "."):  # importer is or is in prefix
            out.add(prefix)
    return out


def _known_prefix(name: str, modules: Mapping[str, Path]) -> str | None:
    """The longest prefix of dotted ``name`` that is one of ``modules`` (``import a.b.c`` where c is a name)."""
    parts = name.split(".")
    for k in range(len(parts), 0, -1):
        prefix = ".".join(parts[:k])
        if prefix in modules:
            return prefix
    return None


def import_edges(name: str, source: str, modules: Mapping[str, Path]) -> dict[str, set[str]]:
    """The modules of ``modules`` that module ``name`` (source text ``source``) imports, per kind."""
    is_package = modules[name].name == "__init__.py"
    edges: dict[str, set[str]] = {MODULE: set(), LAZY: set(), TYPING: set()}
    for node, kind in _imports(ast.parse(source, filename=str(modules[name]))):
        targets: set[str] = set()
        if isinstance(node, ast.Import):
            for alias in node.names:
                found = _known_prefix(alias.name, modules)
                if found is not None:
                    targets |= _with_parents(found, name, modules)
        else:
            if node.level:
                package = name.split(".") if is_package else name.split(".")[:-1]
                if node.level > 1:
                    package = package[: len(package) - (node.level - 1)]
                base = ".".join([*package, *([node.module] if node.module else [])])
            else:
                base = node.module or ""
            found = _known_prefix(base, modules)
            if found is None:
                continue
            targets |= _with_parents(found, name, modules)
            for alias in node.names:
                sub = f"{found}.{alias.name}"
                if found == base and sub in modules:
                    targets |= _with_parents(sub, name, modules)
                elif found != name:
                    targets.add(found)  # a name defined by found's code, even from inside the package
        edges[kind] |= targets - {name}
    return edges


def package_graph(root: Path = ROOT, packages: Iterable[str] = PACKAGES) -> dict[str, dict[str, set[str]]]:
    """Per kind (MODULE, LAZY, TYPING): module -> the modules it imports."""
    modules = module_files(root, packages)
    graph: dict[str, dict[str, set[str]]] = {MODULE: {}, LAZY: {}, TYPING: {}}
    for name, path in modules.items():
        for kind, targets in import_edges(name, path.read_text(), modules).items():
            graph[kind][name] = targets
    return graph


def merged(graph: Mapping[str, Graph], kinds: Iterable[str]) -> dict[str, set[str]]:
    """The union of the graphs of ``kinds``."""
    out: dict[str, set[str]] = {}
    for kind in kinds:
        for node, targets in graph[kind].items():
            out.setdefault(node, set()).update(targets)
    return out


def strongly_connected(graph: Graph) -> list[list[str]]:
    """Tarjan's strongly connected components of ``graph`` (iterative), each sorted; nodes only
    named as targets count as nodes."""
    nodes = sorted(set(graph) | {t for targets in graph.values() for t in targets})
    succ = {n: sorted(graph.get(n, ())) for n in nodes}
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    stack: list[str] = []
    on_stack: set[str] = set()
    out: list[list[str]] = []
    for start in nodes:
        if start in index:
            continue
        index[start] = low[start] = len(index)
        stack.append(start)
        on_stack.add(start)
        work = [(start, iter(succ[start]))]
        while work:
            node, children = work[-1]
            for child in children:
                if child not in index:
                    index[child] = low[child] = len(index)
                    stack.append(child)
                    on_stack.add(child)
                    work.append((child, iter(succ[child])))
                    break
                if child in on_stack:
                    low[node] = min(low[node], index[child])
            else:
                work.pop()
                if work:
                    low[work[-1][0]] = min(low[work[-1][0]], low[node])
                if low[node] == index[node]:
                    component = []
                    while True:
                        member = stack.pop()
                        on_stack.discard(member)
                        component.append(member)
                        if member == node:
                            break
                    out.append(sorted(component))
    return out


def cycles(graph: Graph) -> list[list[str]]:
    """The import cycles of ``graph``: its strongly connected components of more than one module, and
    a module importing itself."""
    return sorted(c for c in strongly_connected(graph) if len(c) > 1 or c[0] in graph.get(c[0], ()))


def shortest_cycle(graph: Graph, component: list[str]) -> list[str]:
    """One shortest cycle through the first module of ``component``, closed (first == last): for the message."""
    members, start = set(component), component[0]
    previous: dict[str, str] = {}
    frontier = [start]
    while frontier:
        nxt = []
        for node in frontier:
            for child in sorted(graph.get(node, ())):
                if child == start:
                    path = [node]
                    while path[-1] != start:
                        path.append(previous[path[-1]])
                    return [*reversed(path), start]
                if child in members and child not in previous:
                    previous[child] = node
                    nxt.append(child)
        frontier = nxt
    return [start, start]


def describe(graph: Graph, kinds: Mapping[str, Graph] | None = None) -> str:
    """Every cycle of ``graph``, one per line: its modules and one shortest loop through them, each
    edge marked with its kinds (``-[lazy]->``) when the per-kind graphs ``kinds`` are given."""

    def arrow(a: str, b: str) -> str:
        marks = [k for k, g in (kinds or {}).items() if b in g.get(a, ())]
        return f" -[{','.join(marks)}]-> " if marks else " -> "

    lines = []
    for c in cycles(graph):
        loop = shortest_cycle(graph, c)
        lines.append(f"{len(c)} modules {c}: {loop[0]}" + "".join(arrow(a, b) + b for a, b in pairwise(loop)))
    return "\n".join(lines)


# --- the cycle finder itself -------------------------------------------------------------------


def test_cycle_finder_finds_a_cycle_and_only_the_cycle() -> None:
    graph = {"a": {"b"}, "b": {"c"}, "c": {"a", "d"}, "d": set(), "e": {"e"}, "f": {"d"}}
    assert cycles(graph) == [["a", "b", "c"], ["e"]]
    assert shortest_cycle(graph, ["a", "b", "c"]) == ["a", "b", "c", "a"]
    assert "a -> b -> c -> a" in describe(graph)
    assert "a -[module]-> b -[lazy]-> c -[module,lazy]-> a" in describe(
        graph, {"module": {"a": {"b"}, "c": {"a"}}, "lazy": {"b": {"c"}, "c": {"a"}}})
    assert cycles({"a": {"b"}, "b": {"c"}, "c": set()}) == []


def test_cycle_finder_on_a_deep_chain_does_not_recurse() -> None:
    chain = {str(k): {str(k + 1)} for k in range(5000)}
    assert cycles(chain) == []
    chain["5000"] = {"0"}
    assert [len(c) for c in cycles(chain)] == [5001]


def test_edges_resolve_relative_absolute_package_and_lazy_imports(tmp_path: Path) -> None:
    files = {
        "pkg/__init__.py": "from pkg.sub import thing\n",
        "pkg/sub/__init__.py": "from .impl import thing\n",
        "pkg/sub/impl.py": "import pkg.other\nfrom .. import util\nfrom . import helper\n",
        "pkg/sub/helper.py": "from pkg.sub import thing\n",
        "pkg/other.py": ("from typing import TYPE_CHECKING\nif TYPE_CHECKING:\n    from pkg.sub.impl import X\n"
                         "def f():\n    from pkg import util\n    import os\n"),
        "pkg/util.py": "class C:\n    import pkg.other.nothing\n",
    }
    for rel, text in files.items():
        (tmp_path / rel).parent.mkdir(parents=True, exist_ok=True)
        (tmp_path / rel).write_text(text)
    graph = package_graph(tmp_path, ["pkg"])
    assert graph[MODULE] == {
        "pkg": {"pkg.sub"},  # pkg.sub.thing is a name: pkg.sub's __init__
        "pkg.sub": {"pkg.sub.impl"},
        "pkg.sub.impl": {"pkg.other", "pkg.util", "pkg.sub.helper"},  # pkg, pkg.sub: its own parents
        "pkg.sub.helper": {"pkg.sub"},  # a name of its own package's __init__: a real dependency
        "pkg.other": set(),
        "pkg.util": {"pkg.other"},  # class body: module level; pkg.other.nothing is a name
    }
    assert graph[LAZY]["pkg.other"] == {"pkg.util"}
    assert graph[TYPING]["pkg.other"] == {"pkg.sub", "pkg.sub.impl"}
    assert cycles(graph[MODULE]) == [["pkg.sub", "pkg.sub.helper", "pkg.sub.impl"]]
    assert cycles(merged(graph, (MODULE, LAZY, TYPING))) == [
        ["pkg.other", "pkg.sub", "pkg.sub.helper", "pkg.sub.impl", "pkg.util"]]


# --- the packages ------------------------------------------------------------------------------


@pytest.fixture(scope="module")
def graph() -> dict[str, dict[str, set[str]]]:
    return package_graph()


def test_the_walk_sees_the_packages(graph: dict[str, dict[str, set[str]]]) -> None:
    nodes = graph[MODULE]
    assert {"dualarm_control", "dualarm_control.app.record.run_record", "dualarm_sim.cell"} <= set(nodes)
    assert "dualarm_control.app.record.run_record" in graph[MODULE]["dualarm_control.app.record.report"]
    assert "dualarm_control.ros.inputs" in graph[MODULE]["dualarm_control.app.bench.floor"]
    assert "dualarm_control.app.run.command" in graph[LAZY]["dualarm_control.app.cli"]


def test_no_cycle_among_module_level_imports(graph: dict[str, dict[str, set[str]]]) -> None:
    modules = graph[MODULE]
    assert not cycles(modules), "import cycles (module level):\n" + describe(modules)


def test_no_cycle_counting_lazy_and_type_checking_imports(graph: dict[str, dict[str, set[str]]]) -> None:
    everything = merged(graph, (MODULE, LAZY, TYPING))
    assert not cycles(everything), ("import cycles (module-level, lazy and TYPE_CHECKING):\n"
                                    + describe(everything, graph))
