"""The registry of Poisson families (docs/theory.md §4): one registration adds a family.

A :class:`PoissonFamily` is a Poisson structure given by data (the *structure*: structure
constants, a matrix...), with

- its spec key (the spec-file key that holds the structure) and the reader of that value;
- pi(x) as a numeric function, as a program over tape values (for the spray realisations
  ``truncated:K``, `rkhp.systems.spray`) with its degree as a polynomial, and symbolically (sympy,
  for `rkhp.systems.structure`'s checks) where available;
- its domain and its default Casimirs;
- its symmetric base birealisation: ``base(structure, sign)`` is the program (x, p, f) -> alpha
  (sign +1) or beta (sign -1), a list of n values, written once over any arithmetic that has
  + - * and numbers (tape Vars, `rkhp.series.differentials`' exact jets) and the functions of the
  namespace f (f.exp, f.phimv, f.crb: `rkhp.taylor.tape.functions` for tapes).

Realisations (`rkhp.systems.core`) compose every family's base with a shift. Spec files
(`rkhp.systems.spec`), the built-ins, `rkhp check` (through the system's pi) and the exact
elementary differentials (`rkhp.series.differentials`) all read the families from :data:`FAMILIES`.

The families:
- ``lie-poisson``: pi_ij(x) = sum_k C_ijk x_k; K(p) with K(p) x = -pi(x) p; alpha = phi(K(p)) x,
  beta = phi(-K(p)) x, phi(z) = z / (1 - e^{-z}) (a composite tape operation: power series with a
  guard, |K| < 0.9 * 2 pi). On so(3)* (structure ``LieAlgebra(SO3, closed_form=True)``, the
  built-in rigid body) the closed form alpha = x + (p x x)/2 + c(|p|^2) p x (p x x) is recorded
  instead.
- ``log-canonical``: pi_ij = lambda_ij x_i x_j on the positive orthant,
  alpha_i = x_i exp(-(1/2) sum_j lambda_ij x_j p_j).
- ``constant``: alpha = x - pi p / 2, beta = x + pi p / 2.
- ``general``: any pi(x) as expressions: the Poisson-spray realisation, one composite tape
  operation (docs/theory.md §9.3); registered by `rkhp.systems.general` (importing
  `rkhp.systems` registers it).
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from ..base import documents
from ..base.errors import InputError
from ..base.exact_text import combination_text
from ..taylor import tape as tp
from .core import PoissonSystem, SymbolicSystem, build_system
from .structure import lie_poisson_matrix, log_canonical_matrix, symbols_of

#: so(3)*: {x_i, x_j} = -eps_ijk x_k, i.e. pi(x) v = x cross v
SO3 = np.zeros((3, 3, 3))
for _i, _j, _k in ((0, 1, 2), (1, 2, 0), (2, 0, 1)):
    SO3[_i, _j, _k], SO3[_j, _i, _k] = -1.0, 1.0


@dataclass(frozen=True)
class PoissonFamily:
    """A family of Poisson structures (see the module).

    Attributes:
        name: as in spec files and `PoissonSystem.family`.
        spec_key: the spec-file key holding the structure.
        domain: a key of `rkhp.systems.core.DOMAINS`.
        read: (spec value, n, where) -> structure (InputError naming `where`).
        check: structure -> n (InputError if it is not a structure of this family).
        poisson: structure -> (x -> pi(x), float (n, n)).
        program: structure -> (y -> n x n entries: numbers or functions of y with + - * / ** and
            the tape functions), pi at the tape level.
        degree: structure -> the degree of pi as a polynomial in x (None if it is not one).
        base: (structure, sign) -> program (x, p, f) -> list of n values (alpha: +1, beta: -1).
        casimirs: structure -> (Casimir functions, their names) by default.
        symbolic: structure -> pi_ij(x1..xn) as sympy rows, or None.
        matrix: whether the spec value is an n x n matrix, one row per entry of x0 (lie-poisson's
            is a list of entries [i, j, k, value] instead).
    """

    name: str
    spec_key: str
    domain: str
    read: Callable
    check: Callable
    poisson: Callable
    program: Callable
    degree: Callable
    base: Callable
    casimirs: Callable
    symbolic: Callable | None = None
    matrix: bool = True


FAMILIES: dict[str, PoissonFamily] = {}

CONSTANT, LIE_POISSON, LOG_CANONICAL, GENERAL = "constant", "lie-poisson", "log-canonical", "general"
"""The names of the registered families (the last is registered by `rkhp.systems.general`)."""


def register_family(family: PoissonFamily) -> None:
    """Add a family to the registry (its name must be new)."""
    if family.name in FAMILIES:
        raise ValueError(f"family {family.name!r} is already registered")
    FAMILIES[family.name] = family


def family(name: str) -> PoissonFamily:
    """The family called `name` (InputError listing the registered ones otherwise)."""
    if name not in FAMILIES:
        raise InputError(f"family must be one of {', '.join(FAMILIES)}, got {name!r}")
    return FAMILIES[name]


def family_system(family_name: str, structure, hamiltonian: Callable, *, name: str, x0,
                  t_final: float, realisation: str = "symmetric", casimirs=None,
                  casimir_names=(), exact_solution=None, description: str = "",
                  hamiltonian_expression: Callable | None = None) -> PoissonSystem:
    """The system of a family's structure with Hamiltonian `hamiltonian(x)` (a program over tape
    Vars), its realisation `realisation` composed on the family's base; without `casimirs`, the
    family's default ones. `hamiltonian_expression()`: H as a sympy expression in the real
    symbols x1..xn, where the system is given by expressions (`PoissonSystem.symbolic`)."""
    fam = family(family_name)
    n = fam.check(structure)
    if casimirs is None:
        casimirs, casimir_names = fam.casimirs(structure)
    alpha, beta = fam.base(structure, 1.0), fam.base(structure, -1.0)
    system = build_system(name=name, family=fam.name, dim=n, poisson=fam.poisson(structure),
                          hamiltonian=hamiltonian,
                          base_alpha=lambda x, p: alpha(x, p, tp.functions),
                          base_beta=lambda x, p: beta(x, p, tp.functions),
                          x0=x0, t_final=t_final, poisson_program=fam.program(structure),
                          poisson_degree=fam.degree(structure), realisation_name=realisation,
                          domain=fam.domain, casimirs=casimirs, casimir_names=casimir_names,
                          exact_solution=exact_solution, description=description, structure=structure)
    if hamiltonian_expression is not None and fam.symbolic is not None:
        system.extra["symbolic"] = lambda: SymbolicSystem(symbols_of(n), fam.symbolic(structure),
                                                          hamiltonian_expression())
    return system


# ----------------------------------------------------------------------------------------------
# helpers of the families below


def check_antisymmetric(matrix: np.ndarray, what: str) -> None:
    """InputError unless `matrix` is a square, finite, antisymmetric float matrix."""
    if matrix.ndim != 2 or matrix.shape[0] != matrix.shape[1]:
        raise InputError(f"{what} must be a square matrix, got shape {matrix.shape}")
    if not np.all(np.isfinite(matrix)):
        raise InputError(f"{what} has non-finite entries")
    if not np.allclose(matrix, -matrix.T, rtol=0, atol=1e-14 * max(1.0, np.abs(matrix).max())):
        raise InputError(f"{what} is not antisymmetric")


def read_matrix(value, n: int, where: str) -> np.ndarray:
    """An n x n float matrix from a spec value (`rkhp.base.documents`: types, finite numbers)."""
    return np.array(documents.matrix(value, where, n))


def short(value) -> str:
    """A spec value as text, cut to 60 characters (for messages)."""
    text = value if isinstance(value, str) else repr(value)
    return text if len(text) <= 60 else text[:57] + "..."


def _combination(k: np.ndarray, term: str) -> str:
    """'k1 TERM1 - k2 TERM2 ...' with the coefficients rounded for display (within 1e-12 of 0
    or of +-1: left out, or written without a coefficient)."""
    def snapped(c: float) -> float:
        return 0.0 if abs(c) < 1e-12 else math.copysign(1.0, c) if abs(abs(c) - 1) < 1e-12 else c

    return combination_text(((snapped(c), f"{term}{i + 1}") for i, c in enumerate(k)),
                            lambda c: f"{c:.6g}")


def _linear_kernel(matrix: np.ndarray) -> list[np.ndarray]:
    from scipy.linalg import null_space

    return [v / np.abs(v).max() for v in null_space(matrix).T]


# ----------------------------------------------------------------------------------------------
# lie-poisson


@dataclass(frozen=True, eq=False)
class LieAlgebra:
    """The structure of a Lie–Poisson system: constants C[i, j, k] ({x_i, x_j} = sum_k C_ijk x_k);
    `closed_form`: record the so(3)* closed form (C must be :data:`SO3`) instead of phi(K) x."""

    constants: np.ndarray
    closed_form: bool = False


def _read_structure_constants(value, n: int, where: str) -> LieAlgebra:
    """C[i, j, k] from entries [i, j, k, value] (1-based integer indices, finite values;
    {x_j, x_i} = -{x_i, x_j} is implied)."""
    C = np.zeros((n, n, n))
    given: dict[tuple[int, int, int], float] = {}
    if not isinstance(value, list) or not value:
        raise InputError(f"{where} must be a non-empty list of [i, j, k, value]")
    if len(value) > n ** 3:
        raise InputError(f"{where}: {len(value)} entries; at most n^3 = {n ** 3}")
    for entry in value:
        if not (isinstance(entry, list) and len(entry) == 4):
            raise InputError(f"{where}: entry {short(entry)} is not [i, j, k, value]")
        i, j, k = entry[:3]
        if not all(type(q) is int and 1 <= q <= n for q in (i, j, k)):
            raise InputError(f"{where}: indices in {short(entry)} must be integers from 1 to {n}")
        v = documents.document_number(entry[3], f"{where}: value in {short(entry)}")
        if i == j:
            raise InputError(f"{where}: {{x_{i}, x_{i}}} = 0 by antisymmetry, got {entry!r}")
        for key, val in (((i, j, k), v), ((j, i, k), -v)):
            if key in given and given[key] != val:
                raise InputError(f"{where}: {entry!r} contradicts an earlier entry")
            given[key] = val
            C[key[0] - 1, key[1] - 1, key[2] - 1] = val
    return LieAlgebra(C)


def _check_lie(structure: LieAlgebra) -> int:
    C = np.asarray(structure.constants, dtype=np.float64)
    n = C.shape[0]
    if C.shape != (n, n, n):
        raise InputError(f"structure constants must have shape (n, n, n), got {C.shape}")
    for k in range(n):
        check_antisymmetric(C[:, :, k], f"structure constants C[:, :, {k + 1}]")
    if structure.closed_form and not np.array_equal(C, SO3):
        raise InputError("the closed-form realisation is that of so(3)*")
    return n


def _lie_poisson(structure: LieAlgebra):
    C = np.asarray(structure.constants, dtype=np.float64)

    def lie_poisson_at(x):
        return np.einsum("ijk,k->ij", C, np.asarray(x, dtype=np.float64))

    return lie_poisson_at


def _linear(coefficients, y):
    """sum_k c_k y_k over the non-zero c_k (0.0 when all vanish)."""
    terms = [y[k] * float(c) for k, c in enumerate(coefficients) if c != 0.0]
    return sum(terms[1:], terms[0]) if terms else 0.0


def so3_matrix(y):
    """pi(y) on so(3)*: pi(y) v = y cross v."""
    return [[0.0, -y[2], y[1]], [y[2], 0.0, -y[0]], [-y[1], y[0], 0.0]]


def _lie_program(structure: LieAlgebra):
    C = np.asarray(structure.constants, dtype=np.float64)
    n = C.shape[0]
    if structure.closed_form:
        return so3_matrix
    return lambda y: [[_linear(C[i, j], y) for j in range(n)] for i in range(n)]


def _cross_product(a, b):
    return [a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]]


def _lie_base(structure: LieAlgebra, sign: float):
    C = np.asarray(structure.constants, dtype=np.float64)
    n = C.shape[0]

    def phi_k(x, p, f):
        # K(p)_ik = -sum_j C_ijk p_j; alpha = phi(K(p)) x, beta = phi(-K(p)) x
        K = [[sum(-sign * C[i, j, k] * p[j] for j in range(n) if C[i, j, k] != 0.0)
              for k in range(n)] for i in range(n)]
        return f.phimv(K, x)

    def so3_closed(x, p, f):
        # alpha = x + (p x x)/2 + c(|p|^2) p x (p x x) (beta: sign -1; docs/theory.md §4)
        px = _cross_product(p, x)
        ppx = _cross_product(p, px)
        c = f.crb(p)
        return [x[i] + (0.5 * sign) * px[i] + c * ppx[i] for i in range(3)]

    return so3_closed if structure.closed_form else phi_k


def _lie_symbolic(structure: LieAlgebra):
    return lie_poisson_matrix(structure.constants)


register_family(PoissonFamily(
    name=LIE_POISSON, spec_key="structure_constants", domain="R^n",
    read=_read_structure_constants, check=_check_lie, poisson=_lie_poisson, program=_lie_program,
    degree=lambda structure: 1, base=_lie_base, casimirs=lambda structure: ((), ()),
    symbolic=_lie_symbolic, matrix=False))


# ----------------------------------------------------------------------------------------------
# log-canonical


def _check_matrix(what: str):
    def check(structure) -> int:
        matrix = np.asarray(structure, dtype=np.float64)
        check_antisymmetric(matrix, what)
        return matrix.shape[0]

    return check


def _log_canonical_base(lam, sign: float):
    L = np.asarray(lam)
    n = L.shape[0]

    def log_canonical_base(x, p, f):
        out = []
        for i in range(n):
            terms = [(-0.5 * sign * L[i, j]) * (x[j] * p[j]) for j in range(n) if L[i, j] != 0]
            out.append(x[i] * f.exp(sum(terms[1:], terms[0])) if terms else x[i])
        return out

    return log_canonical_base


def _log_canonical_casimirs(lam):
    kernel = _linear_kernel(np.asarray(lam, dtype=np.float64))
    return (tuple((lambda x, k=k: float(np.dot(k, np.log(x)))) for k in kernel),
            tuple(_combination(k, "log x") for k in kernel))


def _log_canonical_symbolic(lam):
    return log_canonical_matrix(lam)


def _log_canonical_program(lam):
    L = np.asarray(lam, dtype=np.float64)
    n = L.shape[0]
    return lambda y: [[y[i] * y[j] * float(L[i, j]) if L[i, j] else 0.0 for j in range(n)]
                      for i in range(n)]


def _log_canonical_poisson(lam):
    L = np.asarray(lam, dtype=np.float64)

    def log_canonical_at(x):
        x = np.asarray(x, dtype=np.float64)
        return L * np.outer(x, x)

    return log_canonical_at


register_family(PoissonFamily(
    name=LOG_CANONICAL, spec_key="lambda", domain="positive orthant", read=read_matrix,
    check=_check_matrix("lambda"), poisson=_log_canonical_poisson, program=_log_canonical_program,
    degree=lambda lam: 2, base=_log_canonical_base, casimirs=_log_canonical_casimirs,
    symbolic=_log_canonical_symbolic))


# ----------------------------------------------------------------------------------------------
# constant


def _constant_base(pi, sign: float):
    P = np.asarray(pi)
    n = P.shape[0]

    def constant_base(x, p, f):
        return [x[i] + sum((-0.5 * sign * P[i, j]) * p[j] for j in range(n) if P[i, j] != 0)
                for i in range(n)]

    return constant_base


def _constant_casimirs(pi):
    kernel = _linear_kernel(np.asarray(pi, dtype=np.float64))
    return (tuple((lambda x, k=k: float(np.dot(k, x))) for k in kernel),
            tuple(_combination(k, "x") for k in kernel))


def _constant_poisson(pi):
    P = np.asarray(pi, dtype=np.float64)
    return lambda x: P.copy()


def _constant_program(pi):
    P = np.asarray(pi, dtype=np.float64)
    return lambda y: [[float(v) for v in row] for row in P]


def _constant_symbolic(pi):
    import sympy

    return tuple(tuple(sympy.nsimplify(float(v)) for v in row) for row in np.asarray(pi, dtype=np.float64))


register_family(PoissonFamily(
    name=CONSTANT, spec_key="poisson", domain="R^n", read=read_matrix,
    check=_check_matrix("poisson"), poisson=_constant_poisson, program=_constant_program,
    degree=lambda pi: 0, base=_constant_base, casimirs=_constant_casimirs,
    symbolic=_constant_symbolic))
