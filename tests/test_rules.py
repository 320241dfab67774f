"""The project's rules on its own source, checked on the parsed code (strings and
comments do not count): short functions, a short top-level README, and the dependency
rules that `jaxunilat/README.md` states ("Dependencies run one way"): the layers inside
jaxunilat, jaxunilat's engine never importing its subpackage `jaxunilat.identify` (whose
source is the repository's top-level `identify/` folder), and identify importing only
jaxunilat's public names and `jaxunilat._internal`.

An import is every `import`/`from ... import` anywhere in a module (inside functions
too), relative ones resolved, and `importlib.import_module("...")`/`__import__("...")`
with a literal name.
"""

from __future__ import annotations

import ast
import functools
import pathlib

import jaxunilat

ROOT = pathlib.Path(__file__).resolve().parent.parent
PACKAGES = ("jaxunilat", "identify")

#: The longest function or method allowed, in lines (docstring included).
MAX_FUNCTION_LINES = 150
#: The top-level README's largest size, bytes (it is for users; design notes live beside the code).
MAX_README_BYTES = 12 * 1024

_CORE = {"_internal", "_models", "_solver"}
_VIEWS = {"analysis", "plot", "debug"}
#: What each part of jaxunilat may import of the others (`__init__`: the top-level package,
#: `import jaxunilat` included), as jaxunilat/README.md states it. A part not listed fails
#: the test: say where a new one sits, here and in the README.
LAYERS = {
    "_internal": set(),
    "_models": {"_internal"},
    "_solver": {"_models", "_internal"},
    "analysis": _CORE,
    "plot": _CORE,
    "debug": _CORE,
    "paper": _CORE | {"analysis", "plot"},
    "__init__": _CORE | _VIEWS | {"paper"},
    "_bench": _CORE | _VIEWS | {"paper", "__init__"},
    "bench": {"_bench"},
    "_cli": _CORE | _VIEWS | {"paper", "__init__", "_bench", "bench"},
    "__main__": {"_cli"},
}


def _sources(package: str) -> list[pathlib.Path]:
    return sorted((ROOT / package).rglob("*.py"))


def _where(path: pathlib.Path, line: int) -> str:
    return f"{path.relative_to(ROOT)}:{line}"


@functools.cache
def _tree(path: pathlib.Path) -> ast.Module:
    return ast.parse(path.read_text(encoding="utf-8"))


@functools.cache
def imports(path: pathlib.Path) -> tuple[tuple[int, str], ...]:
    """(line, absolute module name) of every import in a source file (identify/'s files are
    modules of `jaxunilat.identify`, as installed)."""
    return tuple(_imports_in(_tree(path), module_parts(path)))


def module_parts(path: pathlib.Path) -> tuple[str, ...]:
    """The dotted parts of the installed module a source file is (`__init__` for a package)."""
    parts = path.relative_to(ROOT).with_suffix("").parts
    return ("jaxunilat", *parts) if parts[0] == "identify" else parts


def is_identify(name: str) -> bool:
    """Whether an imported module name is (in) `jaxunilat.identify`, or a bare `identify`."""
    return name.split(".")[0] == "identify" or name.split(".")[:2] == ["jaxunilat", "identify"]


def _imports_in(tree: ast.Module, module: tuple[str, ...]) -> list[tuple[int, str]]:
    """(line, absolute module name) of every import in the parsed module `module` (its
    dotted parts, `__init__` for a package): for `from M import a` both M and M.a (a may
    be a submodule)."""
    package = list(module[:-1])  # the package that holds the module (for __init__: the package itself)
    found = []
    for node in ast.walk(tree):
        if isinstance(node, ast.ImportFrom):
            base = node.module or ""
            if node.level:
                anchor = package[: len(package) - (node.level - 1)]
                base = ".".join(anchor + ([base] if base else []))
            found += [(node.lineno, base)] + [(node.lineno, f"{base}.{a.name}") for a in node.names]
        elif isinstance(node, ast.Import):
            found += [(node.lineno, a.name) for a in node.names]
        elif isinstance(node, ast.Call) and _dynamic_import(node):
            found.append((node.lineno, node.args[0].value))
    return found


def _dynamic_import(node: ast.Call) -> bool:
    """`importlib.import_module("name")` or `__import__("name")` with a literal absolute name."""
    func = node.func
    name = func.attr if isinstance(func, ast.Attribute) else func.id if isinstance(func, ast.Name) else ""
    if name not in ("import_module", "__import__") or not node.args:
        return False
    arg = node.args[0]
    return isinstance(arg, ast.Constant) and isinstance(arg.value, str) and not arg.value.startswith(".")


def _part(path: pathlib.Path) -> str:
    """The part of jaxunilat a source file belongs to: its first folder, or the module name."""
    rel = path.relative_to(ROOT / "jaxunilat").parts
    return rel[0] if len(rel) > 1 else rel[0].removesuffix(".py")


def _imported_part(name: str) -> str | None:
    """The part of jaxunilat an import names (`__init__` for the top-level package and its
    attributes), None outside jaxunilat."""
    parts = name.split(".")
    if parts[0] != "jaxunilat":
        return None
    top = ROOT / "jaxunilat"
    if len(parts) > 1 and ((top / parts[1]).is_dir() or (top / f"{parts[1]}.py").is_file()):
        return parts[1]
    return "__init__"  # `import jaxunilat`, `from jaxunilat import simulate`, `__version__`


def test_no_function_is_over_150_lines():
    """Functions and methods short enough to read, in both packages (docstrings included)."""
    long = []
    for package in PACKAGES:
        for path in _sources(package):
            for node in ast.walk(_tree(path)):
                if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef)):
                    lines = node.end_lineno - node.lineno + 1
                    if lines > MAX_FUNCTION_LINES:
                        long.append(f"{_where(path, node.lineno)}: {node.name} ({lines} lines)")
    assert long == []


def test_the_top_level_readme_is_short_and_keeps_the_ci_commands():
    """README.md is for users (at most 12 KB), and holds the two commands CI runs verbatim
    (`.ci/run` reads the line after each marker's fence)."""
    text = (ROOT / "README.md").read_text(encoding="utf-8")
    assert len(text.encode("utf-8")) <= MAX_README_BYTES
    lines = text.splitlines()
    for marker in ("<!-- ci:main -->", "<!-- ci:test -->"):
        i = lines.index(marker)
        assert lines[i + 1].startswith("```") and lines[i + 2].strip() and lines[i + 3] == "```", marker


def test_jaxunilat_never_imports_identify():
    """The dependency runs one way: identify on jaxunilat's engine. The command line and the
    bench name identify's commands and rows in their tables, as "module:function" strings
    imported only when used; no module of jaxunilat imports identify."""
    offenders = [
        f"{_where(path, line)}: {name}"
        for path in _sources("jaxunilat")
        for line, name in imports(path)
        if is_identify(name)
    ]
    assert offenders == []


def test_identify_imports_no_private_jaxunilat_module():
    """identify imports jaxunilat's public names and `jaxunilat._internal`, never another
    private module (`jaxunilat._solver`, `jaxunilat._internal._io`, ...)."""
    offenders = [
        f"{_where(path, line)}: {name}"
        for path in _sources("identify")
        for line, name in imports(path)
        if private_of_jaxunilat(name)
    ]
    assert offenders == []


def private_of_jaxunilat(name: str) -> bool:
    """Whether a module name is private to jaxunilat's engine: under `jaxunilat`, not in
    `jaxunilat.identify`, with a `_` part, and neither `jaxunilat._internal` nor one of its
    public names."""
    parts = name.split(".")
    if parts[0] != "jaxunilat" or is_identify(name):
        return False
    if parts[1:2] == ["_internal"]:
        return len(parts) > 2 and parts[2].startswith("_")
    return any(p.startswith("_") for p in parts[1:])


def test_identify_reads_only_public_names_of_jaxunilat():
    """`ju.NAME` in identify names the curated public API (not a private attribute, and
    not one of the top-level aliases kept for the namespaces)."""
    public = {name for name in dir(jaxunilat) if not name.startswith("_")}
    offenders = []
    for path in _sources("identify"):
        tree = _tree(path)
        aliases = {
            a.asname or a.name
            for node in ast.walk(tree)
            if isinstance(node, ast.Import)
            for a in node.names
            if a.name == "jaxunilat"
        }
        for node in ast.walk(tree):
            if isinstance(node, ast.Attribute) and isinstance(node.value, ast.Name):
                if node.value.id in aliases and node.attr not in public:
                    offenders.append(f"{_where(path, node.lineno)}: {node.value.id}.{node.attr}")
    assert offenders == []


def test_the_layers_inside_jaxunilat():
    """Each part imports only the parts below it (`LAYERS`): `_internal` nothing of the rest,
    `_models` only `_internal`, `_solver` only `_models` and `_internal`, the views (`analysis`,
    `plot`, `debug`) only the core, and nothing but `__main__` imports `_cli`."""
    offenders = []
    for path in _sources("jaxunilat"):
        part = _part(path)
        if part not in LAYERS:
            offenders.append(f"{path.relative_to(ROOT)}: the part {part!r} has no layer (see LAYERS)")
            continue
        for line, name in imports(path):
            target = _imported_part(name)
            if target is not None and target != part and target not in LAYERS[part]:
                offenders.append(f"{_where(path, line)}: {name} ({part} -> {target})")
    assert offenders == []


def test_the_import_parser_sees_every_form():
    """The rules' parser: relative imports in modules and in `__init__.py`, imports inside
    functions, and importlib's with a literal name."""
    code = (
        "import identify.x\n"
        "from . import _a\n"
        "from .._solver import simulate\n"
        "def f():\n"
        "    from jaxunilat.identify import fit\n"
        "    importlib.import_module('identify._cli')\n"
        "    __import__('identify')\n"
    )
    names = [name for _, name in _imports_in(ast.parse(code), ("jaxunilat", "_models", "__init__"))]
    assert "jaxunilat._models._a" in names  # __init__.py: `.` is the package itself
    assert "jaxunilat._solver.simulate" in names
    assert {"identify.x", "jaxunilat.identify.fit", "identify._cli", "identify"} <= set(names)
    assert all(is_identify(n) for n in ("identify.x", "jaxunilat.identify.fit", "identify"))
    assert not is_identify("jaxunilat.identifying") and not private_of_jaxunilat(
        "jaxunilat._internal.EXIT_OK"
    )
    assert private_of_jaxunilat("jaxunilat._internal._io") and private_of_jaxunilat("jaxunilat._solver")
    assert _imported_part("jaxunilat") == _imported_part("jaxunilat.simulate") == "__init__"
    assert _imported_part("jaxunilat._solver._simulate") == "_solver"
