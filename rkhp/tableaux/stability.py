"""Linear stability and phase of RKHP methods (docs/theory.md §13, docs/stability.md).

On the harmonic oscillator pi = [[0, 1], [-1, 0]], H = (x1^2 + x2^2)/2 (any constant-pi system with
a quadratic Hamiltonian is a sum of such oscillators after a linear symplectic change of variables),
z = h omega, with the symmetric birealisation alpha, beta = x -/+ pi p/2, every stage of the RKHP
step (paper §5.2) is a multiple of x: Z_i(x) = m_i x with

    m_i = z sum_j a_ij (1 + m_j^2/4),        m = z sum_i b_i (1 + m_i^2/4),

and the step is the Cayley transform (I + m J/2)(I - m J/2)^-1: an exact rotation by
theta(z) = 2 arctan(m(z)/2). The exact flow has m = 2 tan(z/2). Amplitude is exact for every z; what
a method changes is the phase theta(z) - z (its order p and leading constant), where theta stops
growing with z (the wrap limit), and for an implicit tableau whether the stage equations have a
solution at all (the existence limit z*, a fold of the branch through m(0) = 0).

With the ``shifted`` realisation (alpha, beta = x + Q p -/+ pi p/2, Q symmetric) the stages are
symmetric matrices M_i = z sum_j a_ij (I + D M_j)^T (I + D M_j), D = Q - pi/2, the step matrix is
R = (I + D' P)(I + D P)^-1 (D' = Q + pi/2, P the same sum with b), and the trace of R decides: |tr R| < 2 is an elliptic
(bounded) step, a rotation by arccos(tr R / 2) in a skew frame; |tr R| > 2 is hyperbolic. tr R depends
on delta = det(P^-1 + Q) alone (elliptic iff delta > 0), explicit and implicit stages alike; an implicit
tableau's matrix stages are followed from M = 0 to their fold (`shifted_branch`).

Everything here is exact (sympy, in the number field of the tableau's entries) where the tableau is
exact; a tableau given by decimals is read at its digits and its values have no exact text.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from fractions import Fraction

import mpmath
import sympy
from sympy.polys.constructor import construct_domain

from ..base.errors import InputError, NumericalFailure
from ..base.expressions import parse_expression
from .tableau import Tableau, as_sympy, is_exact, to_fraction

Z = sympy.Symbol("z")
#: the explicit m(z) is written out exactly up to this many stages (its degree is 2^s - 1)
MAX_POLYNOMIAL_STAGES = 8
#: largest order of the series of theta(z) - z
MAX_SERIES_ORDER = 41
#: the phase order is looked for up to this power of z (beyond the series order asked for)
PHASE_SEARCH_ORDER = 25
#: stage equations are eliminated exactly (Groebner bases) up to this many stages
MAX_ELIMINATION_STAGES = 2
#: the continuation of an implicit branch stops beyond this z (the branch then exists up to it)
MAX_CONTINUATION_Z = 64.0
#: working digits of the numerical continuation and root refinement
DIGITS = 40
#: the shifted realisation's Q (docs/theory.md §4; `rkhp.systems.core.shift_matrix` for n = 2)
SHIFT_Q = sympy.Matrix([[sympy.Rational(1, 2), sympy.Rational(1, 4)],
                        [sympy.Rational(1, 4), sympy.Rational(1, 2)]])
#: one implicit stage, shifted realisation: M = c G(M) depends on c = z a_11 alone, and its branch
#: through M = 0 folds at c = 1/3, a root of the eliminant (c - 1)(3c - 1)(4c^2 + 8c - 3) of the
#: stage equations and det J = 0 (lex Groebner basis; docs/stability.md), so z* = 1/(3 a_11)
ONE_STAGE_SHIFTED_FOLD = sympy.Rational(1, 3)
#: the oscillator's Poisson matrix, dynamics xdot = J grad H
J = sympy.Matrix([[0, 1], [-1, 0]])
REALISATIONS = ("symmetric", "shifted")


@dataclass(frozen=True)
class Number:
    """A real number: its exact text (sympy's, None where only a value is known) and its value."""

    exact: str | None
    value: float

    def json(self) -> dict:
        """``{"exact": ..., "float": ...}``; an unbounded limit is ``{"exact": "oo", "float": null}``."""
        return {"exact": self.exact, "float": self.value if math.isfinite(self.value) else None}


#: the stability interval of a step that is elliptic for every z > 0
UNBOUNDED = Number("oo", math.inf)


@dataclass(frozen=True)
class Field:
    """The number field K of a tableau's entries (sympy domain QQ or QQ<alpha>), the entries as
    elements of K, and whether they are exact (False: decimals read at their digits)."""

    K: object
    A: tuple
    b: tuple
    exact: bool
    digits: int | None

    def is_zero(self, x) -> bool:
        """Whether a value of K is zero: exactly, or at the tableau's digits (10^(3-D))."""
        if self.exact:
            return not x
        return abs(float(self.K.to_sympy(x))) <= 10.0 ** (3 - self.digits)

    def text(self, x) -> str | None:
        return exact_text(self.K.to_sympy(x)) if self.exact else None

    def number(self, x) -> Number:
        return Number(self.text(x), float(self.K.to_sympy(x).evalf(30)))


def exact_text(expr) -> str:
    """A sympy number or expression as text (``^`` for powers, as rkhp writes formulas)."""
    return str(expr).replace("**", "^")


def exact_number(g):
    """A number given from Python as a sympy number: sympy numbers as they are, Fractions and
    integers exactly, floats by nsimplify; text and anything else refused (InputError: text goes
    through the safe expression reader of tableau files, never through sympify)."""
    if isinstance(g, sympy.Basic):
        return g
    if isinstance(g, bool) or not isinstance(g, (int, float, Fraction)):
        raise InputError(f"expected a number, got {type(g).__name__}")
    if isinstance(g, float):
        return sympy.nsimplify(g)
    return sympy.Rational(g.numerator, g.denominator) if isinstance(g, Fraction) else sympy.Integer(g)


def tableau_field(tableau: Tableau, extra=()) -> Field:
    """The field of the entries of A and b (and of `extra` sympy numbers, e.g. composition
    coefficients): decimals known to D digits enter as the rationals they spell."""
    values = [as_sympy(x) if is_exact(x) else sympy.Rational(*_pair(to_fraction(x, 0)))
              for x in tableau.entries()]
    values += [exact_number(g) for g in extra]
    K, elements = construct_domain(values, extension=True)
    K, elements = K.get_field(), [K.get_field().convert_from(e, K) for e in elements]
    s = tableau.stages
    A = tuple(tuple(elements[i * s + j] for j in range(s)) for i in range(s))
    b = tuple(elements[s * s: s * s + s])
    return Field(K, A, b, tableau.is_exact, tableau.digits)


def _pair(q: Fraction) -> tuple[int, int]:
    return q.numerator, q.denominator


# ----------------------------------------------------------------------------- truncated series


def _mul(K, u, v, n):
    """Product of two series (lists of K elements, index = power of z) truncated after z^n."""
    out = [K.zero] * (n + 1)
    for i, ui in enumerate(u[: n + 1]):
        if not ui:
            continue
        for j, vj in enumerate(v[: n + 1 - i]):
            if vj:
                out[i + j] += ui * vj
    return out


def _add(K, u, v, n):
    u = list(u) + [K.zero] * (n + 1 - len(u))
    v = list(v) + [K.zero] * (n + 1 - len(v))
    return [x + y for x, y in zip(u[: n + 1], v[: n + 1], strict=True)]


def _scale(c, u):
    return [c * x for x in u]


def _shift(K, u, n):
    """z u(z), truncated after z^n."""
    return ([K.zero] + list(u))[: n + 1]


def _stage_map(F: Field, ms, n):
    """One application of m_i <- z sum_j a_ij (1 + m_j^2/4) to series ms (truncated after z^n)."""
    K = F.K
    quarter = K.one / K.convert(4)
    w = [_add(K, [K.one], _scale(quarter, _mul(K, m, m, n)), n) for m in ms]
    out = []
    for row in F.A:
        acc = [K.zero] * (n + 1)
        for a, wj in zip(row, w, strict=True):
            if a:
                acc = _add(K, acc, _scale(a, wj), n)
        out.append(_shift(K, acc, n))
    total = [K.zero] * (n + 1)
    for bi, wi in zip(F.b, w, strict=True):
        if bi:
            total = _add(K, total, _scale(bi, wi), n)
    return out, _shift(K, total, n)


def m_series(F: Field, n: int) -> list:
    """The series of m(z) to z^n on the branch through m(0) = 0 (explicit or implicit): each
    application of the stage map gains one power of z, so n + 1 applications from 0 suffice."""
    K = F.K
    ms = [[K.zero] * (n + 1) for _ in F.b]
    m = [K.zero] * (n + 1)
    for _ in range(n + 2):
        ms, m = _stage_map(F, ms, n)
    return m


def theta_minus_z(K, m, n: int) -> list:
    """Series of 2 arctan(m/2) - z to z^n, m = O(z) (arctan u = sum (-1)^k u^(2k+1)/(2k+1))."""
    half = K.one / K.convert(2)
    u = _scale(half, m)
    u2 = _mul(K, u, u, n)
    power = u
    total = [K.zero] * (n + 1)
    k = 0
    while any(power):
        coef = K.convert(2 * (-1) ** k) / K.convert(2 * k + 1)
        total = _add(K, total, _scale(coef, power), n)
        power = _mul(K, power, u2, n)
        k += 1
    if n >= 1:
        total[1] -= K.one
    return total


# ----------------------------------------------------------------------------- phase


@dataclass(frozen=True)
class Phase:
    """theta(z) - z to z^order (coefficients by power), the phase order p (theta - z = O(z^(p+1)),
    None when no power up to `searched` has a non-zero coefficient) and its leading constant."""

    order: int
    coefficients: tuple[tuple[int, Number], ...]
    phase_order: int | None
    phase_constant: Number | None
    searched: int

    def series_text(self) -> str | None:
        """``-z^5/1920 + ...`` (exact), None for a tableau known to its digits only."""
        terms = [(k, c) for k, c in self.coefficients if c.exact is not None and c.exact != "0"]
        if any(c.exact is None for _, c in self.coefficients):
            return None
        return polynomial_text([(k, parse_expression(c.exact, where="phase coefficient")) for k, c in terms])


def polynomial_text(terms) -> str:
    """sum c_k z^k in increasing powers (``z + z^3/12 + 3*z^7/16384``), ``0`` for none."""
    expr = sum((c * Z**k for k, c in terms), sympy.Integer(0))
    if expr == 0:
        return "0"
    text = sympy.sstr(expr, order="rev-lex")
    return text.replace("**", "^")


def _phase(F: Field, series_of, order: int) -> Phase:
    """The Phase from `series_of(n)` (theta - z to z^n), growing n until a non-zero coefficient
    shows (at most PHASE_SEARCH_ORDER)."""
    n = order
    K0 = F.K.zero
    series = series_of(n)
    while True:
        nonzero = [k for k in range(n + 1) if not F.is_zero(series[k])]
        if nonzero or n >= max(PHASE_SEARCH_ORDER, order):
            break
        n = min(n + 8, max(PHASE_SEARCH_ORDER, order))
        series = series_of(n)
    coefficients = tuple((k, F.number(series[k]) if not F.is_zero(series[k]) else Number(F.text(K0), 0.0))
                         for k in range(1, order + 1))
    if not nonzero:
        return Phase(order, coefficients, None, None, n)
    k = nonzero[0]
    return Phase(order, coefficients, k - 1, F.number(series[k]), n)


def phase(tableau: Tableau, order: int = 9) -> Phase:
    """Phase of an RKHP tableau on the oscillator with the symmetric realisation: theta(z) - z to
    z^order, the phase order and constant (docs/theory.md §13)."""
    _check_order(order)
    F = tableau_field(tableau)
    return _phase(F, lambda n: theta_minus_z(F.K, m_series(F, n), n), order)


def composition_phase(tableau: Tableau, gammas, order: int = 9) -> Phase:
    """Phase of the composition of the RKHP step of `tableau` with substeps gamma_1 h, ...,
    gamma_s h (sympy numbers): the substeps are rotations about the same centre, so
    theta(z) = sum_i theta_base(gamma_i z) and the coefficient of z^k is theta_base's times
    sum_i gamma_i^k (docs/stability.md, "Compositions")."""
    _check_order(order)
    gammas = [exact_number(g) for g in gammas]
    if not gammas:
        raise InputError("a composition needs at least one substep")
    for g in gammas:
        if not (g.is_number and g.is_real and g.is_algebraic):
            raise InputError(f"substep coefficient {g}: not a real algebraic number")
    F = tableau_field(tableau, gammas)
    K = F.K
    G = [K.from_sympy(g) for g in gammas]

    def series_of(n):
        base = theta_minus_z(K, m_series(F, n), n)
        base[1] += K.one  # theta_base itself
        out = [K.zero] * (n + 1)
        for k in range(1, n + 1):
            if base[k]:
                out[k] = base[k] * sum((g**k for g in G), K.zero)
        out[1] -= K.one
        return out

    return _phase(F, series_of, order)


def _check_order(order: int) -> None:
    if not 1 <= order <= MAX_SERIES_ORDER:
        raise InputError(f"the order of the phase series must be from 1 to {MAX_SERIES_ORDER}, got {order}")


# ----------------------------------------------------------------------------- explicit m(z)


def m_polynomial(tableau: Tableau):
    """m(z) of an explicit tableau exactly (a sympy polynomial in z, degree at most 2^s - 1), or
    None for more than MAX_POLYNOMIAL_STAGES stages or a tableau known to its digits only."""
    if not tableau.is_explicit:
        raise InputError(f"{tableau.name} is {tableau.kind}: m(z) is a root of the stage equations")
    if tableau.stages > MAX_POLYNOMIAL_STAGES or not tableau.is_exact:
        return None
    F = tableau_field(tableau)
    K = F.K

    def const(x):
        return sympy.Poly.from_list([x], Z, domain=K)

    one, quarter, z = const(K.one), const(K.one / K.convert(4)), sympy.Poly(Z, Z, domain=K)
    ws = []
    for i in range(tableau.stages):
        mi = const(K.zero)
        for j in range(i):
            if F.A[i][j]:
                mi += ws[j] * const(F.A[i][j])
        mi = mi * z
        ws.append(one + mi * mi * quarter)
    m = const(K.zero)
    for bi, wi in zip(F.b, ws, strict=True):
        if bi:
            m += wi * const(bi)
    return m * sympy.Poly(Z, Z, domain=K)


def poly_text(p) -> str:
    """A polynomial in z in increasing powers."""
    return polynomial_text([(k[0], sympy.radsimp(c)) for k, c in zip(p.monoms(), p.coeffs(), strict=True)])


# ----------------------------------------------------------------------------- exact roots


def _norm_over_q(expr, K):
    """A polynomial over QQ in z vanishing wherever the K-polynomial `expr` (in z) does: its norm
    (the resultant with the generator's minimal polynomial); `expr` itself over QQ."""
    if K == sympy.QQ:
        return sympy.Poly(expr, Z, domain=sympy.QQ)
    r = sympy.Dummy("r")
    generic = _in_generator(expr, K, r)
    minpoly = sympy.Poly(K.mod.to_list(), r)
    return sympy.Poly(sympy.resultant(generic, minpoly.as_expr(), r), Z, domain=sympy.QQ)


def _in_generator(expr, K, r):
    """`expr` (polynomial in z with coefficients in K) with K's generator written as the symbol r."""
    poly = sympy.Poly(expr, Z, domain=K)
    out = sympy.Integer(0)
    for (k,), c in zip(poly.monoms(), poly.rep.coeffs(), strict=True):
        coeffs = c.to_list()
        value = sum(sympy.Rational(int(q.numerator), int(q.denominator)) * r**(len(coeffs) - 1 - i)
                    for i, q in enumerate(coeffs))
        out += value * Z**k
    return sympy.expand(out)


def exact_root(poly_q, value) -> str | None:
    """The exact text of the real root of `poly_q` (over QQ, in z) nearest `value` (an mpf):
    radicals up to degree 2, else ``CRootOf(...)``; None if no root matches to 20 digits."""
    with mpmath.workdps(DIGITS):
        value = mpmath.mpf(value)
        for factor, _ in sympy.factor_list(poly_q.as_expr(), Z)[1]:
            f = sympy.Poly(factor, Z)
            if f.degree() < 1:
                continue
            for index, (low, high) in enumerate(iv for iv, _ in f.intervals()):
                if not low - 1 <= value <= high + 1:
                    continue
                root = _refine(f, low, high)
                if abs(root - value) > mpmath.mpf(10) ** -20 * (1 + abs(value)):
                    continue
                if f.degree() <= 2:
                    candidates = [x for x in sympy.solve(f.as_expr(), Z) if x.is_real]
                    best = min(candidates, key=lambda x: abs(mpmath.mpf(str(x.evalf(DIGITS))) - value))
                    return exact_text(sympy.radsimp(best))
                return exact_text(sympy.CRootOf(f.as_expr(), index))
    return None


def _refine(f, low, high) -> mpmath.mpf:
    """A real root of f isolated in [low, high], to DIGITS digits (exact rational refinement)."""
    eps = sympy.Rational(1, 10 ** (DIGITS + 5))
    a, b = f.refine_root(low, high, eps=eps) if low != high else (low, high)
    return (mpmath.mpf(int(a.p)) / int(a.q) + mpmath.mpf(int(b.p)) / int(b.q)) / 2


def first_positive_root(expr, K) -> Number | None:
    """The smallest positive real root of a polynomial in z with coefficients in K, exactly: the
    positive roots of its norm over QQ are isolated exactly (sympy's real-root isolation) and the
    first one where the polynomial itself vanishes is taken; None when there is none."""
    poly = sympy.Poly(expr, Z, domain=K)
    if poly.degree() < 1:
        return None
    q = _norm_over_q(poly.as_expr(), K).sqf_part()
    with mpmath.workdps(DIGITS):
        for (low, high), _ in sorted(q.intervals(), key=lambda iv: iv[0][0]):
            if high <= 0:
                continue
            root = _refine(q, low, high)
            if root <= 0 or not _vanishes(poly, K, root):
                continue
            return Number(exact_root(q, root), float(root))
    return None


def _vanishes(poly, K, root) -> bool:
    """Whether a K-polynomial vanishes at `root` (relative to its coefficients' size there)."""
    coeffs = [mpmath.mpf(str(sympy.N(K.to_sympy(c), DIGITS))) for c in poly.rep.to_list()]
    value = mpmath.polyval(coeffs, root)
    scale = sum(abs(c) * abs(root) ** k for k, c in enumerate(reversed(coeffs)))
    return abs(value) <= mpmath.mpf(10) ** (10 - DIGITS) * scale


# ----------------------------------------------------------------------------- explicit limits


def wrap_limit_explicit(m) -> Number | None:
    """The largest z0 with theta = 2 arctan(m/2) strictly increasing on [0, z0]: the first positive
    root of odd multiplicity of m'(z); None when m increases on all of (0, oo) (theta then tends to
    +-pi without reaching it)."""
    K = m.get_domain()
    dm = m.diff(Z)
    sqf = sympy.Poly(dm.as_expr(), Z, domain=K).sqf_list()[1]
    odd = sympy.Poly(1, Z, domain=K)
    for factor, multiplicity in sqf:
        if multiplicity % 2:
            odd *= factor
    return first_positive_root(odd.as_expr(), K)


#: the numerical wrap limit (tableaux without an exact m(z)) is looked for on (0, WRAP_SCAN_Z]
WRAP_SCAN_Z = 20.0


def wrap_limit_numeric(tableau: Tableau) -> Number | None:
    """The wrap limit of an explicit tableau without an exact m(z) (more than MAX_POLYNOMIAL_STAGES
    stages, or decimals): the first z on a grid of step 10^-3 over (0, WRAP_SCAN_Z] where
    theta(z) = 2 arctan(m(z)/2) (float64) stops increasing, refined by bisection; None when theta
    increases over the whole scan."""
    import numpy as np

    zs = np.arange(1, int(WRAP_SCAN_Z * 1000) + 1) / 1000.0
    with np.errstate(all="ignore"):
        theta = np.array(rotation_angles(tableau, [float(z) for z in zs]))
    falls = np.nonzero(np.diff(theta) < -1e-10)[0]  # a fall beyond round-off near theta = pi
    if not len(falls):
        return None
    lo, hi = float(zs[max(falls[0] - 1, 0)]), float(zs[falls[0] + 1])

    def slope(z):
        return rotation_angle(tableau, z + 1e-7) - rotation_angle(tableau, z - 1e-7)

    for _ in range(60):
        mid = (lo + hi) / 2
        lo, hi = (mid, hi) if slope(mid) > 0 else (lo, mid)
    return Number(None, (lo + hi) / 2)


# ----------------------------------------------------------------------------- implicit branch


@dataclass(frozen=True)
class Branch:
    """The branch through m(0) = 0 of an implicit tableau's stage equations: the existence limit
    z* (a fold, where the Jacobian I - z A diag(m/2) is singular; None when the branch goes on past
    MAX_CONTINUATION_Z), the wrap limit (where m'(z) first vanishes or m escapes to infinity), and
    the equations as text."""

    equations: tuple[str, ...]
    existence_limit: Number | None
    wrap_limit: Number | None


def stage_equations(tableau: Tableau) -> tuple[str, ...]:
    """``m_i = z (a_i1 (1 + m_1^2/4) + ...)`` for each stage, then ``m = z (...)``."""
    F = tableau_field(tableau)
    ms = sympy.symbols(f"m1:{tableau.stages + 1}")
    w = [1 + mj**2 / 4 for mj in ms]
    out = []
    for i, row in enumerate(F.A):
        rhs = sum((F.K.to_sympy(a) * wj for a, wj in zip(row, w, strict=True) if a), sympy.Integer(0))
        out.append(f"m{i + 1} = z*({exact_text(rhs)})")
    total = sum((F.K.to_sympy(bi) * wi for bi, wi in zip(F.b, w, strict=True) if bi), sympy.Integer(0))
    out.append(f"m = z*({exact_text(total)})")
    return tuple(out)


def _mp_tableau(tableau: Tableau):
    with mpmath.workdps(DIGITS):
        A = mpmath.matrix([[mpmath.mpf(to_fraction(x, 4 * DIGITS).numerator) / to_fraction(x, 4 * DIGITS).denominator
                            for x in row] for row in tableau.A])
        b = [mpmath.mpf(to_fraction(x, 4 * DIGITS).numerator) / to_fraction(x, 4 * DIGITS).denominator
             for x in tableau.b]
    return A, b


def _residual(A, m, z):
    s = len(m)
    return mpmath.matrix([m[i] - z * sum(A[i, j] * (1 + m[j] ** 2 / 4) for j in range(s)) for i in range(s)])


def _jacobian(A, m, z):
    s = len(m)
    return mpmath.matrix([[(1 if i == j else 0) - z * A[i, j] * m[j] / 2 for j in range(s)] for i in range(s)])


def _det(M):
    """det M by elimination with partial pivoting (0 for a singular M)."""
    M = M.copy()
    n, det = M.rows, mpmath.mpf(1)
    for k in range(n):
        p = max(range(k, n), key=lambda i: abs(M[i, k]))
        if M[p, k] == 0:
            return mpmath.mpf(0)
        if p != k:
            for j in range(n):
                M[k, j], M[p, j] = M[p, j], M[k, j]
            det = -det
        det *= M[k, k]
        for i in range(k + 1, n):
            f = M[i, k] / M[k, k]
            for j in range(k, n):
                M[i, j] -= f * M[k, j]
    return det


def _solve_at(A, m, z, iterations=60):
    """Newton on the stage equations at fixed z from m; None when it does not converge."""
    m = mpmath.matrix(m)
    for _ in range(iterations):
        r = _residual(A, m, z)
        try:
            dm = mpmath.lu_solve(_jacobian(A, m, z), r)
        except ZeroDivisionError:
            return None
        m = m - dm
        if mpmath.norm(dm) <= mpmath.mpf(10) ** (5 - DIGITS) * (1 + mpmath.norm(m)):
            return m
    return None


def _dm_dz(A, b, m, z):
    """d m/dz along the branch: dm_i/dz from J dm = A w, then the total."""
    s = len(m)
    w = mpmath.matrix([1 + m[j] ** 2 / 4 for j in range(s)])
    dms = mpmath.lu_solve(_jacobian(A, m, z), A * w)
    return sum(b[i] * (w[i] + z * m[i] * dms[i] / 2) for i in range(s))


def branch_point(A, z_target, start=None):
    """The point m(z_target) of the branch through m(0) = 0 (predictor along the tangent, Newton
    corrector, step halved where the corrector fails or jumps), continued from ``start`` (a point
    (m, z) of the branch with z <= z_target; default (0, 0)); None where the branch has ended
    (past its fold) before z_target, or z_target is within about 1e-8 of the fold. Call under
    mpmath.workdps(DIGITS)."""
    s = A.rows
    m, z = start if start is not None else (mpmath.matrix([0] * s), mpmath.mpf(0))
    dz = min(mpmath.mpf(1) / 16, z_target - z) if z_target > z else mpmath.mpf(0)
    while z < z_target:
        dz = min(dz, z_target - z)
        predicted = m + dz * _tangent(A, m, z)
        trial = _solve_at(A, predicted, z + dz, iterations=12)
        if trial is None or mpmath.norm(trial - predicted) > dz * (1 + mpmath.norm(m)) \
                or abs(_det(_jacobian(A, trial, z + dz))) < mpmath.mpf(10) ** -4:
            if dz < mpmath.mpf(10) ** -9 * (1 + z_target):
                return None  # within about 1e-8 of the fold (det J ~ sqrt(z* - z)): the branch ends
            dz /= 2
            continue
        m, z = trial, z + dz
        dz *= 2
    return m


def implicit_branch(tableau: Tableau) -> Branch:
    """Follow the branch through m(0) = 0 in z (Newton continuation, DIGITS digits) up to its fold
    z*, refine the fold (F = 0, det J = 0) and write it exactly where the elimination is in reach
    (Groebner basis, at most MAX_ELIMINATION_STAGES stages; docs/stability.md)."""
    equations = stage_equations(tableau)
    with mpmath.workdps(DIGITS):
        A, b = _mp_tableau(tableau)
        s = tableau.stages
        m = mpmath.matrix([0] * s)
        z = mpmath.mpf(0)
        dz = mpmath.mpf(1) / 16
        last_slope = _dm_dz(A, b, m, z)
        wrap = None
        while z < MAX_CONTINUATION_Z:
            trial = _solve_at(A, m + dz * _tangent(A, m, z), z + dz, iterations=12)
            if trial is None or mpmath.norm(trial - m) > 4 * dz * (1 + mpmath.norm(m)) \
                    or abs(_det(_jacobian(A, trial, z + dz))) < mpmath.mpf(10) ** -12:
                if dz < mpmath.mpf(10) ** -25:
                    break
                dz /= 4
                continue
            m, z = trial, z + dz
            slope = _dm_dz(A, b, m, z)
            if wrap is None and slope * last_slope < 0:
                wrap = _refine_wrap(A, b, m, z - dz, z)
            last_slope = slope
            if mpmath.norm(m) > 10**8:
                wrap = wrap or Number(None, float(z))
                return Branch(equations, None, wrap)
            dz = min(dz * 2, mpmath.mpf(1) / 4)
        if z >= MAX_CONTINUATION_Z:
            return Branch(equations, None, wrap)
        zf = _refine_fold(A, m, z)
    text = _exact_fold(tableau, zf) if s <= MAX_ELIMINATION_STAGES and tableau.is_exact else None
    return Branch(equations, Number(text, float(zf)), wrap)


def _tangent(A, m, z):
    s = len(m)
    w = mpmath.matrix([1 + m[j] ** 2 / 4 for j in range(s)])
    return mpmath.lu_solve(_jacobian(A, m, z), A * w)


def _refine_fold(A, m, z):
    """Newton on (F(m, z) = 0, det(I - z A diag(m/2)) = 0) from a point just before the fold."""
    s = len(m)

    def equations(*u):
        mm, zz = mpmath.matrix(u[:s]), u[s]
        r = _residual(A, mm, zz)
        return [r[i] for i in range(s)] + [_det(_jacobian(A, mm, zz))]

    try:
        root = mpmath.findroot(equations, [m[i] for i in range(s)] + [z], tol=mpmath.mpf(10) ** (10 - 2 * DIGITS),
                               maxsteps=200)
    except (ValueError, ZeroDivisionError) as exc:
        raise NumericalFailure(f"the fold of the stage equations near z = {float(z):.6g} did not converge: "
                               f"{exc}") from None
    return root[s]


def _refine_wrap(A, b, m, z0, z1) -> Number:
    """Bisection in z for dm/dz = 0 between z0 and z1 (the branch solved at each z)."""
    lo, hi = z0, z1
    m_lo = _solve_at(A, m, lo)
    s_lo = _dm_dz(A, b, m_lo, lo)
    for _ in range(120):
        mid = (lo + hi) / 2
        mm = _solve_at(A, m_lo, mid)
        if _dm_dz(A, b, mm, mid) * s_lo > 0:
            lo, m_lo = mid, mm
        else:
            hi = mid
    return Number(None, float((lo + hi) / 2))


def _exact_fold(tableau: Tableau, z_fold) -> str | None:
    """The fold written exactly: eliminate m_1..m_s from the stage equations and det J = 0
    (lex Groebner basis over QQ, the entries' field generator as one more unknown), then the root
    of the eliminant at z_fold."""
    F = tableau_field(tableau)
    K = F.K
    s = tableau.stages
    ms = sympy.symbols(f"m1:{s + 1}")
    r = sympy.Dummy("r")

    def entry(x):
        if K == sympy.QQ:
            return K.to_sympy(x)
        coeffs = x.to_list()
        return sum(sympy.Rational(int(q.numerator), int(q.denominator)) * r**(len(coeffs) - 1 - i)
                   for i, q in enumerate(coeffs))

    Ar = sympy.Matrix(s, s, lambda i, j: entry(F.A[i][j]))
    eqs = [ms[i] - Z * sum(Ar[i, j] * (1 + ms[j] ** 2 / 4) for j in range(s)) for i in range(s)]
    jac = sympy.Matrix(s, s, lambda i, j: sympy.diff(eqs[i], ms[j]))
    polys = [sympy.expand(e * 4) for e in eqs] + [sympy.expand(jac.det() * 2**s)]
    gens = list(ms)
    if K != sympy.QQ:
        polys.append(sympy.Poly(K.mod.to_list(), r).as_expr())
        gens.append(r)
    basis = sympy.groebner(polys, *gens, Z, order="lex")
    univariate = [g for g in basis.exprs if g.free_symbols <= {Z}]
    if not univariate:
        return None
    return exact_root(sympy.Poly(univariate[-1], Z, domain=sympy.QQ), z_fold)


# ----------------------------------------------------------------------------- shifted realisation


def shifted_trace(tableau: Tableau):
    """tr R(z) of the explicit RKHP step on the unit oscillator with the shifted realisation
    (alpha, beta = x + Q p -/+ J p/2, Q = SHIFT_Q): a rational function of z, exactly.

    Stages Z_i(x) = M_i x, M_i = z sum_j a_ij (I + D M_j)^T (I + D M_j), D = Q - J/2; psi = P x with P
    the same sum with b; alpha(x, psi) = y gives x = (I + D P)^-1 y and the step is
    R = (I + D' P)(I + D P)^-1, D' = Q + J/2 (paper §5.2, docs/stability.md). An implicit tableau
    has no rational tr R: `shifted_trace_series` and `shifted_branch`."""
    if not tableau.is_explicit:
        raise InputError(f"{tableau.name} is {tableau.kind}: tr R(z) is a rational function for explicit "
                         "tableaux only")
    F = tableau_field(tableau)
    K = F.K
    D, Dp = SHIFT_Q - J / 2, SHIFT_Q + J / 2
    eye = sympy.eye(2)
    grads = []
    for i in range(tableau.stages):
        Mi = sympy.zeros(2, 2)
        for j in range(i):
            if F.A[i][j]:
                Mi += K.to_sympy(F.A[i][j]) * grads[j]
        Mi = (Z * Mi).applyfunc(sympy.expand)
        G = (eye + D * Mi).T * (eye + D * Mi)
        grads.append(G.applyfunc(sympy.expand))
    P = sympy.zeros(2, 2)
    for bi, G in zip(F.b, grads, strict=True):
        if bi:
            P += K.to_sympy(bi) * G
    P = (Z * P).applyfunc(sympy.expand)
    left, right = eye + Dp * P, eye + D * P
    # R = left right^-1: tr R = tr(left adj(right)) / det(right)
    num = sympy.expand((left * right.adjugate()).trace())
    den = sympy.expand(right.det())
    return sympy.cancel(num / den)


def stability_interval(trace, K) -> Number | None:
    """The largest z0 with an elliptic step (|tr R| < 2) on (0, z0): the first positive root of
    the numerator of tr^2 - 4, or of the denominator (where the step stops being defined);
    UNBOUNDED when there is none. K: the field of the tableau's entries.

    With P = z sum_i b_i G_i invertible, R = (S + J/2)(S - J/2)^-1, S = P^-1 + Q: when S is positive
    definite (P and Q positive definite: positive weights and rkhp's SHIFT_Q) R is similar to a
    Cayley transform of an antisymmetric matrix, a rotation: the interval is then unbounded
    (docs/stability.md)."""
    num, den = sympy.fraction(sympy.together(trace))
    num, den = sympy.Poly(num, Z, domain=K), sympy.Poly(den, Z, domain=K)
    f = num**2 - den**2 * 4
    f = sympy.Poly(sympy.cancel(f.as_expr() / Z ** _zero_multiplicity(f)), Z, domain=K)
    roots = [r for r in (first_positive_root(f.as_expr(), K), first_positive_root(den.as_expr(), K))
             if r is not None]
    return min(roots, key=lambda r: r.value) if roots else UNBOUNDED


def _zero_multiplicity(p) -> int:
    coeffs = p.all_coeffs()[::-1]
    k = 0
    while k < len(coeffs) and not coeffs[k]:
        k += 1
    return k


def trace_phase(F: Field, trace, order: int) -> Phase:
    """The rotation number of an elliptic step, theta = arccos(tr R/2), as a series: theta - z to
    z^order, tr R(z) a rational function (explicit tableaux)."""
    K = F.K
    num, den = sympy.fraction(sympy.together(trace))
    num = [K.from_sympy(c) for c in sympy.Poly(num, Z, domain=K).all_coeffs()[::-1]]
    den = [K.from_sympy(c) for c in sympy.Poly(den, Z, domain=K).all_coeffs()[::-1]]
    return _phase(F, lambda n: _theta_of_trace(K, _divide(K, num, den, n + 2), n), order)


def _theta_of_trace(K, tr, n):
    """theta - z to z^n from the series of tr R to z^(n+2): theta = arccos(tr/2) = 2 arcsin(z sqrt(v))
    with (2 - tr)/4 = z^2 v(z)."""
    u = [-x / K.convert(4) for x in tr]
    u[0] += K.one / K.convert(2)
    if u[0] or u[1]:
        raise NumericalFailure("tr R(z) is not 2 - O(z^2): the step is not consistent")
    v = u[2:] + [K.zero, K.zero]
    w = _shift(K, _sqrt(K, v, n), n)
    w2 = _mul(K, w, w, n)
    total, power, k = [K.zero] * (n + 1), w, 0
    while any(power):
        coef = K.convert(2 * math.comb(2 * k, k)) / K.convert(4**k * (2 * k + 1))
        total = _add(K, total, _scale(coef, power), n)
        power = _mul(K, power, w2, n)
        k += 1
    total[1] -= K.one
    return total


def _divide(K, num, den, n):
    """The series of num/den (coefficient lists, den[0] != 0) to z^n."""
    num = list(num) + [K.zero] * (n + 1)
    out = []
    for k in range(n + 1):
        acc = num[k] - sum((out[j] * den[k - j] for j in range(max(0, k - len(den) + 1), k)), K.zero)
        out.append(acc / den[0])
    return out


def _sqrt(K, v, n):
    """The series of sqrt(v) to z^n, v[0] a square in K (here 1/4)."""
    root0 = sympy.sqrt(K.to_sympy(v[0]))
    if not root0.is_Rational:
        raise NumericalFailure(f"tr R(z) = 2 - {4 * K.to_sympy(v[0])} z^2 + ...: sum b_i != 1")
    out = [K.from_sympy(root0)]
    for k in range(1, n + 1):
        acc = v[k] - sum((out[j] * out[k - j] for j in range(1, k)), K.zero)
        out.append(acc / (K.convert(2) * out[0]))
    return out


# ----------------------------------------------------------------------------- shifted, implicit stages
#
# With alpha = x + D p (D = Q - J/2) the stage Z_i(x) = M_i x, M_i symmetric, solves
# M_i = z sum_j a_ij G(M_j), G(M) = (I + D M)^T (I + D M) (g_j(x) = |(I + D M_j) x|^2 / 2): 3 unknowns
# per stage, quadratic. Whatever the M_i, tr R depends on delta = det(P^-1 + Q) alone,
# tr R = 2 (4 delta - 1)/(4 delta + 1) (docs/stability.md), so elliptic <=> delta > 0.


def shifted_stage_equations(tableau: Tableau) -> tuple[str, ...]:
    """``M_i = z (a_i1 G(M_1) + ...)`` for each stage, ``P = z (...)``, and G's definition."""
    F = tableau_field(tableau)
    grams = [sympy.Symbol(f"G(M{j + 1})") for j in range(tableau.stages)]
    out = []
    for name, row in [(f"M{i + 1}", r) for i, r in enumerate(F.A)] + [("P", F.b)]:
        total = sum((F.K.to_sympy(a) * g for a, g in zip(row, grams, strict=True) if a), sympy.Integer(0))
        out.append(f"{name} = z*({exact_text(total)})")
    out.append("G(M) = (I + D M)^T (I + D M), D = Q - J/2, M_i symmetric 2 x 2")
    return tuple(out)


def _mat_series(K, F: Field, n: int):
    """The series of the stages M_i and of P to z^n (lists [[m00, m01], [m10, m11]] of coefficient
    lists): n + 1 applications of the stage map from M_i = 0, each exact to one more power."""
    D = [[K.from_sympy(x) for x in row] for row in (SHIFT_Q - J / 2).tolist()]
    zero = [K.zero] * (n + 1)
    one = [K.one] + [K.zero] * n

    def gram(M):
        N = [[_add(K, one if i == j else zero,
                   _add(K, _scale(D[i][0], M[0][j]), _scale(D[i][1], M[1][j]), n), n)
              for j in range(2)] for i in range(2)]
        return [[_add(K, _mul(K, N[0][i], N[0][j], n), _mul(K, N[1][i], N[1][j], n), n) for j in range(2)]
                for i in range(2)]

    def combine(row, grams):
        out = [[zero] * 2 for _ in range(2)]
        for a, G in zip(row, grams, strict=True):
            if a:
                out = [[_add(K, out[i][j], _scale(a, G[i][j]), n) for j in range(2)] for i in range(2)]
        return [[_shift(K, out[i][j], n) for j in range(2)] for i in range(2)]

    Ms = [[[zero] * 2 for _ in range(2)] for _ in F.A]
    for _ in range(n + 1):
        grams = [gram(M) for M in Ms]
        Ms = [combine(row, grams) for row in F.A]
    return combine(F.b, [gram(M) for M in Ms])


def shifted_trace_series(F: Field, n: int) -> list:
    """tr R(z) to z^n for any tableau (explicit or implicit) with the shifted realisation:
    R = (I + D' P)(I + D P)^-1, tr R = tr((I + D'P) adj(I + DP)) / det(I + DP)."""
    K = F.K
    P = _mat_series(K, F, n)
    one = [K.one] + [K.zero] * n

    def plus_identity_times(C):
        C = [[K.from_sympy(x) for x in row] for row in C.tolist()]
        return [[_add(K, one if i == j else [K.zero] * (n + 1),
                      _add(K, _scale(C[i][0], P[0][j]), _scale(C[i][1], P[1][j]), n), n) for j in range(2)]
                for i in range(2)]

    left, right = plus_identity_times(SHIFT_Q + J / 2), plus_identity_times(SHIFT_Q - J / 2)
    adj = [[right[1][1], _scale(-K.one, right[0][1])], [_scale(-K.one, right[1][0]), right[0][0]]]
    num = [K.zero] * (n + 1)
    for i in range(2):
        for k in range(2):
            num = _add(K, num, _mul(K, left[i][k], adj[k][i], n), n)
    den = _add(K, _mul(K, right[0][0], right[1][1], n), _scale(-K.one, _mul(K, right[0][1], right[1][0], n)), n)
    return _divide(K, num, den, n)


_BASIS = ((0, 0), (0, 1), (1, 1))


def _shifted_arrays(tableau: Tableau, exact: bool = False):
    """A, b, D, D' as numpy arrays: float64, or (exact) object arrays of mpmath numbers at the
    working precision (DIGITS digits under mpmath.workdps)."""
    import numpy as np

    if not exact:
        return (np.array(tableau.A_float, dtype=float), np.array(tableau.b_float, dtype=float),
                np.array((SHIFT_Q - J / 2).tolist(), dtype=float), np.array((SHIFT_Q + J / 2).tolist(), dtype=float))
    A, b = _mp_tableau(tableau)
    def rational(x):
        q = sympy.Rational(x)
        return mpmath.mpf(int(q.p)) / int(q.q)
    const = [np.array([[rational(x) for x in row] for row in C.tolist()], dtype=object)
             for C in (SHIFT_Q - J / 2, SHIFT_Q + J / 2)]
    return (np.array(A.tolist(), dtype=object), np.array(list(b), dtype=object), *const)


def _symmetric(u, j):
    import numpy as np

    return np.array([[u[3 * j], u[3 * j + 1]], [u[3 * j + 1], u[3 * j + 2]]], dtype=u.dtype)


def _stage_grams(u, s, D):
    import numpy as np

    Ns = [np.eye(2, dtype=u.dtype) + D @ _symmetric(u, j) for j in range(s)]
    return Ns, [N.T @ N for N in Ns]


def _stage_sums(A, grams):
    """sum_j a_ij G_j for each stage i, as the 3s components (00, 01, 11)."""
    s = len(grams)
    sums = [sum((A[i][j] * grams[j] for j in range(s)), 0 * grams[0]) for i in range(s)]
    return [S[p, q] for S in sums for (p, q) in _BASIS]


def _shifted_residual(A, D, u, z):
    import numpy as np

    s = len(A)
    _, grams = _stage_grams(u, s, D)
    return u - z * np.array(_stage_sums(A, grams), dtype=u.dtype)


def _shifted_jacobian(A, D, u, z):
    """dF/du of F = u - z (sum_j a_ij G(M_j)) (u: the 3s entries (00, 01, 11) of the M_j);
    dG(M)[E] = (D E)^T N + N^T (D E), N = I + D M."""
    import numpy as np

    s = len(A)
    Ns, _ = _stage_grams(u, s, D)
    Jm = np.zeros((3 * s, 3 * s), dtype=u.dtype) + 0 * u[0]
    for j in range(s):
        for k, (p, q) in enumerate(_BASIS):
            E = np.zeros((2, 2), dtype=u.dtype) + 0 * u[0]
            E[p, q] = E[q, p] = 1
            dG = (D @ E).T @ Ns[j] + Ns[j].T @ (D @ E)
            for i in range(s):
                for r, (pp, qq) in enumerate(_BASIS):
                    Jm[3 * i + r, 3 * j + k] = (1 if (i, r) == (j, k) else 0) - z * A[i][j] * dG[pp, qq]
    return Jm


def _shifted_tangent(A, D, u, z):
    import numpy as np

    _, grams = _stage_grams(u, len(A), D)
    return np.linalg.solve(_shifted_jacobian(A, D, u, z), np.array(_stage_sums(A, grams)))


def _shifted_newton(A, D, u, z, iterations=30):
    """Newton at fixed z (float64) from u; None when it does not converge."""
    import numpy as np

    for _ in range(iterations):
        try:
            du = np.linalg.solve(_shifted_jacobian(A, D, u, z), _shifted_residual(A, D, u, z))
        except np.linalg.LinAlgError:
            return None
        u = u - du
        if not np.all(np.isfinite(u)):
            return None
        if np.linalg.norm(du) <= 1e-15 * (1 + np.linalg.norm(u)):
            return u
    return u if np.linalg.norm(_shifted_residual(A, D, u, z)) <= 1e-13 * (1 + np.linalg.norm(u)) else None


def _shifted_step_matrix(b, D, Dp, u, z):
    """R = (I + D'P)(I + DP)^-1 (None where det(I + DP) = 0) and det(I + DP) at the stages u."""
    import numpy as np

    _, grams = _stage_grams(u, len(b), D)
    P = z * sum((b[i] * grams[i] for i in range(len(b))), 0 * grams[0])
    right = np.eye(2) + D @ P
    det = right[0, 0] * right[1, 1] - right[0, 1] * right[1, 0]
    if det == 0:
        return None, det
    adj = np.array([[right[1, 1], -right[0, 1]], [-right[1, 0], right[0, 0]]])
    return (np.eye(2) + Dp @ P) @ adj / det, det


def _ellipticity(b, D, Dp, u, z):
    """min(4 - tr R^2, det(I + DP)): the step is elliptic while it is positive."""
    R, det = _shifted_step_matrix(b, D, Dp, u, z)
    if R is None:
        return 0.0
    tr = R[0, 0] + R[1, 1]
    return min(4 - tr * tr, det)


@dataclass(frozen=True)
class ShiftedBranch:
    """The branch of the shifted stage equations through M_i(0) = 0: where it folds (None: it
    reaches MAX_CONTINUATION_Z) and the stability interval (elliptic on (0, z0))."""

    existence_limit: Number | None
    stability_interval: Number


def _continue(A, D, u, z, z_target, on_step=None):
    """Predictor (tangent) - corrector (Newton) continuation of the branch from (u, z) towards
    z_target in float64. A step is taken when the corrector moves less than half the predictor and
    det J keeps its sign (past a fold Newton fails or lands on the other branch, where det J has
    the other sign); otherwise halved. Returns (u, z, reached): z_target, or the last point before
    the fold (within about 1e-12)."""
    import numpy as np

    dz = min(1.0 / 32, z_target - z)
    det = np.linalg.det(_shifted_jacobian(A, D, u, z))
    while z < z_target:
        dz = min(dz, z_target - z)
        try:
            step = dz * _shifted_tangent(A, D, u, z)
        except np.linalg.LinAlgError:  # J singular at an accepted point: the fold itself
            return u, z, False
        trial = _shifted_newton(A, D, u + step, z + dz, iterations=12)
        trial_det = None if trial is None else np.linalg.det(_shifted_jacobian(A, D, trial, z + dz))
        if trial is None or np.linalg.norm(trial - u - step) > np.linalg.norm(step) / 2 or trial_det * det <= 0 \
                or np.linalg.norm(trial) > 1e8:
            if dz < 1e-12 * (1 + z):
                return u, z, False
            dz /= 2
            continue
        if on_step is not None:
            on_step(u, z, trial, z + dz)
        u, z, det = trial, z + dz, trial_det
        dz *= 2
    return u, z, True


def shifted_branch(tableau: Tableau) -> ShiftedBranch:
    """Follow the shifted stage equations from M = 0 in z (`_continue`), watch the step's
    ellipticity (4 - tr R^2 > 0 and det(I + DP) > 0); bisect the first boundary (float64) and
    refine the fold (Newton on F = 0, det J = 0, DIGITS digits)."""
    import numpy as np

    A, b, D, Dp = _shifted_arrays(tableau)
    boundary = []

    def watch(u0, z0, u1, z1):
        if not boundary and _ellipticity(b, D, Dp, u1, z1) <= 0:
            boundary.append(_bisect_boundary(A, b, D, Dp, u0, z0, z1))

    u, z, reached = _continue(A, D, np.zeros(3 * tableau.stages), 0.0, MAX_CONTINUATION_Z, watch)
    if reached:
        fold, limit = None, None
    elif np.linalg.norm(u) > 1e7:  # the stages grow without bound near z: no step beyond
        fold, limit = z, Number(None, z)
    else:
        fold = _refine_shifted_fold(tableau, u, z)
        limit = Number(_one_stage_fold_text(tableau, fold), float(fold))
    if boundary and (fold is None or boundary[0] < fold):
        return ShiftedBranch(limit, Number(None, boundary[0]))
    return ShiftedBranch(limit, limit if limit is not None else UNBOUNDED)


def _bisect_boundary(A, b, D, Dp, u, lo, hi):
    """Bisection for the first z in (lo, hi] where the step stops being elliptic (to float64)."""
    while hi - lo > 4e-16 * hi:
        mid = (lo + hi) / 2
        trial = _shifted_newton(A, D, u, mid)
        if trial is not None and _ellipticity(b, D, Dp, trial, mid) > 0:
            lo, u = mid, trial
        else:
            hi = mid
    return (lo + hi) / 2


def _refine_shifted_fold(tableau: Tableau, u, z):
    """Newton (mpmath.findroot, DIGITS digits) on F(u, z) = 0, det J(u, z) = 0 from (u, z) near the fold."""
    import numpy as np

    n = len(u)
    with mpmath.workdps(DIGITS):
        A, _, D, _ = _shifted_arrays(tableau, exact=True)

        def equations(*v):
            uu = np.array(v[:n], dtype=object)
            r = _shifted_residual(A, D, uu, v[n])
            return [r[i] for i in range(n)] + [mpmath.det(mpmath.matrix(_shifted_jacobian(A, D, uu, v[n]).tolist()))]

        try:
            root = mpmath.findroot(equations, [mpmath.mpf(float(x)) for x in u] + [mpmath.mpf(z)],
                                   tol=mpmath.mpf(10) ** (10 - 2 * DIGITS), maxsteps=200)
        except (ValueError, ZeroDivisionError) as exc:
            raise NumericalFailure(f"the fold of the shifted stage equations near z = {z:.6g} did not "
                                   f"converge: {exc}") from None
        return root[n]


def _one_stage_fold_text(tableau: Tableau, fold) -> str | None:
    """z* = ONE_STAGE_SHIFTED_FOLD / a_11 as text for an exact one-stage tableau whose refined fold
    is that root (None otherwise)."""
    if tableau.stages != 1 or not tableau.is_exact:
        return None
    F = tableau_field(tableau)
    exact = ONE_STAGE_SHIFTED_FOLD / F.K.to_sympy(F.A[0][0])
    with mpmath.workdps(DIGITS):
        close = abs(mpmath.mpf(str(sympy.N(exact, DIGITS))) - fold) <= mpmath.mpf(10) ** (10 - DIGITS) * (1 + abs(fold))
    return exact_text(exact) if close else None


# ----------------------------------------------------------------------------- the report


@dataclass(frozen=True)
class Stability:
    """What `rkhp stability` reports for one method (docs/stability.md, docs/json.md).

    kind: ``explicit``, ``implicit`` or ``composition``; m: the exact polynomial m(z) as text
    (explicit, symmetric realisation, at most MAX_POLYNOMIAL_STAGES stages; else None);
    stage_equations: implicit tableaux; trace: tr R(z) (shifted realisation).
    """

    name: str
    kind: str
    realisation: str
    m: str | None
    m_degree: int | None
    stage_equations: tuple[str, ...] | None
    phase: Phase
    wrap_limit: Number | None
    existence_limit: Number | None
    trace: str | None
    stability_interval: Number | None


def analyse(tableau: Tableau, order: int = 9, realisation: str = "symmetric") -> Stability:
    """The linear stability and phase of an RKHP tableau (see the module)."""
    _check_order(order)
    if realisation not in REALISATIONS:
        raise InputError(f"unknown realisation {realisation!r} for the linear analysis; choose one of "
                         f"{', '.join(REALISATIONS)}")
    if realisation == "shifted" and tableau.is_explicit:
        trace = shifted_trace(tableau)
        F = tableau_field(tableau)
        return Stability(tableau.name, "explicit", realisation, None, None, None, trace_phase(F, trace, order),
                         None, None, exact_text(trace) if tableau.is_exact else None,
                         stability_interval(trace, F.K))
    if realisation == "shifted":
        F = tableau_field(tableau)
        ph = _phase(F, lambda n: _theta_of_trace(F.K, shifted_trace_series(F, n + 2), n), order)
        branch = shifted_branch(tableau)
        return Stability(tableau.name, "implicit", realisation, None, None, shifted_stage_equations(tableau), ph,
                         None, branch.existence_limit, None, branch.stability_interval)
    ph = phase(tableau, order)
    if tableau.is_explicit:
        m = m_polynomial(tableau)
        wrap = wrap_limit_explicit(m) if m is not None else wrap_limit_numeric(tableau)
        return Stability(tableau.name, "explicit", realisation, None if m is None else poly_text(m),
                         None if m is None else m.degree(), None, ph, wrap, None, None, None)
    branch = implicit_branch(tableau)
    return Stability(tableau.name, "implicit", realisation, None, None, branch.equations, ph,
                     branch.wrap_limit, branch.existence_limit, None, None)


def analyse_composition(name: str, tableau: Tableau, gammas, order: int = 9,
                        digits: int | None = None) -> Stability:
    """The phase of a composition of the RKHP step of `tableau` with substeps gamma_i h
    (`composition_phase`; symmetric realisation). Its substeps turn back and forth, so theta is not
    monotone and no wrap limit is given. Coefficients known to `digits` digits (decimals read
    exactly) leave residues of that size: those coefficients of theta - z count as zero."""
    ph = composition_phase(tableau, gammas, order)
    return Stability(name, "composition", "symmetric", None, None, None,
                     ph if digits is None else _within_digits(ph, digits), None, None, None, None)


def _within_digits(ph: Phase, digits: int) -> Phase:
    """`ph` with the coefficients below 10^-(digits - 5) as zeros and the others by their values
    (the exact decimals' long rationals say no more than their digits)."""
    tol = 10.0 ** -(digits - 5)
    coefficients = tuple((k, Number(None, c.value) if abs(c.value) > tol else Number("0", 0.0))
                         for k, c in ph.coefficients)
    nonzero = [(k, c) for k, c in coefficients if c.value != 0.0]
    if not nonzero:
        return Phase(ph.order, coefficients, None, None, ph.searched)
    k, c = nonzero[0]
    return Phase(ph.order, coefficients, k - 1, c, ph.searched)


def step_matrix_shifted(tableau: Tableau, z: float):
    """R(z) with the shifted realisation in float64 (see shifted_trace): explicit stages directly,
    implicit ones on the branch through 0 (shifted_branch; None past its fold)."""
    import numpy as np

    if not tableau.is_explicit:
        A, b, D, Dp = _shifted_arrays(tableau)
        u, _, reached = _continue(A, D, np.zeros(3 * tableau.stages), 0.0, z)
        return _shifted_step_matrix(b, D, Dp, u, z)[0] if reached else None
    Q = np.array(SHIFT_Q.tolist(), dtype=float)
    Jf = np.array(J.tolist(), dtype=float)
    D, Dp, eye = Q - Jf / 2, Q + Jf / 2, np.eye(2)
    A, b = tableau.A_float, tableau.b_float
    grads = []
    for i in range(tableau.stages):
        Mi = z * sum((A[i][j] * grads[j] for j in range(i)), np.zeros((2, 2)))
        grads.append((eye + D @ Mi).T @ (eye + D @ Mi))
    P = z * sum(b[i] * grads[i] for i in range(tableau.stages))
    return (eye + Dp @ P) @ np.linalg.inv(eye + D @ P)


def rotation_angle(tableau: Tableau, z: float, realisation: str = "symmetric") -> float | None:
    """theta(z) in float64: 2 arctan(m(z)/2) (symmetric realisation; None where an implicit
    tableau's branch has no solution at z), arccos(tr R/2) (shifted; None where |tr R| > 2)."""
    return rotation_angles(tableau, [z], realisation)[0]


def _explicit_angles(A, b, zs) -> list[float]:
    """theta(z) = 2 arctan(m(z)/2) of an explicit tableau at every z of ``zs`` at once: the stage
    maps m_i = z sum_j<i a_ij (1 + m_j^2/4) (docs/theory.md §13) as arrays over z, summed in the
    order of j as one z at a time would, arctan per z by `math.atan`."""
    import numpy as np

    z = np.asarray(zs, dtype=np.float64)
    weights = []  # 1 + m_j^2/4 of the stages so far
    for row in A:
        acc = np.zeros_like(z)
        for a, w in zip(row, weights):
            acc = acc + a * w
        m = z * acc
        weights.append(1 + m ** 2 / 4)
    total = np.zeros_like(z)
    for bi, w in zip(b, weights, strict=True):
        total = total + bi * w
    return [2.0 * math.atan(t / 2) for t in (z * total).tolist()]


def rotation_angles(tableau: Tableau, zs, realisation: str = "symmetric") -> list[float | None]:
    """`rotation_angle` at each z of the increasing ``zs``; an implicit tableau's branch (symmetric
    realisation) is continued from one z to the next, and once it has ended (past its fold) every
    later z has no solution."""
    if realisation == "shifted":
        angles = []
        for z in zs:
            R = step_matrix_shifted(tableau, z)
            tr = None if R is None else float(R.trace())
            angles.append(math.acos(tr / 2) if tr is not None and abs(tr) <= 2 else None)
        return angles
    A, b = tableau.A_float, tableau.b_float
    s = tableau.stages

    def angle(ms, z):
        return 2.0 * math.atan(z * sum(b[i] * (1 + ms[i] ** 2 / 4) for i in range(s)) / 2)

    if tableau.is_explicit:
        return _explicit_angles(A, b, zs)
    angles, start = [], None
    with mpmath.workdps(25):
        A_mp = _mp_tableau(tableau)[0]
        for z in zs:
            target = mpmath.mpf(z)
            point = None if start is False else branch_point(A_mp, target, start)
            start = False if point is None else (point, target)
            angles.append(None if point is None else angle([float(x) for x in point], z))
    return angles


def phase_coefficients_numeric(A, b, n: int):
    """theta(z) - z to z^n for numeric A, b (float64, or mpmath numbers in object arrays): the series
    of m from n + 2 applications of the stage map, explicit and implicit alike; a numpy array,
    index = power of z."""
    import numpy as np

    dtype = np.asarray(b).dtype
    zero = np.zeros(n + 1, dtype=dtype) * b[0]

    def mul(u, v):
        out = zero.copy()
        for i in range(n + 1):
            if u[i]:
                out[i:] += u[i] * v[: n + 1 - i]
        return out

    def shift(u):
        out = zero.copy()
        out[1:] = u[:n]
        return out

    s = len(b)
    ms = [zero.copy() for _ in range(s)]
    m = zero.copy()
    for _ in range(n + 2):
        w = [mul(mi, mi) / 4 for mi in ms]
        for wi in w:
            wi[0] += 1
        ms = [shift(sum((A[i][j] * w[j] for j in range(s)), zero.copy())) for i in range(s)]
        m = shift(sum((b[i] * w[i] for i in range(s)), zero.copy()))
    u = m / 2
    u2 = mul(u, u)
    total, power, k = zero.copy(), u, 0
    while k <= n:
        total = total + power * (2 * (-1) ** k) / (2 * k + 1)
        power = mul(power, u2)
        k += 1
    total[1] -= 1
    return total
