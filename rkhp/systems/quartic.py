"""The ``quartic`` realisation: degenerate but not symmetric (docs/theory.md §8).

Every system's base birealisation (alpha, beta) is symmetric, beta(x, p) = alpha(x, -p). The
quartic realisation composes it with the time-1 flow of the Hamiltonian K(p) on T*M, the
symplectomorphism (x, p) -> (x + grad K(p), p) that fixes the zero section:

    alpha''(x, p) = alpha(x + grad K(p), p),   beta''(x, p) = beta(x + grad K(p), p),

    K(p) = sum_k (u_k . p)^4 / 24,   grad K(p) = sum_k u_k (u_k . p)^3 / 6,

with the fixed directions, in dimension n, u_k = e_k (k = 1..n, the coordinate axes) and
u_{n+1} = (1, 1, ..., 1). Since grad K(p) = O(|p|^3), d_p alpha''(x, 0) = d_p alpha(x, 0) stays
antisymmetric: the realisation is degenerate (paper, eq. (degen)), the trees outside T_0 still
vanish and the degenerate order conditions suffice. But grad K is odd, so
alpha''(x, -p) = beta(x - grad K(p), p) differs from beta''(x, p): the realisation is not
symmetric and the relations of docs/theory.md §8 among the F(t) fail (already at order 4). A method with
symmetric order q but degenerate order d < q drops to order d here, while a method of degenerate
order q keeps it.
"""

from __future__ import annotations

from fractions import Fraction

from .core import register_realisation

SIXTH = Fraction(1, 6)
"""Exact, so that the exact elementary differentials (`rkhp.series.differentials`) read 1/6; a tape
Var reads it as the float 1/6."""


def quartic_directions(n: int) -> list[tuple[float, ...]]:
    """The directions u_k of K(p) = sum_k (u_k . p)^4 / 24 in dimension n: e_1..e_n, (1,...,1)."""
    axes = [tuple(1.0 if i == k else 0.0 for i in range(n)) for k in range(n)]
    return axes + [tuple(1.0 for _ in range(n))]


def quartic_shift(p):
    """grad K(p) = sum_k u_k (u_k . p)^3 / 6 over tape Vars p (a list of n Vars)."""
    n = len(p)
    shift = [None] * n
    for u in quartic_directions(n):
        terms = [p[j] * u[j] if u[j] != 1.0 else p[j] for j in range(n) if u[j] != 0.0]
        up = sum(terms[1:], terms[0])
        cube = (up * up * up) * SIXTH
        for i in range(n):
            if u[i] != 0.0:
                term = cube * u[i]
                shift[i] = term if shift[i] is None else shift[i] + term
    return shift


register_realisation(
    "quartic", quartic_shift, True,
    "alpha(x + grad K(p), p), K(p) = sum_k (u_k . p)^4 / 24, u_k = e_1..e_n and (1,...,1): "
    "degenerate, not symmetric (docs/theory.md §8)")
