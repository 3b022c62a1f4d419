"""rkhp: Runge–Kutta–Hamiltonian–Poisson integrators (Busnot Laurent & Cosserat).

The package imports nothing heavy on start-up: the names below are loaded on first use.
"""

from __future__ import annotations

from ._lazy import lazy_getattr

__version__ = "0.1.0"

# public name -> module that defines it (loaded lazily, PEP 562)
_LAZY = {
    "Tree": "rkhp.trees",
    "parse_tree": "rkhp.trees",
    "trees_of_order": "rkhp.trees",
    "trees_up_to": "rkhp.trees",
    "count_trees": "rkhp.trees",
    "order_conditions": "rkhp.conditions",
    "InputError": "rkhp.errors",
    "NumericalFailure": "rkhp.errors",
    "integrate": "rkhp.methods",
    "resolve_method": "rkhp.methods",
    "Tableau": "rkhp.tableau",
    "load_tableau": "rkhp.tablefiles",
    "verify": "rkhp.verification",
    "get_system": "rkhp.systems",
}

__all__ = sorted(_LAZY)


__getattr__ = lazy_getattr("rkhp", _LAZY)


def __dir__():
    return sorted(set(globals()) | set(_LAZY))
