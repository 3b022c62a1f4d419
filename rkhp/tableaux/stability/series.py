"""Truncated power series in z (lists of elements of a number field K, index = power of z) and the
series of m(z) and theta(z) - z of an RKHP step on the oscillator (docs/theory.md §13)."""

from __future__ import annotations

import sympy

from ...base.errors import NumericalFailure
from .field import NumberField


def mul(K, u, v, n):
    """Product of two series (lists of K elements, index = power of z) truncated after z^n."""
    out = [K.zero] * (n + 1)
    for i, ui in enumerate(u[: n + 1]):
        if not ui:
            continue
        for j, vj in enumerate(v[: n + 1 - i]):
            if vj:
                out[i + j] += ui * vj
    return out


def add(K, u, v, n):
    u = list(u) + [K.zero] * (n + 1 - len(u))
    v = list(v) + [K.zero] * (n + 1 - len(v))
    return [x + y for x, y in zip(u[: n + 1], v[: n + 1], strict=True)]


def scale(c, u):
    return [c * x for x in u]


def shift(K, u, n):
    """z u(z), truncated after z^n."""
    return ([K.zero] + list(u))[: n + 1]


def divide(K, num, den, n):
    """The series of num/den (coefficient lists, den[0] != 0) to z^n."""
    num = list(num) + [K.zero] * (n + 1)
    out = []
    for k in range(n + 1):
        acc = num[k] - sum((out[j] * den[k - j] for j in range(max(0, k - len(den) + 1), k)), K.zero)
        out.append(acc / den[0])
    return out


def sqrt(K, v, n):
    """The series of sqrt(v) to z^n, v[0] a square in K (here 1/4)."""
    root0 = sympy.sqrt(K.to_sympy(v[0]))
    if not root0.is_Rational:
        raise NumericalFailure(f"tr R(z) = 2 - {4 * K.to_sympy(v[0])} z^2 + ...: sum b_i != 1")
    out = [K.from_sympy(root0)]
    for k in range(1, n + 1):
        acc = v[k] - sum((out[j] * out[k - j] for j in range(1, k)), K.zero)
        out.append(acc / (K.convert(2) * out[0]))
    return out


def _stage_map(F: NumberField, ms, n):
    """One application of m_i <- z sum_j a_ij (1 + m_j^2/4) to series ms (truncated after z^n)."""
    K = F.K
    quarter = K.one / K.convert(4)
    w = [add(K, [K.one], scale(quarter, mul(K, m, m, n)), n) for m in ms]
    out = []
    for row in F.A:
        acc = [K.zero] * (n + 1)
        for a, wj in zip(row, w, strict=True):
            if a:
                acc = add(K, acc, scale(a, wj), n)
        out.append(shift(K, acc, n))
    total = [K.zero] * (n + 1)
    for bi, wi in zip(F.b, w, strict=True):
        if bi:
            total = add(K, total, scale(bi, wi), n)
    return out, shift(K, total, n)


def m_series(F: NumberField, n: int) -> list:
    """The series of m(z) to z^n on the branch through m(0) = 0 (explicit or implicit): each
    application of the stage map gains one power of z, so n + 1 applications from 0 suffice."""
    K = F.K
    ms = [[K.zero] * (n + 1) for _ in F.b]
    m = [K.zero] * (n + 1)
    for _ in range(n + 2):
        ms, m = _stage_map(F, ms, n)
    return m


def theta_minus_z(K, m, n: int) -> list:
    """Series of 2 arctan(m/2) - z to z^n, m = O(z) (arctan u = sum (-1)^k u^(2k+1)/(2k+1))."""
    half = K.one / K.convert(2)
    u = scale(half, m)
    u2 = mul(K, u, u, n)
    power = u
    total = [K.zero] * (n + 1)
    k = 0
    while any(power):
        coef = K.convert(2 * (-1) ** k) / K.convert(2 * k + 1)
        total = add(K, total, scale(coef, power), n)
        power = mul(K, power, u2, n)
        k += 1
    if n >= 1:
        total[1] -= K.one
    return total


def phase_coefficients_numeric(A, b, n: int):
    """theta(z) - z to z^n for numeric A, b (float64, or mpmath numbers in object arrays): the series
    of m from n + 2 applications of the stage map, explicit and implicit alike; a numpy array,
    index = power of z."""
    import numpy as np

    dtype = np.asarray(b).dtype
    zero = np.zeros(n + 1, dtype=dtype) * b[0]

    def mul_numeric(u, v):
        out = zero.copy()
        for i in range(n + 1):
            if u[i]:
                out[i:] += u[i] * v[: n + 1 - i]
        return out

    def shift_numeric(u):
        out = zero.copy()
        out[1:] = u[:n]
        return out

    s = len(b)
    ms = [zero.copy() for _ in range(s)]
    m = zero.copy()
    for _ in range(n + 2):
        w = [mul_numeric(mi, mi) / 4 for mi in ms]
        for wi in w:
            wi[0] += 1
        ms = [shift_numeric(sum((A[i][j] * w[j] for j in range(s)), zero.copy())) for i in range(s)]
        m = shift_numeric(sum((b[i] * w[i] for i in range(s)), zero.copy()))
    u = m / 2
    u2 = mul_numeric(u, u)
    total, power, k = zero.copy(), u, 0
    while k <= n:
        total = total + power * (2 * (-1) ** k) / (2 * k + 1)
        power = mul_numeric(power, u2)
        k += 1
    total[1] -= 1
    return total

