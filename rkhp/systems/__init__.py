"""Poisson systems and their birealisations (docs/theory.md §4, paper §2).

`get_system(name_or_path, realisation="symmetric")` returns a :class:`PoissonSystem`;
`builtin_systems()` lists the built-in names. The registry of Poisson families (structure, base
birealisation, spec key) is `rkhp.systems.families`; realisations are in `rkhp.systems.core`;
spec files in `rkhp.systems.spec`.
"""

from . import general, quartic  # noqa: F401  (register the general family and the quartic realisation)
from .builtins import builtin_systems, get_system
from .core import REALISATIONS, PoissonSystem, register_realisation, shift_matrix

__all__ = ["PoissonSystem", "get_system", "builtin_systems", "REALISATIONS",
           "register_realisation", "shift_matrix"]
