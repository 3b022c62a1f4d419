"""The method grammar moved to :mod:`rkhp.methods` (docs/methods.md), shared by every command and
the Python API; these names stay importable from here for scripts written against rkhp.studies."""

from ..methods import DEFAULT_METHODS, Method, condition_class, resolve_method, resolve_methods

__all__ = ["DEFAULT_METHODS", "Method", "condition_class", "resolve_method", "resolve_methods"]
