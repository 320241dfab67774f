"""The layers of `identify` (design notes: `identify/README.md`, "Layout").

Every import between identify's modules (at module level or inside a function) is
read from the source: the graph has no cycle, and a layer imports only itself and the
layers below it: `_data` nothing else of identify, `_fit` only `_data`, `_report` only
`_data` and `_fit`; `_apply` (qualify, MuJoCo export) nothing else. The top-level
modules (`__init__`, `_pipeline`, `plot`, the command line) may import every layer.
Run as a script, it prints the graph's edges between layers.
"""

from __future__ import annotations

import ast
import pathlib
import warnings

import pytest

from jaxunilat import identify

ROOT = pathlib.Path(identify.__file__).parent
#: Rank of each layer; a module imports its own layer or a layer of lower rank only.
RANKS = {"_data": 0, "_apply": 0, "_fit": 1, "_report": 2}
TOP = 3
PLOTS = ("plot_detection", "plot_fit", "plot_restitution", "plot_restitution_of_fit", "plot_table_import")


def _modules() -> dict[str, pathlib.Path]:
    """Dotted name → source file of every module of the package."""
    out = {}
    for path in sorted(ROOT.rglob("*.py")):
        parts = ["identify", *path.relative_to(ROOT).with_suffix("").parts]
        if parts[-1] == "__init__":
            parts = parts[:-1]
        out[".".join(parts)] = path
    return out


def _is_package(name: str, modules: dict[str, pathlib.Path]) -> bool:
    return modules[name].name == "__init__.py"


def _targets(name: str, node: ast.AST, modules: dict[str, pathlib.Path]) -> list[str]:
    """The identify modules one import statement of module `name` loads."""
    if isinstance(node, ast.Import):
        bases = [alias.name for alias in node.names]
        return [b for b in bases if b in modules]
    if node.level:
        package = name if _is_package(name, modules) else name.rsplit(".", 1)[0]
        for _ in range(node.level - 1):
            package = package.rsplit(".", 1)[0]
        base = f"{package}.{node.module}" if node.module else package
    else:
        base = node.module or ""
    out = [base] if base in modules else []
    out += [f"{base}.{alias.name}" for alias in node.names if f"{base}.{alias.name}" in modules]
    return out


def import_graph() -> dict[str, set[str]]:
    """Module → the identify modules it imports (anywhere in its source)."""
    modules = _modules()
    graph = {}
    for name, path in modules.items():
        tree = ast.parse(path.read_text(encoding="utf-8"))
        edges = set()
        for node in ast.walk(tree):
            if isinstance(node, (ast.Import, ast.ImportFrom)):
                edges.update(_targets(name, node, modules))
        edges.discard(name)
        graph[name] = edges
    return graph


def layer(name: str) -> str:
    """A module's layer: `_data`, `_fit`, `_report`, `_apply`, or "top"."""
    parts = name.split(".")
    return parts[1] if len(parts) >= 2 and parts[1] in RANKS else "top"


def rank(name: str) -> int:
    return RANKS.get(layer(name), TOP)


def find_cycle(graph: dict[str, set[str]]) -> list[str] | None:
    """One import cycle (a list of modules, the first repeated at the end), or None."""
    state: dict[str, int] = {}  # 1: on the current path, 2: done

    def visit(node: str, path: list[str]) -> list[str] | None:
        state[node] = 1
        for nxt in sorted(graph.get(node, ())):
            if state.get(nxt) == 1:
                return [*path[path.index(nxt) :], nxt]
            if nxt not in state:
                found = visit(nxt, [*path, nxt])
                if found:
                    return found
        state[node] = 2
        return None

    for start in sorted(graph):
        if start not in state:
            found = visit(start, [start])
            if found:
                return found
    return None


def layer_violations(graph: dict[str, set[str]]) -> list[str]:
    """`importer -> imported` for every import of another layer that is not below."""
    return [
        f"{a} -> {b}"
        for a, targets in sorted(graph.items())
        for b in sorted(targets)
        if layer(a) != layer(b) and rank(b) >= rank(a)
    ]


def test_the_import_graph_is_read_from_the_sources():
    graph = import_graph()
    # Known edges, module level and inside functions, relative and through a package.
    assert "identify._fit._stages" in graph["identify._pipeline"]
    assert "identify._fit._alone" in graph["identify._fit._summary"]
    assert "identify._data._import" in graph["identify._fit._plausible"]  # inside a function
    assert "identify._data._format" in graph["identify._data"]


def test_identify_modules_import_no_cycle():
    assert find_cycle(import_graph()) is None


def test_lower_layers_never_import_upper_ones():
    assert layer_violations(import_graph()) == []


def test_a_cycle_and_an_upward_import_are_found():
    graph = {"identify._fit._a": {"identify._report._b"}, "identify._report._b": {"identify._fit._a"}}
    assert find_cycle(graph) == ["identify._fit._a", "identify._report._b", "identify._fit._a"]
    assert layer_violations(graph) == ["identify._fit._a -> identify._report._b"]


@pytest.mark.parametrize("name", PLOTS)
def test_the_figures_live_in_identify_plot_only(name):
    assert name in identify.plot.__all__ and callable(getattr(identify.plot, name))
    assert not hasattr(identify, name)


def test_the_new_place_itself_does_not_warn():
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        assert callable(identify.plot.plot_fit)
        assert callable(identify.fit)


if __name__ == "__main__":
    g = import_graph()
    for a, targets in sorted(g.items()):
        across = sorted(b for b in targets if layer(b) != layer(a))
        if across:
            print(f"{a} ({layer(a)}) -> {', '.join(across)}")
    print("cycle:", find_cycle(g))
    print("layer violations:", layer_violations(g) or "none")
