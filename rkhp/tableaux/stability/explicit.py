"""Explicit tableaux on the oscillator, symmetric realisation: m(z) as an exact polynomial, theta(z) in
float64 and the wrap limit (docs/theory.md §13, docs/stability.md)."""

from __future__ import annotations

import math
from typing import NamedTuple

import sympy

from ...base.errors import InputError
from ..tableau import Tableau
from .field import Number, Z, tableau_field
from .phase import series_text
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
    return series_text([(k[0], sympy.radsimp(c)) for k, c in zip(p.monoms(), p.coeffs(), strict=True)])


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


#: the numerical wrap limit (tableaux without an exact m(z)) is looked for on (0, WRAP_SCAN_Z] on a
#: grid of step WRAP_SCAN_STEP
WRAP_SCAN_Z = 20.0
WRAP_SCAN_STEP = 1e-3


class Scaled(NamedTuple):
    """Numbers mantissa 2^exponent as arrays (float64 mantissas in [1/2, 1) or 0, int64 exponents):
    float64's precision without its range. m(z) of an s-stage tableau has degree 2^s - 1 and passes
    10^308 at z of a few units from about 15 stages on; its slope's sign stays readable."""

    mantissa: object
    exponent: object


def _scaled(x, exponent=0) -> Scaled:
    import numpy as np

    mantissa, shift = np.frexp(x)
    return Scaled(mantissa, shift.astype(np.int64) + exponent)


def _scaled_add(u: Scaled, v: Scaled) -> Scaled:
    import numpy as np

    top = np.maximum(u.exponent, v.exponent)
    return _scaled(np.ldexp(u.mantissa, u.exponent - top) + np.ldexp(v.mantissa, v.exponent - top), top)


def _scaled_mul(u: Scaled, v: Scaled) -> Scaled:
    return _scaled(u.mantissa * v.mantissa, u.exponent + v.exponent)


def _scaled_times(c: float, u: Scaled) -> Scaled:
    return _scaled(c * u.mantissa, u.exponent)


def m_and_slope(A, b, zs) -> tuple[Scaled, Scaled]:
    """m(z) and m'(z) of an explicit tableau at every z of ``zs`` (Scaled arrays): the stage maps
    m_i = z S_i, S_i = sum_j<i a_ij (1 + m_j^2/4) (docs/theory.md §13) and their derivatives
    m_i' = S_i + z sum_j<i a_ij m_j m_j'/2, as arrays over z."""
    import numpy as np

    z = _scaled(np.asarray(zs, dtype=np.float64))
    zero, one = _scaled(np.zeros_like(z.mantissa)), _scaled(np.ones_like(z.mantissa))

    def sums(row, ws, dws):
        total, slope = zero, zero
        for a, w, dw in zip(row, ws, dws):
            if a:
                total, slope = _scaled_add(total, _scaled_times(a, w)), _scaled_add(slope, _scaled_times(a, dw))
        return _scaled_mul(z, total), _scaled_add(total, _scaled_mul(z, slope))

    ws, dws = [], []  # 1 + m_j^2/4 and its derivative m_j m_j'/2
    for row in A:
        m, dm = sums(row, ws, dws)
        ws.append(_scaled_add(one, _scaled_times(0.25, _scaled_mul(m, m))))
        dws.append(_scaled_times(0.5, _scaled_mul(m, dm)))
    return sums(b, ws, dws)


def wrap_limit_numeric(tableau: Tableau) -> Number | None:
    """The wrap limit of an explicit tableau without an exact m(z) (more than MAX_POLYNOMIAL_STAGES
    stages, or decimals): the first z of a grid of step WRAP_SCAN_STEP over (0, WRAP_SCAN_Z] where
    m'(z) < 0 (`m_and_slope`: float64 digits, unbounded exponent), the sign change of m' before it
    bisected to float64; None when m' stays positive over the scan. theta = 2 arctan(m/2) itself is
    no guide: near its maximum it is within 4/m of pi, below float64's resolution of pi once m
    passes about 10^16."""
    import numpy as np

    A, b = tableau.A_float, tableau.b_float
    zs = np.arange(1, round(WRAP_SCAN_Z / WRAP_SCAN_STEP) + 1) * WRAP_SCAN_STEP
    falls = np.nonzero(m_and_slope(A, b, zs)[1].mantissa < 0)[0]
    if not len(falls):
        return None
    lo, hi = (float(zs[falls[0] - 1]) if falls[0] else 0.0), float(zs[falls[0]])
    while True:
        mid = (lo + hi) / 2
        if not lo < mid < hi:
            return Number(None, mid)
        lo, hi = (mid, hi) if m_and_slope(A, b, [mid])[1].mantissa[0] > 0 else (lo, mid)


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

