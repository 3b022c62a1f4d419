"""Checks of a Poisson matrix given as sympy expressions in x1..xn (docs/theory.md §4 and §9).

A matrix pi(x) with pi_ij = {x_i, x_j} is a Poisson structure when it is antisymmetric and the
Jacobi identity holds,

    J_ijk = {x_i, {x_j, x_k}} + {x_j, {x_k, x_i}} + {x_k, {x_i, x_j}}
          = sum_l pi_il d_l pi_jk + pi_jl d_l pi_ki + pi_kl d_l pi_ij = 0,

and a function C is a Casimir when {C, x_i} = sum_l d_l C pi_li = 0 for every i (convention
{f, g} = grad f . pi grad g). J is totally antisymmetric once pi is, so only the triples
i < j < k are checked.

How each identity is decided (:func:`decide_zero`):

1. symbolically, with a bounded effort: rational expressions (after treating exp, sin, ... as
   generators) are brought to one fraction whose numerator is expanded, which decides a rational
   expression exactly either way; other expressions are passed to sympy's ``simplify`` when they
   are small, which can only prove them zero. Sizes are bounded before each step (operation counts,
   a bound on the number of expanded terms) and the whole symbolic work has a time budget
   (:data:`SYMBOLIC_SECONDS`); what is left undecided is decided numerically;
2. numerically, at seeded random points near x0 (:func:`random_points_near`): a residual passes when
   it is at most :data:`TOLERANCE` times the sum of the absolute values of its terms (the size of
   its rounding errors; the factors at each point are scaled by powers of two,
   :data:`LARGEST_EXPONENT`, so that a large pi or grad C still gives finite products). The
   numeric test runs on every identity first (it is cheap and finds every failure that is not
   tiny); the symbolic one then proves the rest or finds a failure below the numeric tolerance.

A structure that fails is refused with an InputError of one line naming the failing triple
(i, j, k) (1-based) or the failing Casimir and x_i, and the residual.
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass
from decimal import Decimal
from itertools import combinations

import numpy as np

from ..base.errors import InputError
from ..base.expressions import variable_names

#: a numeric residual passes when |r| <= TOLERANCE * (sum of |terms|)
TOLERANCE = 1e-9
#: random points of the numeric check
POINTS = 12
#: time budget of the symbolic proofs of one structure (seconds, checked between proofs)
SYMBOLIC_SECONDS = 10.0
#: expressions with more operations are not simplified symbolically
MAX_OPS = 4_000
#: ... nor passed to sympy's `simplify` (which can take long on larger ones)
MAX_SIMPLIFY_OPS = 80
#: a bound on the number of terms an expansion may produce
MAX_EXPANDED_TERMS = 20_000
#: the factors of the numeric check at a point (pi and its derivatives; grad C) larger than
#: 2**LARGEST_EXPONENT are divided there by a power of two that brings them down to it: J is
#: quadratic in pi and {C, x_i} linear in pi and in grad C, so the residuals relative to their
#: terms are unchanged (exactly: powers of two), while products of two factors summed over three
#: times MAX_DIMENSION terms stay below float64's largest number, 2**1024
LARGEST_EXPONENT = 500


@dataclass(frozen=True)
class StructureCheck:
    """How a Poisson matrix and its declared Casimirs were checked.

    Attributes:
        dim: n.
        jacobi_triples: triples i < j < k whose J_ijk is not identically zero term by term.
        jacobi_symbolic: how many of them were proved zero symbolically (the others numerically).
        casimir_identities: identities {C, x_i} = 0 that are not trivially zero.
        casimir_symbolic: how many of them were proved zero symbolically.
        residual: the largest numeric residual relative to its terms, over all identities.
        tolerance: the numeric tolerance (relative to the sum of the absolute terms).
        points: number of random points of the numeric check.
        seed: their seed.
    """

    dim: int
    jacobi_triples: int
    jacobi_symbolic: int
    casimir_identities: int
    casimir_symbolic: int
    residual: float
    tolerance: float
    points: int
    seed: int

    json_keys = ("dim", "method", "jacobi_triples", "jacobi_symbolic", "casimir_identities", "casimir_symbolic",
                 "residual", "tolerance", "points", "seed")

    @property
    def method(self) -> str:
        """"symbolic" when every identity was proved symbolically, else "numeric"."""
        proved = self.jacobi_symbolic + self.casimir_symbolic
        return "symbolic" if proved == self.jacobi_triples + self.casimir_identities else "numeric"


class _Budget:
    """A deadline for the symbolic work (None: no symbolic work at all)."""

    def __init__(self, seconds: float | None):
        self.deadline = None if seconds is None else time.monotonic() + seconds

    def left(self) -> bool:
        return self.deadline is not None and time.monotonic() < self.deadline


def _expanded_terms(expr) -> float:
    """An upper bound on the number of terms of the expansion of `expr` (powers and products
    multiply, sums add; an atom or a function call counts as one)."""
    if expr.is_Add:
        return sum(_expanded_terms(a) for a in expr.args)
    if expr.is_Mul:
        out = 1.0
        for a in expr.args:
            out *= _expanded_terms(a)
        return out
    if expr.is_Pow and expr.exp.is_Integer:
        return _expanded_terms(expr.base) ** abs(int(expr.exp))
    return 1.0


def decide_zero(expr, budget: _Budget | None = None) -> bool | None:
    """True if `expr` is proved identically zero, False if it is proved not to be, None if the
    bounded symbolic effort does not decide (see the module docstring)."""
    import sympy

    if expr == 0:
        return True
    budget = budget or _Budget(SYMBOLIC_SECONDS)
    if not budget.left() or sympy.count_ops(expr) > MAX_OPS:
        return None
    if _expanded_terms(expr) > MAX_EXPANDED_TERMS:
        return None
    numerator, _ = sympy.fraction(sympy.cancel(sympy.together(expr)))
    numerator = sympy.expand(numerator)
    if numerator == 0:
        return True
    generators = numerator.free_symbols
    if numerator.is_polynomial(*generators):
        return False  # a non-zero polynomial in the variables themselves
    if budget.left() and sympy.count_ops(expr) <= MAX_SIMPLIFY_OPS:
        if sympy.simplify(expr) == 0:
            return True
    return None


def _entries(matrix, where: str):
    """The n x n entries as a tuple of tuples of sympy expressions (InputError if not square)."""
    rows = tuple(tuple(row) for row in matrix)
    n = len(rows)
    if n == 0 or any(len(r) != n for r in rows):
        raise InputError(f"{where} must be a square matrix of expressions")
    return rows


def check_antisymmetric_expressions(matrix, where: str = "poisson", budget: _Budget | None = None) -> None:
    """pi_ij + pi_ji = 0 for every i <= j, decided symbolically (numerically at random points for
    an expression the bounded symbolic effort does not decide); InputError naming the first
    failing entry otherwise."""
    rows = _entries(matrix, where)
    n = len(rows)
    budget = budget or _Budget(SYMBOLIC_SECONDS)
    for i in range(n):
        for j in range(i, n):
            total = rows[i][j] + rows[j][i]
            verdict = decide_zero(total, budget)
            if verdict is None:
                verdict = _numeric_zero(total, n)
            if not verdict:
                what = (f"diagonal entry ({i + 1}, {i + 1}) = {rows[i][i]} is not 0" if i == j
                        else f"entries ({i + 1}, {j + 1}) and ({j + 1}, {i + 1}) do not sum to 0: "
                             f"{rows[i][j]} + {rows[j][i]} = {total}")
                raise InputError(f"{where} is not antisymmetric: {what}")


def _numeric_zero(expr, n: int, seed: int = 0) -> bool:
    """An expression without known structure: zero at POINTS standard normal points (relative
    to 1 + the size of its value; used for antisymmetry only)."""
    import sympy

    f = sympy.lambdify(symbols_of(n), expr, "numpy")
    rng = np.random.default_rng(seed)
    with np.errstate(all="ignore"):
        values = [complex(f(*x)) for x in rng.normal(size=(POINTS, n))]
    values = [v for v in values if np.isfinite(v)]
    return bool(values) and all(abs(v) <= TOLERANCE for v in values)


def symbols_of(n: int):
    """The real sympy symbols x1..xn."""
    import sympy

    return tuple(sympy.Symbol(name, real=True) for name in variable_names(n))


def random_points_near(x0, points: int = POINTS, seed: int = 0) -> np.ndarray:
    """Seeded random points near x0: x0_i + max(|x0_i| / 2, 1/4) * N(0, 1) per component
    (the numeric check keeps the points where pi is finite)."""
    x0 = np.asarray(x0, dtype=np.float64)
    rng = np.random.default_rng(seed)
    spread = np.maximum(0.5 * np.abs(x0), 0.25)
    return x0 + spread * rng.normal(size=(points, x0.size))


@dataclass(frozen=True)
class _Numeric:
    """The matrix and its derivatives at the sample points, scaled at each point
    (:func:`_scale_exponents`): pi_ij(x[m]) = P[m, i, j] 2**e[m] and the derivative of pi_jk in
    x_l there dP[m, l, j, k] 2**e[m]."""

    x: np.ndarray
    P: np.ndarray
    dP: np.ndarray
    e: np.ndarray


def _scale_exponents(values: np.ndarray) -> np.ndarray:
    """For finite values with one row per point (the first axis), the exponent e >= 0 of each
    point such that its values divided by 2**e are at most 2**LARGEST_EXPONENT in size."""
    largest = np.abs(values.reshape(values.shape[0], -1)).max(axis=1, initial=0.0)
    return np.maximum(np.frexp(largest)[1] - LARGEST_EXPONENT, 0)


def _scaled_points(values: np.ndarray, e: np.ndarray) -> np.ndarray:
    """Each point's values (the first axis) divided by 2**e of the point."""
    return np.ldexp(values, -e.reshape((-1,) + (1,) * (values.ndim - 1)))


def _unscaled_text(value: float, exponent: int, spec: str) -> str:
    """value * 2**exponent formatted by `spec`, also beyond float64's range (then from its
    decimal value)."""
    try:
        return format(math.ldexp(value, exponent), spec)
    except OverflowError:
        return format(Decimal(value) * Decimal(2) ** exponent, spec)


def _evaluate(rows, symbols, points: np.ndarray, where: str) -> _Numeric:
    """pi and its first derivatives at the points where every entry is finite."""
    import sympy

    n = len(rows)
    nonzero = [(i, j) for i in range(n) for j in range(n) if rows[i][j] != 0]
    derivatives = [(l, i, j) for (i, j) in nonzero for l in range(n)
                   if symbols[l] in rows[i][j].free_symbols]
    exprs = [rows[i][j] for i, j in nonzero] + [sympy.diff(rows[i][j], symbols[l])
                                               for l, i, j in derivatives]
    f = sympy.lambdify(symbols, exprs, "numpy")
    m = points.shape[0]
    with np.errstate(all="ignore"):
        values = [np.broadcast_to(np.asarray(v, dtype=np.complex128), (m,))
                  for v in f(*points.T)] if exprs else []
    P = np.zeros((m, n, n))
    dP = np.zeros((m, n, n, n))
    good = np.ones(m, dtype=bool)
    for v in values:
        good &= np.isfinite(v) & (np.abs(v.imag) <= 1e-300)
    for (i, j), v in zip(nonzero, values, strict=False):
        P[:, i, j] = v.real
    for (l, i, j), v in zip(derivatives, values[len(nonzero):], strict=True):
        dP[:, l, i, j] = v.real
    if not good.any():
        raise InputError(f"{where}: the Poisson matrix is not finite (or not real) at any of "
                         f"{m} random points near x0; cannot check the Jacobi identity")
    P, dP = P[good], dP[good]
    e = np.maximum(_scale_exponents(P), _scale_exponents(dP))
    return _Numeric(points[good], _scaled_points(P, e), _scaled_points(dP, e), e)


def _jacobi_numeric(num: _Numeric):
    """Residuals J[m, i, j, k] and the sums of the absolute values of their terms, both scaled by
    2**(-2 e[m]) (:class:`_Numeric`)."""
    T = np.einsum("mil,mljk->mijk", num.P, num.dP)
    S = np.einsum("mil,mljk->mijk", np.abs(num.P), np.abs(num.dP))
    J = T + T.transpose(0, 2, 3, 1) + T.transpose(0, 3, 1, 2)
    scale = S + S.transpose(0, 2, 3, 1) + S.transpose(0, 3, 1, 2)
    return J, scale


def _relative(residual: np.ndarray, scale: np.ndarray) -> np.ndarray:
    return np.where(scale > 0, np.abs(residual) / np.where(scale > 0, scale, 1.0), 0.0)


def _jacobi_expression(rows, symbols, i: int, j: int, k: int):
    """J_ijk as a sympy sum of its non-zero terms (None when every term vanishes)."""
    import sympy

    terms = []
    for a, b, c in ((i, j, k), (j, k, i), (k, i, j)):
        target = rows[b][c]
        for l, sym in enumerate(symbols):
            if rows[a][l] != 0 and sym in target.free_symbols:
                terms.append(rows[a][l] * sympy.diff(target, sym))
    return sympy.Add(*terms) if terms else None


def _point_text(x: np.ndarray) -> str:
    return "(" + ", ".join(f"{v:.6g}" for v in x) + ")"


def _casimir_numeric(casimir, symbols, num: _Numeric, where: str):
    """{C, x_i} at the points where grad C is finite (m x n) and the sums of the absolute values
    of their terms, both scaled by 2**(-e) at each point, those exponents e, those points, and
    grad C (sympy)."""
    import sympy

    grad = [sympy.diff(casimir, s) for s in symbols]
    f = sympy.lambdify(symbols, grad, "numpy")
    m = num.x.shape[0]
    with np.errstate(all="ignore"):
        g = np.stack([np.broadcast_to(np.asarray(v, dtype=np.float64), (m,))
                      for v in f(*num.x.T)], axis=1)
    good = np.all(np.isfinite(g), axis=1)
    if not good.any():
        raise InputError(f"casimir {casimir} is not finite at any of the {m} random points near "
                         f"x0 where {where} is; cannot check it")
    g, P = g[good], num.P[good]
    eg = _scale_exponents(g)
    g = _scaled_points(g, eg)
    return (np.einsum("ml,mli->mi", g, P), np.einsum("ml,mli->mi", np.abs(g), np.abs(P)),
            eg + num.e[good], num.x[good], grad)


def _abridged(expr, limit: int = 160) -> str:
    text = str(expr)
    return text if len(text) <= limit else text[: limit - 3] + "..."


def check_structure(matrix, *, casimirs=(), x0=None, seed: int = 0, where: str = "poisson",
                    symbolic_seconds: float | None = SYMBOLIC_SECONDS) -> StructureCheck:
    """Check that `matrix` (n x n sympy expressions in x1..xn, real symbols) is a Poisson matrix
    and that every expression of `casimirs` is a Casimir of it (module docstring).

    Numeric points are drawn near `x0` (default: the origin) with `seed`; `symbolic_seconds`
    bounds the symbolic work (None: numeric only). Raises InputError (one line) on failure.
    """
    rows = _entries(matrix, where)
    n = len(rows)
    symbols = symbols_of(n)
    budget = _Budget(symbolic_seconds)
    check_antisymmetric_expressions(rows, where, budget)
    x0 = np.zeros(n) if x0 is None else np.asarray(x0, dtype=np.float64)
    num = _evaluate(rows, symbols, random_points_near(x0, POINTS, seed), where)
    J, scale = _jacobi_numeric(num)
    rel = _relative(J, scale)
    largest = rel.max(axis=0)
    worst = 0.0
    # the numeric residuals of every triple first: a failing one is refused before any
    # symbolic work (whose cost grows like n^3 expressions)
    for i, j, k in combinations(range(n), 3):
        if not largest[i, j, k] > TOLERANCE:
            worst = max(worst, float(largest[i, j, k]))
            continue
        r = rel[:, i, j, k]
        m = int(np.argmax(r))
        if r[m] > TOLERANCE:
            twice = 2 * int(num.e[m])
            raise InputError(
                f"{where} fails the Jacobi identity at (i, j, k) = ({i + 1}, {j + 1}, {k + 1}): "
                f"{{x{i + 1},{{x{j + 1},x{k + 1}}}}} + cyclic = {_unscaled_text(J[m, i, j, k], twice, '.6g')} "
                f"at x = {_point_text(num.x[m])} (terms of size {_unscaled_text(scale[m, i, j, k], twice, '.3g')}; "
                f"tolerance {TOLERANCE:g} relative)")
    triples = [(t, expr) for t in combinations(range(n), 3)
               if (expr := _jacobi_expression(rows, symbols, *t)) is not None]
    proved = 0
    for (i, j, k), expr in triples:
        verdict = decide_zero(expr, budget)
        if verdict is False:
            residual = _abridged(expr)
            raise InputError(
                f"{where} fails the Jacobi identity at (i, j, k) = ({i + 1}, {j + 1}, {k + 1}): "
                f"{{x{i + 1},{{x{j + 1},x{k + 1}}}}} + cyclic = {residual} (exact)")
        proved += verdict is True
    identities, proved_c = 0, 0
    for c_index, casimir in enumerate(casimirs):
        value, size, exponents, points, grad = _casimir_numeric(casimir, symbols, num, where)
        rc = _relative(value, size)
        for i in range(n):
            expr = _casimir_expression(grad, rows, i)
            if expr is None:
                continue
            identities += 1
            m = int(np.argmax(rc[:, i]))
            worst = max(worst, float(rc[m, i]))
            verdict = decide_zero(expr, budget)
            if verdict is None and not rc[m, i] > TOLERANCE:
                continue
            if not verdict:
                e = int(exponents[m])
                shown = (f"{_unscaled_text(value[m, i], e, '.6g')} at x = {_point_text(points[m])} (terms of "
                         f"size {_unscaled_text(size[m, i], e, '.3g')}; tolerance {TOLERANCE:g} relative)"
                         if verdict is None else f"{_abridged(expr)} (exact)")
                raise InputError(f"casimir {c_index + 1} ({_abridged(casimir, 60)}) is not a Casimir of {where}: "
                                 f"{{C, x{i + 1}}} = {shown}")
            proved_c += 1
    return StructureCheck(dim=n, jacobi_triples=len(triples), jacobi_symbolic=proved,
                          casimir_identities=identities, casimir_symbolic=proved_c,
                          residual=worst, tolerance=TOLERANCE, points=int(num.x.shape[0]),
                          seed=seed)


def _casimir_expression(grad, rows, i: int):
    """{C, x_i} = sum_l d_l C pi_li as a sympy sum (None when every term vanishes)."""
    import sympy

    terms = [grad[l] * rows[l][i] for l in range(len(rows)) if grad[l] != 0 and rows[l][i] != 0]
    return sympy.Add(*terms) if terms else None


def check_matrix_finite_at(matrix, x0, where: str = "poisson") -> np.ndarray:
    """pi(x0) as floats; InputError naming the first entry that is not finite there (a pole of
    the structure at the initial point)."""
    import sympy

    rows = _entries(matrix, where)
    n = len(rows)
    x0 = np.asarray(x0, dtype=np.float64)
    f = sympy.lambdify(symbols_of(n), [e for row in rows for e in row], "numpy")
    with np.errstate(all="ignore"):
        values = [complex(np.asarray(v, dtype=np.complex128)) for v in f(*x0)]
    for q, v in enumerate(values):
        if not (np.isfinite(v) and v.imag == 0.0):
            i, j = divmod(q, n)
            raise InputError(f"{where} is singular at x0 = {_point_text(x0)}: entry ({i + 1}, {j + 1}) "
                             f"= {rows[i][j]} is not finite (or not real) there")
    return np.array([v.real for v in values]).reshape(n, n)


def lie_poisson_matrix(structure) -> tuple[tuple, ...]:
    """pi_ij = sum_k C[i, j, k] x_k as sympy expressions (C as floats; exact where they are
    integers or short decimals), for checking the Lie–Poisson family."""
    import sympy

    C = np.asarray(structure, dtype=np.float64)
    x = symbols_of(C.shape[0])
    return tuple(tuple(sympy.Add(*[sympy.nsimplify(C[i, j, k]) * x[k] for k in range(len(x))
                                   if C[i, j, k] != 0.0]) for j in range(len(x)))
                 for i in range(len(x)))


def log_canonical_matrix(lam) -> tuple[tuple, ...]:
    """pi_ij = lambda_ij x_i x_j as sympy expressions, for checking the log-canonical family."""
    import sympy

    L = np.asarray(lam, dtype=np.float64)
    x = symbols_of(L.shape[0])
    return tuple(tuple(sympy.nsimplify(L[i, j]) * x[i] * x[j] for j in range(len(x)))
                 for i in range(len(x)))
