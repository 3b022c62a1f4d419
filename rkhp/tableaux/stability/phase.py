"""The phase theta(z) - z of an RKHP step or a composition of steps on the oscillator, its order and
leading constant (docs/theory.md §13, docs/stability.md)."""

from __future__ import annotations

from dataclasses import dataclass

import sympy

from ...base.errors import InputError
from ...base.expressions import parse_expression
from ..tableau import Tableau
from .field import Number, NumberField, Z, exact_number, tableau_field
from .series import m_series, theta_minus_z

#: largest order of the series of theta(z) - z
MAX_SERIES_ORDER = 41

#: the phase order is looked for up to this power of z (beyond the series order asked for)
PHASE_SEARCH_ORDER = 25


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
        return series_text([(k, parse_expression(c.exact, where="phase coefficient")) for k, c in terms])


def series_text(terms) -> str:
    """sum c_k z^k in increasing powers (``z + z^3/12 + 3*z^7/16384``), ``0`` for none."""
    expr = sum((c * Z**k for k, c in terms), sympy.Integer(0))
    if expr == 0:
        return "0"
    text = sympy.sstr(expr, order="rev-lex")
    return text.replace("**", "^")


def phase_of(F: NumberField, series_of, order: int) -> Phase:
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
    check_series_order(order)
    F = tableau_field(tableau)
    return phase_of(F, lambda n: theta_minus_z(F.K, m_series(F, n), n), order)


def composition_phase(tableau: Tableau, gammas, order: int = 9) -> Phase:
    """Phase of the composition of the RKHP step of `tableau` with substeps gamma_1 h, ...,
    gamma_s h (sympy numbers): the substeps are rotations about the same centre, so
    theta(z) = sum_i theta_base(gamma_i z) and the coefficient of z^k is theta_base's times
    sum_i gamma_i^k (docs/stability.md, "Compositions")."""
    check_series_order(order)
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

    return phase_of(F, series_of, order)


def check_series_order(order: int) -> None:
    if not 1 <= order <= MAX_SERIES_ORDER:
        raise InputError(f"the order of the phase series must be from 1 to {MAX_SERIES_ORDER}, got {order}")

