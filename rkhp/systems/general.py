"""The ``general`` family: any Poisson matrix pi(x) given as expressions (docs/theory.md §9).

The structure (:class:`PoissonMatrix`) is checked on construction (`rkhp.systems.structure`:
antisymmetry, the Jacobi identity, the declared Casimirs, finiteness at x0). Its birealisation is
the Poisson-spray realisation (Weinstein; Crainic–Mărcuț), symmetric: evaluated to round-off in
the engine's Taylor arithmetic by the composite operation `rkhp.taylor.tape.record_spray` (Gauss
collocation with the average constraint, `rkhp.taylor.composites.spray`; docs/theory.md §9.3), or
its series truncated at degree K in p (``truncated:K``, `rkhp.systems.spray`).

The family's functions below are registered in the registry `rkhp.systems.families` when this
module is imported (spec key ``poisson``, a matrix of expression strings; importing
`rkhp.systems` imports it); :func:`general` builds a system.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from ..base.errors import InputError
from ..base.expressions import parse_expression, variable_names
from .core import PoissonSystem
from .families import GENERAL, PoissonFamily, family_system, register_family, short
from .program import matrix_program, numeric_function
from .structure import StructureCheck, check_matrix_finite_at, check_structure, symbols_of


@dataclass(frozen=True, eq=False)
class PoissonMatrix:
    """The structure of a general system: pi_ij(x) = {x_i, x_j} as sympy expressions in the
    real symbols x1..xn (rows)."""

    entries: tuple

    @property
    def dim(self) -> int:
        return len(self.entries)


def read_poisson_matrix(value, n: int, where: str) -> PoissonMatrix:
    """An n x n matrix of expressions (strings, or numbers) read by the safe reader."""
    if not (isinstance(value, list) and len(value) == n
            and all(isinstance(row, list) and len(row) == n for row in value)):
        raise InputError(f"{where} must be a {n} x {n} matrix (the size of x0) of expression "
                         f"strings")
    entries = []
    for i, row in enumerate(value):
        out = []
        for j, entry in enumerate(row):
            if isinstance(entry, bool) or not isinstance(entry, str | int | float):
                raise InputError(f"{where}: entry ({i + 1}, {j + 1}) must be an expression string "
                                 f"or a number, got {short(entry)}")
            text = entry if isinstance(entry, str) else repr(entry)
            out.append(parse_expression(text, variable_names(n), where=f"{where} ({i + 1}, {j + 1})"))
        entries.append(tuple(out))
    return PoissonMatrix(tuple(entries))


def check_shape(structure: PoissonMatrix) -> int:
    """n (InputError unless the entries form a non-empty square matrix)."""
    rows = structure.entries
    if not rows or any(len(r) != len(rows) for r in rows):
        raise InputError("poisson must be a square matrix of expressions")
    return len(rows)


def poisson_degree(structure: PoissonMatrix) -> int | None:
    """The largest total degree of the entries as polynomials in x1..xn (0 for a constant
    matrix), or None when an entry is not a polynomial."""
    import sympy

    symbols = symbols_of(structure.dim)
    degree = 0
    for row in structure.entries:
        for e in row:
            if e == 0:
                continue
            if not e.is_polynomial(*symbols):
                return None
            degree = max(degree, sympy.Poly(e, *symbols).total_degree())
    return degree


def numeric_poisson(structure: PoissonMatrix) -> Callable:
    """x -> pi(x) as a float (n, n) array."""
    import sympy

    n = structure.dim
    f = sympy.lambdify(symbols_of(n), [e for row in structure.entries for e in row], "numpy")

    def poisson_at(x):
        values = f(*np.asarray(x, dtype=np.float64))
        return np.array([float(v) for v in values]).reshape(n, n)

    return poisson_at


def poisson_program(structure: PoissonMatrix):
    """y -> the n x n entries over tape values (numbers where constant)."""
    return matrix_program(structure.entries, symbols_of(structure.dim))


def spray_base(structure: PoissonMatrix, sign: float):
    """The symmetric spray_base_point: alpha (sign +1) or beta (sign -1) of the Poisson-spray realisation,
    one composite operation f.spray (`rkhp.taylor.tape.record_spray`) giving both."""
    program = poisson_program(structure)
    n = structure.dim

    def spray_base_point(x, p, f):
        pair = f.spray(program, x, p)
        return pair[:n] if sign > 0 else pair[n:]

    return spray_base_point


register_family(PoissonFamily(
    name=GENERAL, spec_key="poisson", domain="R^n", read=read_poisson_matrix, check=check_shape,
    poisson=numeric_poisson, program=poisson_program, degree=poisson_degree, base=spray_base,
    casimirs=lambda structure: ((), ()), symbolic=lambda structure: structure.entries))


def general(structure: PoissonMatrix, hamiltonian: Callable, *, name: str, x0, t_final: float,
            realisation: str = "symmetric", casimirs=(), casimir_names=(),
            exact_solution=None, description: str = "", where: str = "poisson",
            checked: StructureCheck | None = None, seed: int = 0,
            hamiltonian_expression: Callable | None = None) -> PoissonSystem:
    """A system xdot = pi(x) grad H(x) of the general family, `hamiltonian(x)` a program over
    tape values.

    `casimirs` are sympy expressions (checked to Poisson-commute with every x_i). The structure
    is checked unless `checked` (the result of an earlier :func:`check_structure`) is given;
    InputError (one line, naming `where`) if it is not a Poisson matrix or is singular at x0.
    `hamiltonian_expression`: as for `rkhp.systems.families.family_system`.
    """
    x0 = np.asarray(x0, dtype=np.float64)
    rows = structure.entries
    check_matrix_finite_at(rows, x0, where)
    if checked is None:
        checked = check_structure(rows, casimirs=casimirs, x0=x0, seed=seed, where=where)
    symbols = symbols_of(structure.dim)
    system = family_system(
        GENERAL, structure, hamiltonian, name=name, x0=x0, t_final=t_final,
        realisation=realisation, casimirs=tuple(numeric_function(c, symbols) for c in casimirs),
        casimir_names=tuple(casimir_names) or tuple(str(c) for c in casimirs),
        exact_solution=exact_solution, description=description,
        hamiltonian_expression=hamiltonian_expression)
    system.extra["structure_check"] = checked
    return system
