"""rkhp: Runge–Kutta–Hamiltonian–Poisson integrators (Busnot Laurent & Cosserat).

The package imports nothing heavy on start-up: the names below are loaded on first use.
"""

from __future__ import annotations

from ._lazy import lazy_getattr

__version__ = "0.1.0"

# public name -> module that defines it (loaded lazily, PEP 562)
_LAZY = {
    "Tree": "rkhp.trees.rooted",
    "parse_tree": "rkhp.trees.rooted",
    "trees_of_order": "rkhp.trees.rooted",
    "trees_up_to": "rkhp.trees.rooted",
    "count_trees": "rkhp.trees.rooted",
    "order_conditions": "rkhp.trees.conditions",
    "InputError": "rkhp.base.errors",
    "NumericalFailure": "rkhp.base.errors",
    "integrate": "rkhp.integrators.methods",
    "resolve_method": "rkhp.integrators.methods",
    "Tableau": "rkhp.tableaux.tableau",
    "load_tableau": "rkhp.tableaux.files",
    "verify": "rkhp.tableaux.verification",
    "get_system": "rkhp.systems",
    "states_at": "rkhp.integrators.output_times",
    "system": "rkhp.systems.spec",
    "solve": "rkhp.ivp.solve",
    "event": "rkhp.ivp.events",
    "poincare_section": "rkhp.ivp.poincare",
    "json_form": "rkhp.base.json_form",
}

__all__ = sorted(_LAZY)


__getattr__ = lazy_getattr("rkhp", _LAZY)


def __dir__():
    return sorted(set(globals()) | set(_LAZY))
