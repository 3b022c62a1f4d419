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

from .compiler import NJIT, NJIT_NORC, NJIT_NRT
from .compiler import numba as nb
from .ops import ATAN, COS, CRB, DIV, EXP, LOG, POWI, POWR, SIN, SQRT


def _bernoulli_tables():
    import mpmath

    mpmath.mp.dps = 50
    phi = [mpmath.bernoulli(k) / mpmath.factorial(k) for k in range(200)]
    phi[1] = -phi[1]  # z / (1 - e^{-z}) has B_1^+ = +1/2
    series = [(-1) ** j * mpmath.bernoulli(2 * j + 2) / mpmath.factorial(2 * j + 2)
              for j in range(200)]
    return np.array([float(v) for v in phi]), np.array([float(v) for v in series])


#: PHI_COEF[k]: Taylor coefficients of phi(z) = z / (1 - exp(-z)); radius 2 pi.
#: CRB_SERIES[j]: c(u) = sum_j CRB_SERIES[j] u^j, c(u) = (1 - (r/2) cot(r/2)) / r^2, u = r^2.
PHI_COEF, CRB_SERIES = _bernoulli_tables()
CRB_SERIES_LIMIT = 20.0  # series for |u| < 20 (ratio < 1/2 per term), closed form above
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


@nb.njit(**NJIT)
def _uni_mul(a, b, D):
    c = np.zeros(D + 1)
    for i in range(D + 1):
        for j in range(D + 1 - i):
            c[i + j] += a[i] * b[j]
    return c


@nb.njit(**NJIT)
def _uni_compose(coef, a, D):
    v = a.copy()
    v[0] = 0.0
    r = np.zeros(D + 1)
    r[0] = coef[D]
    for k in range(D - 1, -1, -1):
        r = _uni_mul(r, v, D)
        r[0] += coef[k]
    return r


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
def _crb_value(u_hi, u_lo):
    """c(u) for 20 <= u < (2 pi)^2 from u = u_hi + u_lo (double-double): near the pole r = 2 pi
    cot is ill-conditioned, so r = sqrt(u) is carried to double-double accuracy."""
    r = math.sqrt(u_hi)
    p, e = two_prod(r, r)
    r_lo = ((u_hi - p) - e + u_lo) / (2.0 * r)
    w = 0.5 * r
    w_lo = 0.5 * r_lo
    sw = math.sin(w)
    cot = math.cos(w) / sw
    wcot = w * (cot - w_lo / (sw * sw)) + w_lo * cot
    return (1.0 - wcot) / u_hi * (1.0 - u_lo / u_hi)


@nb.njit(**NJIT_NRT)
def crb_coef(u0, u_lo, D, coef):
    """Taylor coefficients at u0 of c(u) = (1 - (sqrt(u)/2) cot(sqrt(u)/2)) / u (docs/theory.md
    §4).

    Power series (exact to round-off) for |u0| < 20; closed form in univariate jets for
    20 <= u0 < (2 pi)^2, the value from u0 + u_lo in double-double; NaN beyond the first pole
    u = (2 pi)^2.
    """
    if abs(u0) < CRB_SERIES_LIMIT:
        for m in range(D + 1):
            s = 0.0
            weight = 1.0  # binom(j, m) u0^(j - m)
            for j in range(m, CRB_SERIES.shape[0]):
                term = CRB_SERIES[j] * weight
                s += term
                if j > m + 2 and abs(term) <= 1e-18 * abs(s):
                    break
                weight *= u0 * (j + 1) / (j + 1 - m)
            coef[m] = s
        return
    if not (u0 < TWO_PI * TWO_PI):
        for m in range(D + 1):
            coef[m] = np.nan
        return
    c = np.zeros(D + 1)
    u = np.zeros(D + 1)
    u[0] = u0
    if D >= 1:
        u[1] = 1.0
    _pow_coef(u0, 0.5, D, c)
    w = _uni_compose(c, u, D) * 0.5
    w0 = w[0]
    sc = np.zeros(D + 1)
    cc = np.zeros(D + 1)
    f = 1.0
    for k in range(D + 1):
        if k > 0:
            f /= k
        sc[k] = math.sin(w0 + 0.5 * math.pi * k) * f
        cc[k] = math.cos(w0 + 0.5 * math.pi * k) * f
    sw = _uni_compose(sc, w, D)
    cw = _uni_compose(cc, w, D)
    _pow_coef(sw[0], -1.0, D, c)
    cot = _uni_mul(cw, _uni_compose(c, sw, D), D)
    num = -_uni_mul(w, cot, D)
    num[0] += 1.0
    _pow_coef(u0, -1.0, D, c)
    res = _uni_mul(num, _uni_compose(c, u, D), D)
    for m in range(D + 1):
        coef[m] = res[m]
    coef[0] = _crb_value(u0, u_lo)
