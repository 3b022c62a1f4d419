"""Closed forms: fix the free parameters of a solution family at simple values, then recognise.

Solutions of the order conditions usually form families (fewer conditions than unknowns). To
reach a tableau with a closed form, free unknowns are fixed one at a time at simple values (zero
first, then rationals of small denominator near the current value), the others following by
Newton's method, until the solution is locally isolated. Each remaining coefficient is then
recognised as a rational or a quadratic irrational (an integer relation of degree <= 2 found by
PSLQ, which decides a failed number in milliseconds where sympy's nsimplify with a list of surds
takes seconds), and the closed form is kept only if every order condition holds exactly.
"""

from __future__ import annotations

from fractions import Fraction

import numpy as np

from .polish import Polished, polish
from .system import ResidualSystem

#: Largest integer coefficient of the relations looked for (rationals and quadratic surds).
MAX_COEFFICIENT = 10**6
#: Largest denominator of the simple rationals tried when fixing a free unknown.
SNAP_DENOMINATOR = 6


def _rank(J: np.ndarray) -> int:
    if J.size == 0:
        return 0
    sv = np.linalg.svd(J, compute_uv=False)
    return int(np.sum(sv > 1e-9 * max(1.0, sv[0])))


def _newton_float(system: ResidualSystem, x: np.ndarray, free: np.ndarray, iterations: int = 30):
    """Minimum-norm Gauss–Newton in float64 on the free unknowns; the point or None."""
    x = x.copy()
    for _ in range(iterations):
        r, J = system.residuals(x)
        if not np.all(np.isfinite(r)):
            return None
        if np.max(np.abs(r), initial=0.0) < 1e-13:
            return x
        step, *_ = np.linalg.lstsq(J[:, free], -r, rcond=None)
        x[free] += step
        if np.max(np.abs(x)) > 1e3:
            return None
    r, _ = system.residuals(x, jacobian=False)
    return x if np.max(np.abs(r), initial=0.0) < 1e-12 else None


def _simple_values(v: float) -> list[Fraction]:
    """Rationals p/q (q <= SNAP_DENOMINATOR) within 3/4 of v, simplest first (zero first)."""
    out = {Fraction(p, q) for q in range(1, SNAP_DENOMINATOR + 1)
           for p in range(int(np.floor((v - 0.75) * q)), int(np.ceil((v + 0.75) * q)) + 1)
           if abs(p / q - v) <= 0.75}
    return sorted(out, key=lambda f: (f != 0, f.denominator, abs(f.numerator), abs(float(f) - v)))


def fix_free_unknowns(system: ResidualSystem, x: np.ndarray, bound: float = 20.0,
                      avoid: frozenset = frozenset()):
    """Fix free unknowns at simple values while a solution remains (greedy, simplest first).

    ``avoid`` lists first choices (index, value) not to take (to try another branch).
    Returns (x, fixed, first): the float64 solution, a dict index -> Fraction of the fixed
    unknowns, and the first choice taken (or None).
    """
    x = np.asarray(x, dtype=float).copy()
    n = len(x)
    fixed: dict[int, Fraction] = {}
    free = np.ones(n, dtype=bool)
    first = None
    while True:
        _, J = system.residuals(x)
        freedom = int(free.sum()) - _rank(J[:, free])
        if freedom <= 0:
            return x, fixed, first
        candidates = sorted(((k, v) for k in range(n) if free[k] for v in _simple_values(x[k])),
                            key=lambda kv: (kv[1] != 0, kv[1].denominator, abs(kv[1].numerator),
                                            abs(x[kv[0]] - float(kv[1]))))
        for k, v in candidates:
            if first is None and (k, v) in avoid:
                continue
            trial = x.copy()
            trial[k] = float(v)
            mask = free.copy()
            mask[k] = False
            moved = _newton_float(system, trial, mask)
            if moved is not None and np.max(np.abs(moved)) <= bound:
                _, J2 = system.residuals(moved)
                if int(mask.sum()) - _rank(J2[:, mask]) < freedom:
                    x, free, fixed[k] = moved, mask, v
                    first = first or (k, v)
                    break
        else:
            return x, fixed, first


def recognise_number(text: str, digits: int):
    """A sympy closed form of a decimal known to ``digits`` digits: a rational p/q, or a
    quadratic irrational (u + v sqrt(d)) / w, from an integer relation of degree <= 2 with
    coefficients up to MAX_COEFFICIENT (mpmath.findpoly, i.e. PSLQ); None when there is none.
    """
    import mpmath
    import sympy

    with mpmath.workdps(digits):
        x = mpmath.mpf(text)
        tolerance = mpmath.mpf(10) ** (5 - digits)
        q = Fraction(text).limit_denominator(MAX_COEFFICIENT)
        if abs(x - mpmath.mpf(q.numerator) / q.denominator) < tolerance:
            return sympy.Rational(q.numerator, q.denominator)
        poly = mpmath.findpoly(x, 2, maxcoeff=MAX_COEFFICIENT)
        if poly is None or len(poly) != 3:
            return None
        c2, c1, c0 = (int(c) for c in poly)
        for sign in (1, -1):
            root = sympy.radsimp((-c1 + sign * sympy.sqrt(c1 * c1 - 4 * c2 * c0)) / (2 * c2))
            if root.is_real and abs(mpmath.mpf(sympy.N(root, digits + 5)) - x) < tolerance:
                return root
    return None


def exact_residuals_vanish(system: ResidualSystem, exact: list) -> bool:
    """Whether every order condition holds exactly at the exact unknowns (sympy arithmetic)."""
    import sympy

    x = np.array([sympy.nsimplify(v) for v in exact], dtype=object)
    r, _ = system.residuals(x, jacobian=False)
    for v in r:
        v = sympy.radsimp(sympy.expand(v))
        if v != 0 and not v.equals(0):
            return False
    return True


def find_closed_form(system: ResidualSystem, x_float, digits: int = 30, tries: int = 4):
    """Try to reach an exactly verified closed form near a solution.

    Explores up to ``tries`` branches of :func:`fix_free_unknowns` (each avoiding the previous
    first choices) and keeps the simplest closed form that verifies exactly (shortest text).
    Returns (exact entries as sympy numbers, polished point), or (None, polished point of the
    first branch, or None when even polishing failed).
    """
    avoid: set = set()
    fallback = best = None
    for _ in range(tries):
        x, fixed, first = fix_free_unknowns(system, np.asarray(x_float, dtype=float),
                                            avoid=frozenset(avoid))
        pol: Polished = polish(system, x, digits, fixed=fixed)
        if pol.converged:
            fallback = fallback or pol
            exact = _recognise_all(system, pol, fixed, digits)
            if exact is not None and (best is None or _size(exact) < _size(best[0])):
                best = (exact, pol)
        if first is None:
            break
        avoid.add(first)
    return best if best is not None else (None, fallback)


def _size(exact) -> int:
    return sum(len(str(v)) for v in exact)


def recognise_point(system: ResidualSystem, pol: Polished):
    """Closed forms of every entry of a polished point as it is (no parameter fixed), kept only
    if the order conditions then hold exactly; else None."""
    return _recognise_all(system, pol, {}, pol.digits)


def _recognise_all(system: ResidualSystem, pol: Polished, fixed: dict, digits: int):
    exact = []
    for k, text in enumerate(pol.x):
        value = _sympy_fraction(fixed[k]) if k in fixed else recognise_number(text, digits)
        if value is None:
            return None
        exact.append(value)
    return exact if exact_residuals_vanish(system, exact) else None


def _sympy_fraction(v: Fraction):
    import sympy

    return sympy.Rational(v.numerator, v.denominator)
