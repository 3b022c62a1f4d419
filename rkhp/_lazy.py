"""Lazy module attributes (PEP 562): names load their defining module on first use, so that
importing a package costs nothing for what a command does not use (no numba, sympy, scipy)."""

from __future__ import annotations

import importlib
import sys


def lazy_getattr(package: str, table: dict[str, str]):
    """A module-level ``__getattr__`` serving ``table`` (public name -> defining module)."""

    def __getattr__(name: str):
        if name in table:
            value = getattr(importlib.import_module(table[name]), name)
            setattr(sys.modules[package], name, value)  # found directly from now on
            return value
        raise AttributeError(f"module {package!r} has no attribute {name!r}")

    return __getattr__
