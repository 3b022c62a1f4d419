"""Positive real roots of polynomials in z over a number field, exactly: isolated on the norm over QQ
and written as radicals or CRootOf (docs/stability.md)."""

from __future__ import annotations

import mpmath
import sympy

from .field import DIGITS, Number, Z, exact_text


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

