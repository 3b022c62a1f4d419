"""Whether an RKHP method is symmetric under a symmetric birealisation (docs/theory.md §12).

With beta(x, p) = alpha(x, -p), the step of generating function S_h maps y = alpha(x, dS(x)) to
y1 = alpha(x, -dS(x)); its inverse is the step of -S_h. The adjoint Phi*_h = Phi_{-h}^{-1} is
therefore the step of -S_{-h}, and the method is symmetric (Phi*_h = Phi_h) exactly when S_h is
odd in h. Over T_0, S_h = sum_t h^|t| a(t)/sigma(t) F(t) (paper Thm 5.1), so the method is
symmetric when, for every even order n, the vector (a(t)/sigma(t)), |t| = n, t in T_0, is a
relation of the symmetric class: sum_t a(t)/sigma(t) F(t) = 0 for every symmetric system
(docs/theory.md §8). With the rows sum_k w_k r(t_k) = 0 of the symmetric conditions (w_t =
P_t/(gamma(t) sigma(t)), P the annihilator of the relations), this reads
sum_k w_k gamma(t_k) a(t_k) = 0 for every row of even order.

RKHP Euler (a(t) = 0 beyond order 1) is symmetric; the exact flow is (its S_h is odd); the
relations ship up to order 8, so a tableau is found symmetric "up to order 8" at most.
"""

from __future__ import annotations

from dataclasses import dataclass
from fractions import Fraction

from ..trees.relations import MAX_SHIPPED_ORDER, symmetric_condition_rows
from .tableau import Tableau
from .verification import default_precision
from .weights import elementary_weights


@dataclass(frozen=True)
class Symmetry:
    """The symmetry of an RKHP method under a symmetric birealisation.

    Attributes:
        symmetric: True when the even-order parts of S_h vanish up to `checked_up_to`.
        checked_up_to: the highest order checked (MAX_SHIPPED_ORDER at most).
        fails_at: the first even order whose part of S_h is not zero, or None.
        precision: how the weights were computed ("exact", digits or "float").
    """

    symmetric: bool
    checked_up_to: int
    fails_at: int | None
    precision: str


def _is_zero(value, exact: bool) -> bool:
    if exact:
        return value == 0 if isinstance(value, (int, Fraction)) else bool(abs(value.evalf(50)) < 1e-40)
    return abs(float(value)) < 1e-12


def rkhp_symmetry(tableau: Tableau, max_order: int = MAX_SHIPPED_ORDER) -> Symmetry:
    """Whether the RKHP method of `tableau` is symmetric under a symmetric birealisation, checked
    on the even orders up to `max_order` (module docstring)."""
    top = min(max_order, MAX_SHIPPED_ORDER)
    precision = default_precision(tableau)
    exact = precision == "exact"
    weights = elementary_weights(tableau, top, precision)
    for n in range(2, top + 1, 2):
        for trees, row in symmetric_condition_rows(n):
            total = sum((w * t.gamma * weights[t] for w, t in zip(row, trees, strict=True)), Fraction(0))
            if not _is_zero(total, exact):
                return Symmetry(False, top, n, str(precision))
    return Symmetry(True, top, None, str(precision))
