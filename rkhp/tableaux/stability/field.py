"""Numbers of the linear analysis: the symbol z, a real Number (exact text and value), the number
field of a tableau's entries (docs/stability.md)."""

from __future__ import annotations

import math
from dataclasses import dataclass
from fractions import Fraction

import sympy
from sympy.polys.constructor import construct_domain

from ...base.errors import InputError
from ..tableau import Tableau, as_sympy, is_exact, to_fraction

Z = sympy.Symbol("z")

#: working digits of the numerical continuation and root refinement
DIGITS = 40


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
class NumberField:
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


def tableau_field(tableau: Tableau, extra=()) -> NumberField:
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
    return NumberField(K, A, b, tableau.is_exact, tableau.digits)


def _pair(q: Fraction) -> tuple[int, int]:
    return q.numerator, q.denominator

