"""Exact rationals and their linear combinations as text: the one formatter of order conditions
(`rkhp.trees.conditions`), relations (`rkhp.trees.relations`), tableau entries (`rkhp.tableaux.tableau`), Casimir names
(`rkhp.systems.families`) and the CLI.
"""

from __future__ import annotations

from collections.abc import Callable, Iterable
from fractions import Fraction


def fraction_text(q) -> str:
    """``1/3``, ``-2``: the text `Fraction` reads back."""
    return str(Fraction(q))


def fraction_latex(q) -> str:
    """``\\frac{1}{3}``, ``-\\frac{1}{2}``, ``-2``."""
    q = Fraction(q)
    if q.denominator == 1:
        return str(q.numerator)
    sign = "-" if q < 0 else ""
    return f"{sign}\\frac{{{abs(q.numerator)}}}{{{q.denominator}}}"


def combination_text(terms: Iterable[tuple[Fraction, str]],
                     fmt: Callable[[Fraction], str] = fraction_text) -> str:
    """sum_k c_k e_k with signs, unit coefficients left out and zero terms dropped:
    ``4 sum_i b_i c_i^3 - 12 sum_{i,j} b_i a_ij c_j^2``, ``-F(b[b]) + F(b[b,b])``; ``0`` when
    every term is zero."""
    out = []
    for coef, expr in terms:
        if coef == 0:
            continue
        magnitude = abs(coef)
        body = expr if magnitude == 1 else f"{fmt(magnitude)} {expr}"
        if not out:
            out.append(("-" if coef < 0 else "") + body)
        else:
            out.append((" - " if coef < 0 else " + ") + body)
    return "".join(out) or "0"
