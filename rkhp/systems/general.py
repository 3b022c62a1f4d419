"""The ``general`` family: any Poisson matrix pi(x) given as expressions (docs/theory.md §9).

The structure is checked on construction (`rkhp.systems.structure`: antisymmetry, the Jacobi
identity, the declared Casimirs, finiteness at x0). Its birealisation is the Poisson-spray
realisation (Weinstein; Crainic–Mărcuț): exactly (``symmetric``), or its series truncated at
degree K in p (``truncated:K``, `rkhp.systems.spray`).
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np

from ..errors import InputError
from .core import PoissonSystem, build_system
from .program import matrix_program, numeric_function
from .structure import StructureCheck, _symbols, check_finite_at, check_structure


def poisson_degree(entries, symbols) -> int | None:
    """The largest total degree of the entries as polynomials in the symbols (0 for a constant
    matrix), or None when an entry is not a polynomial."""
    import sympy

    degree = 0
    for row in entries:
        for e in row:
            if e == 0:
                continue
            if not e.is_polynomial(*symbols):
                return None
            degree = max(degree, sympy.Poly(e, *symbols).total_degree())
    return degree


def _numeric_matrix(entries, symbols) -> Callable:
    import sympy

    n = len(entries)
    f = sympy.lambdify(symbols, [e for row in entries for e in row], "numpy")

    def poisson(x):
        values = f(*np.asarray(x, dtype=np.float64))
        return np.array([float(v) for v in values]).reshape(n, n)

    return poisson


def _exact_realisation(poisson_program, n):
    raise InputError("the exact spray realisation of the general family is not available yet; "
                     "use --realisation truncated:K (K = 1..12)")


def general(entries, hamiltonian: Callable, *, name: str, x0, t_final: float,
            realisation: str = "symmetric", casimirs=(), casimir_names=(),
            exact_solution=None, description: str = "", domain: str = "R^n",
            where: str = "poisson", checked: StructureCheck | None = None,
            seed: int = 0) -> PoissonSystem:
    """A system xdot = pi(x) grad H(x) with pi given as an n x n matrix of sympy expressions in
    the real symbols x1..xn and `hamiltonian(x)` a program over tape values.

    `casimirs` are sympy expressions (checked to Poisson-commute with every x_i). The structure
    is checked unless `checked` (the result of an earlier :func:`check_structure`) is given;
    InputError (one line) if it is not a Poisson matrix or is singular at x0.
    """
    rows = tuple(tuple(row) for row in entries)
    n = len(rows)
    symbols = _symbols(n)
    x0 = np.asarray(x0, dtype=np.float64)
    check_finite_at(rows, x0, where)
    if checked is None:
        checked = check_structure(rows, casimirs=casimirs, x0=x0, seed=seed, where=where)
    numeric_casimirs = tuple(numeric_function(c, symbols) for c in casimirs)
    names = tuple(casimir_names) or tuple(str(c) for c in casimirs)
    program = matrix_program(rows, symbols)
    system = build_system(
        name=name, family="general", dim=n, poisson=_numeric_matrix(rows, symbols),
        hamiltonian=hamiltonian,
        base_alpha=lambda x, p: _exact_realisation(program, n),
        base_beta=lambda x, p: _exact_realisation(program, n),
        x0=x0, t_final=t_final, poisson_program=program,
        poisson_degree=poisson_degree(rows, symbols), realisation_name=realisation,
        domain=domain, casimirs=numeric_casimirs, casimir_names=names,
        exact_solution=exact_solution, description=description)
    system.extra["structure"] = rows
    system.extra["structure_check"] = checked
    return system
