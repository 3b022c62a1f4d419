"""The shifted realisation on the oscillator (alpha, beta = x + Q p -/+ pi p/2, Q symmetric): the
stages are symmetric matrices, the step matrix R and its trace decide ellipticity; explicit
tableaux exactly (tr R a rational function of z), implicit ones by series and by continuation of
their matrix stages to the fold (docs/stability.md)."""

from __future__ import annotations

import math
from dataclasses import dataclass

import mpmath
import sympy

from ...base.errors import InputError, NumericalFailure
from ..tableau import Tableau
from .field import DIGITS, UNBOUNDED, Number, NumberField, Z, exact_text, tableau_field
from .implicit import MAX_CONTINUATION_Z, mp_tableau
from .phase import Phase, phase_of
from .roots import first_positive_root
from .series import add, divide, mul, scale, shift, sqrt

#: the shifted realisation's Q (docs/theory.md §4; `rkhp.systems.core.shift_matrix` for n = 2)
SHIFT_Q = sympy.Matrix([[sympy.Rational(1, 2), sympy.Rational(1, 4)],
                        [sympy.Rational(1, 4), sympy.Rational(1, 2)]])

#: one implicit stage, shifted realisation: M = c G(M) depends on c = z a_11 alone, and its branch
#: through M = 0 folds at c = 1/3, a root of the eliminant (c - 1)(3c - 1)(4c^2 + 8c - 3) of the
#: stage equations and det J = 0 (lex Groebner basis; docs/stability.md), so z* = 1/(3 a_11)
ONE_STAGE_SHIFTED_FOLD = sympy.Rational(1, 3)

#: the oscillator's Poisson matrix, dynamics xdot = J grad H
J = sympy.Matrix([[0, 1], [-1, 0]])


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


def trace_phase(F: NumberField, trace, order: int) -> Phase:
    """The rotation number of an elliptic step, theta = arccos(tr R/2), as a series: theta - z to
    z^order, tr R(z) a rational function (explicit tableaux)."""
    K = F.K
    num, den = sympy.fraction(sympy.together(trace))
    num = [K.from_sympy(c) for c in sympy.Poly(num, Z, domain=K).all_coeffs()[::-1]]
    den = [K.from_sympy(c) for c in sympy.Poly(den, Z, domain=K).all_coeffs()[::-1]]
    return phase_of(F, lambda n: theta_of_trace(K, divide(K, num, den, n + 2), n), order)


def theta_of_trace(K, tr, n):
    """theta - z to z^n from the series of tr R to z^(n+2): theta = arccos(tr/2) = 2 arcsin(z sqrt(v))
    with (2 - tr)/4 = z^2 v(z)."""
    u = [-x / K.convert(4) for x in tr]
    u[0] += K.one / K.convert(2)
    if u[0] or u[1]:
        raise NumericalFailure("tr R(z) is not 2 - O(z^2): the step is not consistent")
    v = u[2:] + [K.zero, K.zero]
    w = shift(K, sqrt(K, v, n), n)
    w2 = mul(K, w, w, n)
    total, power, k = [K.zero] * (n + 1), w, 0
    while any(power):
        coef = K.convert(2 * math.comb(2 * k, k)) / K.convert(4**k * (2 * k + 1))
        total = add(K, total, scale(coef, power), n)
        power = mul(K, power, w2, n)
        k += 1
    total[1] -= K.one
    return total


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


def _mat_series(K, F: NumberField, n: int):
    """The series of the stages M_i and of P to z^n (lists [[m00, m01], [m10, m11]] of coefficient
    lists): n + 1 applications of the stage map from M_i = 0, each exact to one more power."""
    D = [[K.from_sympy(x) for x in row] for row in (SHIFT_Q - J / 2).tolist()]
    zero = [K.zero] * (n + 1)
    one = [K.one] + [K.zero] * n

    def gram(M):
        N = [[add(K, one if i == j else zero,
                   add(K, scale(D[i][0], M[0][j]), scale(D[i][1], M[1][j]), n), n)
              for j in range(2)] for i in range(2)]
        return [[add(K, mul(K, N[0][i], N[0][j], n), mul(K, N[1][i], N[1][j], n), n) for j in range(2)]
                for i in range(2)]

    def combine(row, grams):
        out = [[zero] * 2 for _ in range(2)]
        for a, G in zip(row, grams, strict=True):
            if a:
                out = [[add(K, out[i][j], scale(a, G[i][j]), n) for j in range(2)] for i in range(2)]
        return [[shift(K, out[i][j], n) for j in range(2)] for i in range(2)]

    Ms = [[[zero] * 2 for _ in range(2)] for _ in F.A]
    for _ in range(n + 1):
        grams = [gram(M) for M in Ms]
        Ms = [combine(row, grams) for row in F.A]
    return combine(F.b, [gram(M) for M in Ms])


def shifted_trace_series(F: NumberField, n: int) -> list:
    """tr R(z) to z^n for any tableau (explicit or implicit) with the shifted realisation:
    R = (I + D' P)(I + D P)^-1, tr R = tr((I + D'P) adj(I + DP)) / det(I + DP)."""
    K = F.K
    P = _mat_series(K, F, n)
    one = [K.one] + [K.zero] * n

    def plus_identity_times(C):
        C = [[K.from_sympy(x) for x in row] for row in C.tolist()]
        return [[add(K, one if i == j else [K.zero] * (n + 1),
                      add(K, scale(C[i][0], P[0][j]), scale(C[i][1], P[1][j]), n), n) for j in range(2)]
                for i in range(2)]

    left, right = plus_identity_times(SHIFT_Q + J / 2), plus_identity_times(SHIFT_Q - J / 2)
    adj = [[right[1][1], scale(-K.one, right[0][1])], [scale(-K.one, right[1][0]), right[0][0]]]
    num = [K.zero] * (n + 1)
    for i in range(2):
        for k in range(2):
            num = add(K, num, mul(K, left[i][k], adj[k][i], n), n)
    den = add(K, mul(K, right[0][0], right[1][1], n), scale(-K.one, mul(K, right[0][1], right[1][0], n)), n)
    return divide(K, num, den, n)


_BASIS = ((0, 0), (0, 1), (1, 1))


def _shifted_arrays(tableau: Tableau, exact: bool = False):
    """A, b, D, D' as numpy arrays: float64, or (exact) object arrays of mpmath numbers at the
    working precision (DIGITS digits under mpmath.workdps)."""
    import numpy as np

    if not exact:
        return (np.array(tableau.A_float, dtype=float), np.array(tableau.b_float, dtype=float),
                np.array((SHIFT_Q - J / 2).tolist(), dtype=float), np.array((SHIFT_Q + J / 2).tolist(), dtype=float))
    A, b = mp_tableau(tableau)
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

        def shifted_fold_equations(*v):
            uu = np.array(v[:n], dtype=object)
            r = _shifted_residual(A, D, uu, v[n])
            return [r[i] for i in range(n)] + [mpmath.det(mpmath.matrix(_shifted_jacobian(A, D, uu, v[n]).tolist()))]

        try:
            root = mpmath.findroot(shifted_fold_equations, [mpmath.mpf(float(x)) for x in u] + [mpmath.mpf(z)],
                                   tol=mpmath.mpf(10) ** (10 - 2 * DIGITS), maxsteps=200)
        except (ValueError, ZeroDivisionError, TypeError):  # TypeError: mpmath's LU of an exactly singular matrix
            raise NumericalFailure(f"the fold of the shifted stage equations near z = {z:.6g} could not be refined: "
                                   "Newton on the stage equations and det J = 0 did not converge (it cannot where "
                                   "several stages fold at once, as stages repeating one another do)") from None
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

