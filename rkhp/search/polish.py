"""Polishing a float64 solution to D digits by Newton's method in mpmath, and checking it there.

The order conditions are usually fewer than the unknowns (solutions form families), so each step
is the minimum-norm Gauss–Newton step dx = -J^T (J J^T)^{-1} r, which converges quadratically to a
nearby point of the solution set when J has full row rank; a rank-deficient J falls back to the
SVD pseudo-inverse. Working precision is D + 10 digits; the solution is accepted when every
residual is below 10^-D.
"""

from __future__ import annotations

import time
from dataclasses import dataclass
from fractions import Fraction

import numpy as np

from .system import ResidualSystem


@dataclass(frozen=True)
class Polished:
    """A polished solution.

    Attributes:
        x: the unknowns as decimal strings of ``digits`` significant digits.
        digits: the precision D reached (residuals below 10^-D), or the one attempted on failure.
        residual: max |residual| at the final point, as a float (may underflow to 0.0).
        converged: whether every residual fell below 10^-D.
        iterations: Newton iterations used.
    """

    x: tuple[str, ...]
    digits: int
    residual: float
    converged: bool
    iterations: int

    def mp_values(self):
        """The unknowns as mpmath numbers at the current mpmath precision."""
        import mpmath

        return np.array([mpmath.mpf(v) for v in self.x], dtype=object)


def to_mp(x) -> np.ndarray:
    """An object array of mpmath numbers from floats or strings, at the current precision."""
    import mpmath

    return np.array([mpmath.mpf(v) for v in x], dtype=object)


def newton_step(J, r):
    """Minimum-norm solution dx of J dx = -r in mpmath (object arrays)."""
    import mpmath

    Jm = mpmath.matrix(J.tolist())
    rm = mpmath.matrix(list(r))
    try:
        y = mpmath.lu_solve(Jm * Jm.T, rm)
        dx = -(Jm.T * y)
    except ZeroDivisionError:
        U, S, V = mpmath.svd_r(Jm)
        cutoff = max(S) * mpmath.mpf(10) ** (-mpmath.mp.dps // 2)
        ut_r = U.T * rm
        z = mpmath.matrix([ut_r[k] / S[k] if S[k] > cutoff else 0 for k in range(len(S))])
        dx = -(V.T * z)
    return np.array([dx[k] for k in range(J.shape[1])], dtype=object)


def polish(system: ResidualSystem, x0, digits: int = 30, max_iterations: int = 40,
           fixed: dict[int, Fraction] | None = None, deadline: float | None = None) -> Polished:
    """Newton in mpmath from x0 (floats or strings) until every residual is below 10^-digits.

    ``fixed`` maps unknown indices to values kept fixed (their columns leave the Jacobian); the
    iterations stop (not converged) once the clock (time.time()) passes ``deadline``.
    """
    import mpmath

    with mpmath.workdps(digits + 10):
        x = to_mp(x0)
        free = np.ones(len(x), dtype=bool)
        for k, v in (fixed or {}).items():
            x[k] = mpmath.mpf(v.numerator) / v.denominator
            free[k] = False
        tol = mpmath.mpf(10) ** (-digits)
        best = None
        iterations = 0
        for iterations in range(max_iterations + 1):
            r, J = system.residuals(x)
            size = max(abs(v) for v in r) if len(r) else mpmath.mpf(0)
            if best is not None and size > 1e3 * best and size > 1e-6:
                break  # diverging
            best = size if best is None else min(best, size)
            if size < tol or iterations == max_iterations:
                break
            if deadline is not None and time.time() > deadline:
                break
            step = newton_step(J[:, free], r)
            x[free] = x[free] + step
        converged = bool(size < tol)
        text = tuple(mpmath.nstr(v, digits, strip_zeros=False) for v in x)
        return Polished(text, digits, float(size), converged, iterations)
