"""One name for each thing: every class and function that rkhp/ defines, at the top of a module or
inside a function, has a name no other definition in the package has (read from the sources with
ast, nothing imported).

Methods are not counted: a method's name lives in its class and is reached through an instance,
where the same name in several classes is one interface (``to_floats`` of the weight arithmetics,
``submit`` of the executors). The one exception is a protocol that needs the same module-level
name in several modules, listed in :data:`PROTOCOLS` with the modules it may appear in.
"""

from __future__ import annotations

import ast
from collections import defaultdict
from pathlib import Path

import rkhp

ROOT = Path(rkhp.__file__).parent

#: name -> the modules allowed to define it, and why
PROTOCOLS = {
    # the substep providers of the driver: numba resolves the stubs `begin`, `resume` and `substep`
    # of rkhp.integrators.substeps to each provider's compiled functions of the same names
    # (docs/engine.md "One driver, many substeps")
    "begin": {"integrators/substeps.py", "integrators/tower_substep.py", "integrators/closed_euler.py",
              "integrators/spray_euler.py", "integrators/taylor.py"},
    "resume": {"integrators/substeps.py", "integrators/tower_substep.py", "integrators/closed_euler.py",
               "integrators/spray_euler.py", "integrators/taylor.py"},
    "substep": {"integrators/substeps.py", "integrators/closed_euler.py", "integrators/spray_euler.py",
                "integrators/taylor.py"},
    # a module's attribute hook (PEP 562): the lazy names of a package (rkhp._lazy), numba served
    # with rkhp's patches applied at the first request (rkhp.taylor.compiler)
    "__getattr__": {"_lazy.py", "taylor/compiler.py"},
}


def definitions(source: str) -> list[tuple[str, int]]:
    """(name, line) of every class and function of a module, methods aside (see the module)."""
    out = []

    def visit(node, in_class: bool) -> None:
        for child in ast.iter_child_nodes(node):
            if isinstance(child, ast.FunctionDef | ast.AsyncFunctionDef | ast.ClassDef):
                if isinstance(child, ast.ClassDef) or not in_class:
                    out.append((child.name, child.lineno))
                visit(child, isinstance(child, ast.ClassDef))
            else:
                visit(child, in_class)

    visit(ast.parse(source), False)
    return out


def test_definitions_counts_nested_functions_and_classes_not_methods():
    source = ("def f():\n    def g():\n        class C:\n            def m(self):\n                def h(): pass\n"
              "class D:\n    class E:\n        def m(self): pass\n    def n(self): pass\n")
    assert sorted(name for name, _ in definitions(source)) == ["C", "D", "E", "f", "g", "h"]


def test_every_name_is_defined_once():
    where = defaultdict(list)
    for path in sorted(ROOT.rglob("*.py")):
        module = path.relative_to(ROOT).as_posix()
        for name, line in definitions(path.read_text(encoding="utf-8")):
            where[name].append((module, line))
    assert len(where) > 500
    twice = {name: [f"{m}:{line}" for m, line in places] for name, places in where.items()
             if len(places) > 1 and not {m for m, _ in places} <= PROTOCOLS.get(name, set())}
    assert not twice, twice


def test_the_protocols_are_still_defined_where_listed():
    for name, modules in PROTOCOLS.items():
        for module in modules:
            assert name in {n for n, _ in definitions((ROOT / module).read_text(encoding="utf-8"))}, (name, module)
