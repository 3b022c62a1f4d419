"""Explicit tableaux on the oscillator, symmetric realisation: m(z) as an exact polynomial, theta(z) in
float64 and the wrap limit (docs/theory.md §13, docs/stability.md)."""

from __future__ import annotations

import math

import sympy

from ...base.errors import InputError
from ..tableau import Tableau
from .field import Number, Z, tableau_field
from .phase import polynomial_text
from .roots import first_positive_root

#: the explicit m(z) is written out exactly up to this many stages (its degree is 2^s - 1)
MAX_POLYNOMIAL_STAGES = 8


def m_polynomial(tableau: Tableau):
    """m(z) of an explicit tableau exactly (a sympy polynomial in z, degree at most 2^s - 1), or
    None for more than MAX_POLYNOMIAL_STAGES stages or a tableau known to its digits only."""
    if not tableau.is_explicit:
        raise InputError(f"{tableau.name} is {tableau.kind}: m(z) is a root of the stage equations")
    if tableau.stages > MAX_POLYNOMIAL_STAGES or not tableau.is_exact:
        return None
    F = tableau_field(tableau)
    K = F.K

    def const(x):
        return sympy.Poly.from_list([x], Z, domain=K)

    one, quarter, z = const(K.one), const(K.one / K.convert(4)), sympy.Poly(Z, Z, domain=K)
    ws = []
    for i in range(tableau.stages):
        mi = const(K.zero)
        for j in range(i):
            if F.A[i][j]:
                mi += ws[j] * const(F.A[i][j])
        mi = mi * z
        ws.append(one + mi * mi * quarter)
    m = const(K.zero)
    for bi, wi in zip(F.b, ws, strict=True):
        if bi:
            m += wi * const(bi)
    return m * sympy.Poly(Z, Z, domain=K)


def poly_text(p) -> str:
    """A polynomial in z in increasing powers."""
    return polynomial_text([(k[0], sympy.radsimp(c)) for k, c in zip(p.monoms(), p.coeffs(), strict=True)])


def wrap_limit_explicit(m) -> Number | None:
    """The largest z0 with theta = 2 arctan(m/2) strictly increasing on [0, z0]: the first positive
    root of odd multiplicity of m'(z); None when m increases on all of (0, oo) (theta then tends to
    +-pi without reaching it)."""
    K = m.get_domain()
    dm = m.diff(Z)
    sqf = sympy.Poly(dm.as_expr(), Z, domain=K).sqf_list()[1]
    odd = sympy.Poly(1, Z, domain=K)
    for factor, multiplicity in sqf:
        if multiplicity % 2:
            odd *= factor
    return first_positive_root(odd.as_expr(), K)


#: the numerical wrap limit (tableaux without an exact m(z)) is looked for on (0, WRAP_SCAN_Z]
WRAP_SCAN_Z = 20.0


def wrap_limit_numeric(tableau: Tableau) -> Number | None:
    """The wrap limit of an explicit tableau without an exact m(z) (more than MAX_POLYNOMIAL_STAGES
    stages, or decimals): the first z on a grid of step 10^-3 over (0, WRAP_SCAN_Z] where
    theta(z) = 2 arctan(m(z)/2) (float64) stops increasing, refined by bisection; None when theta
    increases over the whole scan."""
    import numpy as np

    zs = np.arange(1, int(WRAP_SCAN_Z * 1000) + 1) / 1000.0
    with np.errstate(all="ignore"):
        theta = np.array(explicit_angles(tableau.A_float, tableau.b_float, [float(z) for z in zs]))
    falls = np.nonzero(np.diff(theta) < -1e-10)[0]  # a fall beyond round-off near theta = pi
    if not len(falls):
        return None
    lo, hi = float(zs[max(falls[0] - 1, 0)]), float(zs[falls[0] + 1])

    def slope(z):
        up, down = explicit_angles(tableau.A_float, tableau.b_float, [z + 1e-7, z - 1e-7])
        return up - down

    for _ in range(60):
        mid = (lo + hi) / 2
        lo, hi = (mid, hi) if slope(mid) > 0 else (lo, mid)
    return Number(None, (lo + hi) / 2)


def explicit_angles(A, b, zs) -> list[float]:
    """theta(z) = 2 arctan(m(z)/2) of an explicit tableau at every z of ``zs`` at once: the stage
    maps m_i = z sum_j<i a_ij (1 + m_j^2/4) (docs/theory.md §13) as arrays over z, summed in the
    order of j as one z at a time would, arctan per z by `math.atan`."""
    import numpy as np

    z = np.asarray(zs, dtype=np.float64)
    weights = []  # 1 + m_j^2/4 of the stages so far
    for row in A:
        acc = np.zeros_like(z)
        for a, w in zip(row, weights):
            acc = acc + a * w
        m = z * acc
        weights.append(1 + m ** 2 / 4)
    total = np.zeros_like(z)
    for bi, w in zip(b, weights, strict=True):
        total = total + bi * w
    return [2.0 * math.atan(t / 2) for t in (z * total).tolist()]

