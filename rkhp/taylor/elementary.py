"""The Taylor coefficients of the elementary functions: ONE compiled recurrence per function.

`taylor_coefficients(code, u0, u0_lo, f, k, D, coef)` writes coef[q] = g^(q)(u0) / q!, q = 0..D,
for the univariate function g of a FUNCTION op (`rkhp.taylor.ops`): exp, log, sin, cos, sqrt,
atan, u^f (POWR), u^k for k < 0 (POWI), the reciprocal 1/u (for DIV) and c(u) (CRB). The interpreter
(`rkhp.taylor.rows`) composes these with the jet of u at degree D >= 1, and at degree 0 takes the
value coef[0]: the value-only path and the jet path are the same arithmetic by construction.
Adding an elementary function is one `rkhp.taylor.ops.OPS` row plus one branch here.

Outside a function's domain the coefficients are NaN (log and non-integer powers at u0 <= 0;
u^f at u0 = 0 has the value 0 for f > 0 at degree 0 only).
"""

from __future__ import annotations

import math

import numpy as np

from .compiler import NJIT_NORC
from .compiler import numba as nb
from .ops import ATAN, COS, CRB, DIV, EXP, LOG, POWI, POWR, SIN, SQRT


def _bernoulli_tables():
    import mpmath

    mpmath.mp.dps = 50
    phi = [mpmath.bernoulli(k) / mpmath.factorial(k) for k in range(200)]
    phi[1] = -phi[1]  # z / (1 - e^{-z}) has B_1^+ = +1/2
    # c's series minus its first pole's, 2 (4 pi^2)^-(j+1): the rest 2 (4 pi^2)^-(j+1) (zeta(2j+2)
    # - 1) cancels about 0.6 j digits (zeta(2j+2) - 1 ~ 4^-(j+1)), so 180 digits for j < 200
    with mpmath.workdps(180):
        series = [(-1) ** j * mpmath.bernoulli(2 * j + 2) / mpmath.factorial(2 * j + 2)
                  for j in range(200)]
        pole = 4 * mpmath.pi ** 2
        rest = [v - 2 / pole ** (j + 1) for j, v in enumerate(series)]
        pole_hi = float(pole)
        pole_lo = float(pole - pole_hi)
    return (np.array([float(v) for v in phi]), np.array([float(v) for v in series]),
            np.array([float(v) for v in rest]), pole_hi, pole_lo)


#: PHI_COEF[k]: Taylor coefficients of phi(z) = z / (1 - exp(-z)); radius 2 pi.
#: CRB_SERIES[j]: c(u) = sum_j CRB_SERIES[j] u^j, c(u) = (1 - (r/2) cot(r/2)) / r^2, u = r^2;
#: radius (2 pi)^2, the first pole. By the partial fractions of x cot x,
#: c(u) = 2 sum_{k >= 1} 1 / (4 pi^2 k^2 - u) = 2 / (CRB_POLE - u) + sum_j CRB_REST[j] u^j,
#: CRB_REST's radius 16 pi^2 (the second pole); CRB_POLE = (2 pi)^2 as CRB_POLE_HI + CRB_POLE_LO.
PHI_COEF, CRB_SERIES, CRB_REST, CRB_POLE_HI, CRB_POLE_LO = _bernoulli_tables()
CRB_SERIES_LIMIT = 20.0  # CRB_SERIES for |u| < 20 (ratio < 1/2 per term), pole + CRB_REST above
TWO_PI = 2.0 * math.pi


@nb.njit(**NJIT_NORC)
def taylor_coefficients(code, u0, u0_lo, f, k, D, coef):
    """coef[0..D]: the Taylor coefficients at u0 of the function of `code` (see the module);
    u0_lo: the low part of u0 as a double-double (CRB only), f and k: the row's parameters."""
    if code == EXP:
        e = math.exp(u0)
        fac = 1.0
        for q in range(D + 1):
            if q > 0:
                fac /= q
            coef[q] = e * fac
    elif code == LOG:
        coef[0] = math.log(u0) if u0 > 0.0 else np.nan
        for q in range(1, D + 1):
            coef[q] = (-1.0) ** (q + 1) / (q * u0 ** q)
    elif code == SIN or code == COS:
        shifted = u0 + (0.5 * math.pi if code == COS else 0.0)
        fac = 1.0
        for q in range(D + 1):
            if q > 0:
                fac /= q
            coef[q] = math.sin(shifted + 0.5 * math.pi * q) * fac
    elif code == SQRT or code == POWR:
        power = 0.5 if code == SQRT else f
        if u0 > 0.0:
            _pow_coef(u0, power, D, coef)
        elif u0 == 0.0 and D == 0 and power > 0.0:
            coef[0] = 0.0
        else:
            for q in range(D + 1):
                coef[q] = np.nan
    elif code == POWI:
        _pow_coef(u0, float(k), D, coef)
    elif code == DIV:
        _pow_coef(u0, -1.0, D, coef)
    elif code == CRB:
        crb_coef(u0, u0_lo, D, coef)
    elif code == ATAN:
        # atan'(u0 + v) = r(v) = 1 / (a + 2 u0 v + v^2), a = 1 + u0^2: a r_0 = 1, and
        # a r_k + 2 u0 r_{k-1} + r_{k-2} = 0; coef[q] = r_{q-1} / q
        coef[0] = math.atan(u0)
        a = 1.0 + u0 * u0
        r1 = r2 = 0.0  # r_{k-1}, r_{k-2}
        for q in range(1, D + 1):
            r = ((1.0 if q == 1 else 0.0) - 2.0 * u0 * r1 - r2) / a
            coef[q] = r / q
            r2, r1 = r1, r


@nb.njit(**NJIT_NORC)
def _pow_coef(u0, power, D, coef):
    coef[0] = u0 ** power
    for k in range(1, D + 1):
        coef[k] = coef[k - 1] * (power - k + 1) / (k * u0)


@nb.njit(**NJIT_NORC)
def two_prod(a, b):
    """a * b = p + e exactly (Dekker)."""
    p = a * b
    t = 134217729.0 * a
    ah = t - (t - a)
    al = a - ah
    t = 134217729.0 * b
    bh = t - (t - b)
    bl = b - bh
    return p, ((ah * bh - p) + ah * bl + al * bh) + al * bl


@nb.njit(**NJIT_NORC)
def crb_coef(u0, u_lo, D, coef):
    """Taylor coefficients at u0 of c(u) = (1 - (sqrt(u)/2) cot(sqrt(u)/2)) / u (docs/theory.md
    §4).

    Power series (exact to round-off) for |u0| < 20; for 20 <= u0 < (2 pi)^2 the first pole's
    part 2 / (4 pi^2 - u) plus the rest's power series CRB_REST (radius 16 pi^2, all terms
    positive), with d = 4 pi^2 - u from u0 + u_lo in double-double (4 pi^2 - u0 is exact, Sterbenz);
    NaN beyond the first pole u = (2 pi)^2 and for u0 <= -20.
    """
    series = CRB_SERIES
    pole, d = 0.0, 1.0  # 2 / d^(m+1): the m-th Taylor coefficient of 2 / (4 pi^2 - u) at u0
    if not abs(u0) < CRB_SERIES_LIMIT:
        d = (CRB_POLE_HI - u0) + (CRB_POLE_LO - u_lo)
        if not (u0 > 0.0 and d > 0.0):
            for m in range(D + 1):
                coef[m] = np.nan
            return
        series = CRB_REST
        pole = 2.0 / d
    for m in range(D + 1):
        s = 0.0  # sum_{j >= m} series[j] binom(j, m) u0^(j - m), to a relative 1e-18
        weight = 1.0  # binom(j, m) u0^(j - m)
        for j in range(m, series.shape[0]):
            term = series[j] * weight
            s += term
            if j > m + 2 and abs(term) <= 1e-18 * abs(s):
                break
            weight *= u0 * (j + 1) / (j + 1 - m)
        coef[m] = pole + s
        pole /= d
