"""Sphinx extension: the API reference, generated from the library itself at build time.

Two directives, so that no list of names or modules is written by hand:

- ``rkhp-public-names PACKAGE``: a table of the package's public names (its ``__all__``), each
  linked to its entry in the module where it is defined;
- ``rkhp-modules PACKAGE``: ``automodule`` with its members for every module of the package
  whose name has no leading underscore (found by walking the package), one section each.

A public name whose defining module is not documented, or a module that fails to import, breaks
the build (nitpicky mode turns the dangling link into an error).
"""

from __future__ import annotations

import importlib
import inspect
import pkgutil

from docutils import nodes
from docutils.statemachine import StringList
from sphinx.util.docutils import SphinxDirective
from sphinx.util.nodes import nested_parse_with_titles


def public_modules(package: str) -> list[str]:
    """The package and its submodules without a leading underscore in any component, sorted."""
    root = importlib.import_module(package)
    found = [package]
    for info in pkgutil.walk_packages(root.__path__, prefix=package + "."):
        if any(part.startswith("_") for part in info.name.split(".")):
            continue
        found.append(info.name)
    return sorted(found)


def role_of(obj) -> str:
    """The Python domain role that links to a class or a function."""
    return "py:class" if inspect.isclass(obj) else "py:func"


class PublicNames(SphinxDirective):
    """A table of a package's ``__all__``: name, kind, defining module (linked)."""

    required_arguments = 1

    def run(self):
        package = self.arguments[0]
        module = importlib.import_module(package)
        lines = [".. list-table::", "   :header-rows: 1", "   :widths: 30 70", "",
                 "   * - name", "     - defined in, with its first docstring line"]
        for name in module.__all__:
            obj = getattr(module, name)
            home = getattr(obj, "__module__", None) or package
            if not inspect.isclass(obj) and not callable(obj):
                lines += [f"   * - ``{package}.{name}``", f"     - ``{package}``: {escape(repr(obj))}"]
                continue
            target = f"{home}.{getattr(obj, '__qualname__', name)}"
            doc = (inspect.getdoc(obj) or "").strip().splitlines()
            summary = doc[0] if doc else ""
            lines += [f"   * - :{role_of(obj)}:`{package}.{name} <{target}>`",
                      f"     - ``{home}``" + (f": {escape(summary)}" if summary else "")]
        return parse_rst(self, lines)


class Modules(SphinxDirective):
    """``automodule`` with members for each public module of a package."""

    required_arguments = 1

    def run(self):
        lines: list[str] = []
        for name in public_modules(self.arguments[0]):
            lines += [name, "-" * len(name), "",
                      f".. automodule:: {name}", "   :members:", "   :undoc-members:", "   :ignore-module-all:", ""]
        return parse_rst(self, lines)


def escape(text: str) -> str:
    """Text safe inside a reST table cell (no markup)."""
    for char in "\\*`|_":
        text = text.replace(char, "\\" + char)
    return text


def parse_rst(directive: SphinxDirective, lines: list[str]):
    """Parse generated reST lines in place of the directive (inside ``eval-rst`` on MyST pages)."""
    if directive.env.doc2path(directive.env.docname).suffix == ".md":
        lines = ["````{eval-rst}", *lines, "````"]
    node = nodes.section()
    node.document = directive.state.document
    nested_parse_with_titles(directive.state, StringList(lines, source="<apigen>"), node)
    return node.children


# the kinds of object each role may link to when a short name is resolved
KINDS = {"func": ("function", "method", "classmethod", "staticmethod"), "class": ("class", "exception"),
         "meth": ("method", "classmethod", "staticmethod", "property"), "mod": ("module",)}


def resolve_short_name(app, env, node, contnode):
    """missing-reference: a Python name written short in a docstring (``Trajectory``,
    ``rkhp.systems.PoissonSystem`` for a re-export) links to the one documented object whose
    full name ends with it, or with its last component; a private name (``_Graph``) or a module
    constant without a docstring is shown without a link; ambiguous or unknown names stay
    unresolved (and fail a nitpicky build)."""
    if node.get("refdomain") != "py":
        return None
    domain = env.get_domain("py")
    target = node["reftarget"].lstrip("~.")
    if any(part.startswith("_") for part in target.split(".")):
        return contnode  # a private name: not documented, shown as code without a link
    kinds = KINDS.get(node.get("reftype"), ())
    for suffix in (target, target.rsplit(".", 1)[-1]):
        found = [name for name, entry in domain.objects.items()
                 if (name == suffix or name.endswith("." + suffix)) and (not kinds or entry.objtype in kinds)]
        if len(found) == 1:
            return domain.resolve_xref(env, node["refdoc"], app.builder, "obj", found[0], node, contnode)
        if found:
            return None
    if exists_undocumented(node.get("py:module"), target):
        return contnode  # a real module constant without a docstring: shown as code, no link
    return None


def exists_undocumented(module: str | None, target: str) -> bool:
    """Whether ``target`` names an attribute of ``module`` (where the docstring is) or a dotted
    path that imports: data such as a tuple of names has no docstring and so no entry."""
    try:
        if module and hasattr(importlib.import_module(module), target):
            return True
        parent, _, name = target.rpartition(".")
        return bool(parent) and hasattr(importlib.import_module(parent), name)
    except ImportError:
        return False


def setup(app):
    app.connect("missing-reference", resolve_short_name)
    app.add_directive("rkhp-public-names", PublicNames)
    app.add_directive("rkhp-modules", Modules)
    return {"parallel_read_safe": True, "parallel_write_safe": True}
