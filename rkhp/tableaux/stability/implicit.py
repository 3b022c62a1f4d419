"""Implicit tableaux on the oscillator, symmetric realisation: the branch of the stage equations
through m(0) = 0 followed by Newton continuation, its fold (existence limit) and wrap limit
(docs/stability.md)."""

from __future__ import annotations

from dataclasses import dataclass

import mpmath
import sympy

from ...base.errors import InputError, NumericalFailure
from ..tableau import Tableau, to_fraction
from .field import DIGITS, Number, Z, exact_text, tableau_field
from .roots import exact_root

#: stage equations are eliminated exactly (Groebner bases) up to this many stages
MAX_ELIMINATION_STAGES = 2

#: the continuation of an implicit branch stops beyond this z (the branch then exists up to it)
MAX_CONTINUATION_Z = 64.0

#: the most stages of an implicit tableau the linear analysis follows, per realisation: each
#: continuation step solves systems of the s (symmetric) or 3s (shifted) stage unknowns at DIGITS
#: digits, and the fold's refinement takes up to 200 Newton steps of that many + 1 determinants;
#: the slowest, a fold of several stages at once, takes about 10 s at 8 symmetric stages and 30 s
#: at 4 shifted ones (docs/stability.md)
MAX_IMPLICIT_STAGES = {"symmetric": 8, "shifted": 4}


def check_implicit_stages(tableau: Tableau, realisation: str) -> None:
    """InputError for an implicit tableau of more stages than MAX_IMPLICIT_STAGES[realisation],
    before any work."""
    most = MAX_IMPLICIT_STAGES[realisation]
    if not tableau.is_explicit and tableau.stages > most:
        raise InputError(f"{tableau.name}: an implicit tableau of {tableau.stages} stages; the linear analysis "
                         f"on the {realisation} realisation follows the stages of at most {most}")


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


def mp_tableau(tableau: Tableau):
    with mpmath.workdps(DIGITS):
        A = mpmath.matrix([[mpmath.mpf(to_fraction(x, 4 * DIGITS).numerator) / to_fraction(x, 4 * DIGITS).denominator
                            for x in row] for row in tableau.A])
        b = [mpmath.mpf(to_fraction(x, 4 * DIGITS).numerator) / to_fraction(x, 4 * DIGITS).denominator
             for x in tableau.b]
    return A, b


def _residual(A, m, z):
    s = len(m)
    return mpmath.matrix([m[i] - z * sum(A[i, j] * (1 + m[j] ** 2 / 4) for j in range(s)) for i in range(s)])


def _fold_jacobian(A, m, z):
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
            dm = mpmath.lu_solve(_fold_jacobian(A, m, z), r)
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
    dms = mpmath.lu_solve(_fold_jacobian(A, m, z), A * w)
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
                or abs(_det(_fold_jacobian(A, trial, z + dz))) < mpmath.mpf(10) ** -4:
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
        A, b = mp_tableau(tableau)
        s = tableau.stages
        m = mpmath.matrix([0] * s)
        z = mpmath.mpf(0)
        dz = mpmath.mpf(1) / 16
        last_slope = _dm_dz(A, b, m, z)
        wrap = None
        while z < MAX_CONTINUATION_Z:
            trial = _solve_at(A, m + dz * _tangent(A, m, z), z + dz, iterations=12)
            if trial is None or mpmath.norm(trial - m) > 4 * dz * (1 + mpmath.norm(m)) \
                    or abs(_det(_fold_jacobian(A, trial, z + dz))) < mpmath.mpf(10) ** -12:
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
    return mpmath.lu_solve(_fold_jacobian(A, m, z), A * w)


def _refine_fold(A, m, z):
    """Newton on (F(m, z) = 0, det(I - z A diag(m/2)) = 0) from a point just before the fold."""
    s = len(m)

    def fold_equations(*u):
        mm, zz = mpmath.matrix(u[:s]), u[s]
        r = _residual(A, mm, zz)
        return [r[i] for i in range(s)] + [_det(_fold_jacobian(A, mm, zz))]

    try:
        root = mpmath.findroot(fold_equations, [m[i] for i in range(s)] + [z], tol=mpmath.mpf(10) ** (10 - 2 * DIGITS),
                               maxsteps=200)
    except (ValueError, ZeroDivisionError, TypeError):  # TypeError: mpmath's LU of an exactly singular matrix
        raise NumericalFailure(f"the fold of the stage equations near z = {float(z):.6g} could not be refined: "
                               "Newton on the stage equations and det J = 0 did not converge (it cannot where "
                               "several stages fold at once, as stages repeating one another do)") from None
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

    def fold_entry(x):
        if K == sympy.QQ:
            return K.to_sympy(x)
        coeffs = x.to_list()
        return sum(sympy.Rational(int(q.numerator), int(q.denominator)) * r**(len(coeffs) - 1 - i)
                   for i, q in enumerate(coeffs))

    Ar = sympy.Matrix(s, s, lambda i, j: fold_entry(F.A[i][j]))
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

