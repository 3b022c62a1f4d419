"""The import graph of rkhp, read from the sources (ast, nothing imported), and public names that
no submodule can shadow.

How imports are counted (docs/engine.md "Layers and imports"):

- an edge A -> B for every ``import``/``from ... import`` of an rkhp module B in A, at the top of
  the module or inside a function alike: a deferred import is still a dependency, so a cycle
  through one is still a cycle;
- ``from package import name`` where the package serves `name` lazily (its ``_LAZY`` table,
  `rkhp._lazy`) is an edge to the module that defines `name`;
- the implicit loading of a module's parent packages is not an edge (every submodule would
  otherwise form a cycle with the package that re-exports it), but it counts for what a module
  loads (below).

An import inside a function is allowed only when it defers a heavy package (:data:`HEAVY`) that
the importing module does not already load through its top-level imports (transitively, parent
packages included): that is how `rkhp conditions` stays free of numba and dask while every other
import sits at the top of its module.
"""

from __future__ import annotations

import ast
import importlib
import pkgutil
from functools import cache
from pathlib import Path

import pytest

import rkhp

ROOT = Path(rkhp.__file__).parent
#: third-party packages heavy to import (each 0.1 s to 1.7 s measured with `python -c "import X"`)
HEAVY = frozenset({"numpy", "scipy", "sympy", "mpmath", "numba", "llvmlite", "matplotlib", "dask",
                   "distributed", "cloudpickle", "numbalsoda", "jax", "diffrax"})


def _module_files() -> dict[str, Path]:
    out = {}
    for path in ROOT.rglob("*.py"):
        parts = ("rkhp", *path.relative_to(ROOT).with_suffix("").parts)
        out[".".join(parts[:-1] if parts[-1] == "__init__" else parts)] = path
    return out


MODULES = _module_files()


def _lazy_table(tree: ast.Module) -> dict[str, str]:
    """A package's ``_LAZY = {name: module}`` table, if it has one."""
    for node in tree.body:
        if isinstance(node, ast.Assign) and any(getattr(t, "id", None) == "_LAZY" for t in node.targets):
            return ast.literal_eval(node.value)
    return {}


@cache
def _tree(name: str) -> ast.Module:
    return ast.parse(MODULES[name].read_text(encoding="utf-8"))


def _owner(name: str) -> str:
    """The rkhp module a dotted name lives in (rkhp.a.b.f -> rkhp.a.b), or the top package of a
    third-party name (numpy.linalg -> numpy)."""
    if name != "rkhp" and not name.startswith("rkhp."):
        return name.split(".")[0]
    while name not in MODULES:
        name = name.rsplit(".", 1)[0]
    return name


def _targets(module: str, node: ast.Import | ast.ImportFrom) -> list[str]:
    """The modules an import statement of `module` loads (rkhp modules by name, others by their
    top package)."""
    if isinstance(node, ast.Import):
        return [_owner(alias.name) for alias in node.names]
    if node.level:
        base = module.split(".")
        if MODULES[module].name != "__init__.py":
            base = base[:-1]
        base = base[: len(base) - (node.level - 1)]
        source = ".".join(base + ([node.module] if node.module else []))
    else:
        source = node.module
    if source != "rkhp" and not source.startswith("rkhp."):
        return [_owner(source)]
    out = []
    lazy = _lazy_table(_tree(source)) if source in MODULES else {}
    for alias in node.names:
        full = f"{source}.{alias.name}"
        out.append(full if full in MODULES else lazy.get(alias.name, _owner(source)))
    return out


def _imports(module: str) -> tuple[list[tuple[int, str]], list[tuple[int, str]]]:
    """(top-level imports, imports inside functions) of a module as (line, target module); the
    top level includes imports under a top-level ``if``/``try``."""
    tree = _tree(module)
    top_nodes = []
    for node in tree.body:
        if isinstance(node, ast.Import | ast.ImportFrom):
            top_nodes.append(node)
        elif isinstance(node, ast.If | ast.Try):
            top_nodes += [n for n in ast.walk(node) if isinstance(n, ast.Import | ast.ImportFrom)]
    ids = {id(n) for n in top_nodes}
    top = [(n.lineno, t) for n in top_nodes for t in _targets(module, n)]
    inner = [(n.lineno, t) for n in ast.walk(tree)
             if isinstance(n, ast.Import | ast.ImportFrom) and id(n) not in ids
             for t in _targets(module, n)]
    return top, inner


def _edges() -> dict[str, set[str]]:
    """module -> the rkhp modules it imports (anywhere in it), its lazy table included."""
    edges = {}
    for m in MODULES:
        top, inner = _imports(m)
        targets = {t for _, t in top + inner if t in MODULES and t != m}
        edges[m] = targets | set(_lazy_table(_tree(m)).values())
    return edges


@cache
def _loads(module: str) -> frozenset[str]:
    """Everything importing `module` loads through top-level imports: rkhp modules (parent
    packages included) and third-party top packages."""
    seen: set[str] = set()
    todo = [module]
    while todo:
        m = todo.pop()
        if m in seen:
            continue
        seen.add(m)
        if m in MODULES:
            todo += [t for _, t in _imports(m)[0]]
            parts = m.split(".")
            todo += [".".join(parts[:i]) for i in range(1, len(parts))]
    return frozenset(seen)


def _heavy(module: str) -> frozenset[str]:
    return _loads(module) & HEAVY


def _cycles(edges: dict[str, set[str]]) -> list[list[str]]:
    """The strongly connected components with more than one module (Tarjan, iterative)."""
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    stack: list[str] = []
    on_stack: set[str] = set()
    out = []
    for root in sorted(edges):
        if root in index:
            continue
        work = [(root, iter(sorted(edges[root])))]
        index[root] = low[root] = len(index)
        stack.append(root)
        on_stack.add(root)
        while work:
            v, children = work[-1]
            for w in children:
                if w not in index:
                    index[w] = low[w] = len(index)
                    stack.append(w)
                    on_stack.add(w)
                    work.append((w, iter(sorted(edges[w]))))
                    break
                if w in on_stack:
                    low[v] = min(low[v], index[w])
            else:
                work.pop()
                if work:
                    low[work[-1][0]] = min(low[work[-1][0]], low[v])
                if low[v] == index[v]:
                    component = []
                    while True:
                        w = stack.pop()
                        on_stack.discard(w)
                        component.append(w)
                        if w == v:
                            break
                    if len(component) > 1:
                        out.append(sorted(component))
    return out


def test_the_cycle_finder_finds_a_cycle():
    edges = {"a": {"b"}, "b": {"c"}, "c": {"a"}, "d": {"a"}, "e": set()}
    assert _cycles(edges) == [["a", "b", "c"]]
    assert _cycles({"a": {"b"}, "b": set()}) == []


def test_no_import_cycle_among_rkhp_modules():
    edges = _edges()
    assert len(edges) > 50
    cycles = _cycles(edges)
    assert not cycles, [[(a, sorted(edges[a] & set(c))) for a in c] for c in cycles]


ABOVE_BASE = ("rkhp.trees", "rkhp.tableaux", "rkhp.series", "rkhp.systems", "rkhp.integrators",
              "rkhp.studies", "rkhp.search")


@pytest.mark.parametrize("package,forbidden", [
    ("rkhp.taylor", ("rkhp.base",) + ABOVE_BASE),
    ("rkhp.base", ABOVE_BASE),
    ("rkhp.trees", ABOVE_BASE[1:] + ("rkhp.taylor",)),
    ("rkhp.tableaux", ABOVE_BASE[2:] + ("rkhp.taylor",)),
    ("rkhp.systems", ("rkhp.trees", "rkhp.tableaux", "rkhp.series", "rkhp.integrators", "rkhp.studies",
                      "rkhp.search")),
    ("rkhp.series", ("rkhp.integrators", "rkhp.studies", "rkhp.search")),
    ("rkhp.search", ("rkhp.integrators", "rkhp.studies")),
    ("rkhp.integrators", ("rkhp.studies", "rkhp.search")),
])
def test_layers_point_one_way(package, forbidden):
    """The rooms stand in layers (docs/engine.md "Layers and imports"): rkhp.taylor at the ground,
    then rkhp.base; the order conditions (rkhp.trees, then rkhp.tableaux) stand beside the Poisson
    systems and below the series evaluated on them (rkhp.series), the search and the integrators,
    with the studies on top."""
    edges = _edges()
    bad = {m: sorted(t for t in edges[m] if t.startswith(forbidden))
           for m in MODULES if m == package or m.startswith(package + ".")}
    assert not any(bad.values()), bad


def test_imports_inside_functions_only_defer_heavy_packages():
    """An import inside a function must spare its module a heavy package (see the module)."""
    bad = sorted({f"{MODULES[m].relative_to(ROOT.parent)}:{line} imports {target}"
                  for m in MODULES for line, target in _imports(m)[1]
                  if not (_heavy(target) - _heavy(m))})
    assert not bad, bad


def test_the_light_modules_stay_light():
    """What `rkhp conditions` and `rkhp trees` use loads none of the heavy packages."""
    for m in ("rkhp", "rkhp.trees.rooted", "rkhp.trees.conditions", "rkhp.trees.relations", "rkhp.integrators.methods"):
        assert not _heavy(m), (m, sorted(_heavy(m)))


def _all_submodules() -> list[str]:
    return sorted(m.name for m in pkgutil.walk_packages(rkhp.__path__, "rkhp."))


def test_public_names_survive_importing_every_submodule():
    """`import rkhp.search.driver; from rkhp import verify; verify("rk4")` works: importing a
    submodule never replaces a public name of its package (rkhp, and every subpackage that
    serves names lazily) by a module."""
    packages = {"rkhp": rkhp}
    for name in _all_submodules():
        module = importlib.import_module(name)
        if hasattr(module, "__path__"):
            packages[name] = module
    for name, package in packages.items():
        for public in getattr(package, "__all__", ()):
            value = getattr(package, public)
            assert not isinstance(value, type(rkhp)), f"{name}.{public} is a module"
    from rkhp import verify

    assert verify("rk4").order == 4


CLI = ROOT.parent / "cli"


def _cli_imports(path: Path) -> set[str]:
    """The rkhp_cli modules a module of cli/ imports (relative imports or ``rkhp_cli.X``)."""
    out = set()
    for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
        if isinstance(node, ast.ImportFrom) and node.level == 1:
            out |= {node.module} if node.module else {a.name for a in node.names}
        elif isinstance(node, ast.ImportFrom | ast.Import):
            names = [node.module] if isinstance(node, ast.ImportFrom) else [a.name for a in node.names]
            out |= {n.split(".")[1] for n in names if n and n.startswith("rkhp_cli.")}
    return out


def test_no_command_module_imports_another():
    """The modules that define the commands (rkhp_cli.main.COMMANDS) share code only through the
    shared modules of cli/ (options, render, terminal, the views): none imports another."""
    from rkhp_cli.main import COMMANDS

    commands = {module.removeprefix("rkhp_cli.") for module, _, _ in COMMANDS.values()}
    assert len(commands) > 5 and all((CLI / f"{m}.py").is_file() for m in commands)
    bad = {m: sorted(_cli_imports(CLI / f"{m}.py") & commands - {m}) for m in sorted(commands)}
    assert not any(bad.values()), bad


def test_the_cli_import_reader_sees_both_spellings(tmp_path):
    path = tmp_path / "x_cmd.py"
    path.write_text("from .a_cmd import f\nfrom . import b_cmd\nimport rkhp_cli.c_cmd\n"
                    "def g():\n    from rkhp_cli.d_cmd import h\n")
    assert _cli_imports(path) == {"a_cmd", "b_cmd", "c_cmd", "d_cmd"}
