"""Truncated multivariate Taylor arithmetic ("jets") and the compiled tape interpreter (docs/theory.md §7).

A jet in m variables truncated at total degree D is the array of its Taylor coefficients over the
monomials of degree <= D, in graded order (degree 0, then the m monomials of degree 1 in the order
of the variables, ...). Products run over a precomputed list of index pairs sorted by the degree of
the result, so truncating at any D <= Dmax uses a prefix of every table. Univariate functions of a
jet u = u0 + v are evaluated by Horner's rule on their Taylor coefficients at u0:
f(u) = sum_k f^(k)(u0)/k! v^k (v has no constant term, so the sum stops at k = D).

Everything here is compiled with numba (`cache=True`; compiled code persists in numba's cache,
see `rkhp.integrators.cache`). The interpreter takes tapes as data (`rkhp.systems.tape`). The
kernels of the engine's step loop allocate nothing and are compiled without reference counting
(NJIT_NORC); crb_coef, whose closed form allocates, keeps it (NJIT_NRT).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from functools import lru_cache
from math import comb

import numpy as np

from ..systems.tape import (
    ADD,
    ADDC,
    CONST,
    COS,
    CRB,
    DIV,
    EXP,
    LOG,
    MUL,
    MULC,
    NEG,
    PHIMV,
    POWI,
    POWR,
    SIN,
    SQRT,
    SUB,
)
from .cache import numba as nb

NJIT = dict(cache=True, nogil=True, fastmath=False, error_model="numpy")
# Calls between compiled functions pass integers as np.int64(...), never as bare literals: numba
# compiles a separate specialisation for every literal value (measured: 10 of jet_mul).
#: Kernels of the step loop that allocate nothing: compiled without numba's reference counting
#: (its incref/decref of every array argument was about a fifth of a step). A function compiled
#: so may only call functions that allocate nothing, or ones that set NJIT_NRT (below): callees
#: without an explicit setting inherit the caller's.
NJIT_NORC = dict(NJIT, _nrt=False)
#: Functions that allocate and are called from NJIT_NORC kernels (e.g. crb_coef's closed form).
NJIT_NRT = dict(NJIT, _nrt=True)


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


@dataclass(frozen=True, eq=False)
class JetSpace:
    """Tables for jets in `n_vars` variables truncated at degree <= `degree`.

    counts[d]: number of monomials of degree <= d; the product pairs (pa[t], pb[t]) of monomial c
    are t in start[c]:start[c + 1]; up[m, k]: index of m + e_k (0 where deg m = degree);
    expo[m, k]: exponent of variable k in monomial m. Index tables are unsigned (see jet_mul).
    """

    n_vars: int
    degree: int
    counts: np.ndarray
    start: np.ndarray
    pa: np.ndarray
    pb: np.ndarray
    up: np.ndarray
    expo: np.ndarray

    def packed(self):
        return (self.counts, self.start, self.pa, self.pb, self.pa, self.up, self.expo)

    @property
    def size(self) -> int:
        return int(self.counts[-1])


def _monomials(n: int, degree: int) -> list[tuple[int, ...]]:
    out: list[tuple[int, ...]] = []

    def rec(prefix, left, k):
        if k == n - 1:
            out_d.append(prefix + (left,))
            return
        for e in range(left, -1, -1):
            rec(prefix + (e,), left - e, k + 1)

    for d in range(degree + 1):
        out_d: list[tuple[int, ...]] = []
        if n == 0:
            out_d.append(())
        else:
            rec((), d, 0)
        out.extend(out_d)
    return out


@lru_cache(maxsize=64)
def jet_space(n_vars: int, degree: int) -> JetSpace:
    """The tables for jets in `n_vars` variables up to total degree `degree` (cached)."""
    monos = _monomials(n_vars, degree)
    index = {m: i for i, m in enumerate(monos)}
    deg = [sum(m) for m in monos]
    counts = np.array([comb(n_vars + d, d) for d in range(degree + 1)], dtype=np.int64)
    pairs = []
    for i, mi in enumerate(monos):
        for j, mj in enumerate(monos):
            if deg[i] + deg[j] <= degree:
                k = index[tuple(a + b for a, b in zip(mi, mj, strict=True))]
                pairs.append((k, i, j))
    pairs.sort()
    arr = np.array(pairs, dtype=np.int64).reshape(-1, 3)
    start = np.searchsorted(arr[:, 0], np.arange(len(monos) + 1)).astype(np.uint64)
    up = np.zeros((len(monos), max(n_vars, 1)), dtype=np.uint64)
    expo = np.zeros((len(monos), max(n_vars, 1)), dtype=np.int64)
    for i, m in enumerate(monos):
        for k in range(n_vars):
            expo[i, k] = m[k]
            if deg[i] < degree:
                up[i, k] = index[tuple(e + (1 if q == k else 0) for q, e in enumerate(m))]
    return JetSpace(n_vars, degree, counts, start, arr[:, 1].astype(np.uint64),
                    arr[:, 2].astype(np.uint64), up, expo)


# ----------------------------------------------------------------------------------------------
# jet kernels


@nb.njit(**NJIT_NORC)
def jet_mul(X, i, Y, j, Z, k, D, space):
    """Z[k] = X[i] * Y[j] truncated at degree D (rows of 2-d arrays; Z[k] not X[i] or Y[j]).

    Rows are passed as (array, index), not as views: a view costs reference counting. The pair
    tables are unsigned, so that indexing skips the negative-index wrap-around (both measured:
    together about 1.7x on the tower). Two partial sums (even and odd pairs) halve the chain of
    dependent additions (the sum's rounding differs from the sequential one at round-off level).
    """
    counts, start, pa, pb = space[0], space[1], space[2], space[3]
    one = np.uint64(1)
    for c in range(counts[D]):
        hi = start[c + 1]
        acc0 = 0.0
        acc1 = 0.0
        t = start[c]
        while t + one < hi:
            acc0 += X[i, pa[t]] * Y[j, pb[t]]
            acc1 += X[i, pa[t + one]] * Y[j, pb[t + one]]
            t += np.uint64(2)
        if t < hi:
            acc0 += X[i, pa[t]] * Y[j, pb[t]]
        Z[k, c] = acc0 + acc1


@nb.njit(inline="always", **NJIT_NORC)
def jet_compose(coef, X, i, Z, k, D, space, S):
    """Z[k] = sum_q coef[q] (X[i] - X[i, 0])^q truncated at degree D (Horner; scratch rows
    S[0:3]; Z[k] may be X[i])."""
    M = space[0][D]
    for m in range(M):
        S[0, m] = X[i, m]
        S[1, m] = 0.0
    S[0, 0] = 0.0
    S[1, 0] = coef[D]
    for q in range(D - 1, -1, -1):
        jet_mul(S, np.int64(1), S, np.int64(0), S, np.int64(2), D - q, space)
        for m in range(space[0][D - q]):
            S[1, m] = S[2, m]
        S[1, 0] += coef[q]
    for m in range(M):
        Z[k, m] = S[1, m]


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
def _two_prod(a, b):
    """a * b = p + e exactly (Dekker)."""
    p = a * b
    t = 134217729.0 * a
    ah = t - (t - a)
    al = a - ah
    t = 134217729.0 * b
    bh = t - (t - b)
    bl = b - bh
    return p, ((ah * bh - p) + ah * bl + al * bh) + al * bl


@nb.njit(inline="always", **NJIT_NORC)
def _sum_of_squares(W, args, start, count):
    """sum_i W[args[start + i], 0]^2 as a double-double (hi, lo)."""
    hi = 0.0
    lo = 0.0
    for i in range(count):
        v = W[args[start + i], 0]
        p, e = _two_prod(v, v)
        s = hi + p
        bb = s - hi
        lo += (hi - (s - bb)) + (p - bb) + e
        hi = s
    s = hi + lo
    return s, lo - (s - hi)


@nb.njit(**NJIT_NORC)
def _crb_value(u_hi, u_lo):
    """c(u) for 20 <= u < (2 pi)^2 from u = u_hi + u_lo (double-double): near the pole r = 2 pi
    cot is ill-conditioned, so r = sqrt(u) is carried to double-double accuracy."""
    r = math.sqrt(u_hi)
    p, e = _two_prod(r, r)
    r_lo = ((u_hi - p) - e + u_lo) / (2.0 * r)
    w = 0.5 * r
    w_lo = 0.5 * r_lo
    sw = math.sin(w)
    cot = math.cos(w) / sw
    wcot = w * (cot - w_lo / (sw * sw)) + w_lo * cot
    return (1.0 - wcot) / u_hi * (1.0 - u_lo / u_hi)


@nb.njit(**NJIT_NRT)
def crb_coef(u0, u_lo, D, coef):
    """Taylor coefficients at u0 of c(u) = (1 - (sqrt(u)/2) cot(sqrt(u)/2)) / u (docs/theory.md §4).

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


@nb.njit(**NJIT_NORC)
def _phimv(W, out, start, n, args, D, space, S):
    """phi(K) x by its power series sum_k PHI_COEF[k] K^k x, for ||K0||_F < 0.9 * 2 pi."""
    M = space[0][D]
    norm = 0.0
    for i in range(n * n):
        norm += W[args[start + i], 0] ** 2
    norm = math.sqrt(norm)
    ratio = norm / TWO_PI
    if not (ratio < 0.9):
        for i in range(n):
            for m in range(M):
                W[out + i, m] = np.nan
        return
    # K^k x has degree-m coefficients of size ~ binom(k, m) |K0|^(k-m): keep every k <= D, then
    # stop when the tail bound is below round-off
    terms = max(D, 1)
    while terms < PHI_COEF.shape[0] - 1:
        if 2.0 * (terms + 1.0) ** D * ratio ** (terms + 1 - D) < 1e-18:
            break
        terms += 1
    # scratch rows 3..3+n: v = K^k x; rows 3+n..3+2n: K v; row 3+2n: one product
    acc = 3 + 2 * n
    for i in range(n):
        xi = args[start + n * n + i]
        for m in range(M):
            S[3 + i, m] = W[xi, m]
            W[out + i, m] = W[xi, m]
    for k in range(1, terms + 1):
        for i in range(n):
            for m in range(M):
                S[3 + n + i, m] = 0.0
            for j in range(n):
                jet_mul(W, args[start + i * n + j], S, 3 + j, S, acc, D, space)
                for m in range(M):
                    S[3 + n + i, m] += S[acc, m]
        c = PHI_COEF[k]
        for i in range(n):
            for m in range(M):
                S[3 + i, m] = S[3 + n + i, m]
                W[out + i, m] += c * S[3 + i, m]


@nb.njit(**NJIT)
def run_tape(tape, W, D, space, S):
    """Evaluate a tape at truncation degree D; inputs are W[0:n_inputs] (already set).

    S: scratch rows (`scratch_rows(n)` of them, n the system's dimension); its last row holds
    the Taylor coefficients of the univariate functions.
    """
    run_tape_into(tape, W, D, space, S, np.empty(W.shape[0], dtype=np.int64))


@nb.njit(**NJIT_NORC)
def run_tape_into(tape, W, D, space, S, deg):
    """`run_tape` with the caller's work array deg (>= W.shape[0] int64): no allocation in the
    engine's step loop."""
    if D == 0:
        _run_values(tape, W, space, S)
        return
    ops, fpar, args = tape[0], tape[1], tape[2]
    counts = space[0]
    M = counts[D]
    coef = S[S.shape[0] - 1]
    if ops.shape[0] == 0:
        return
    # deg[slot]: a bound on the degree of the slot's polynomial (inputs: read off their
    # coefficients), so that products of low-degree values (e.g. H of x0 + dx) stop early
    for row in range(ops[0, 1]):
        d = D
        while d > 0:
            nonzero = False
            for m in range(counts[d - 1], counts[d]):
                if W[row, m] != 0.0:
                    nonzero = True
                    break
            if nonzero:
                break
            d -= 1
        deg[row] = d
    for r in range(ops.shape[0]):
        code, out, a, b, k = ops[r, 0], ops[r, 1], ops[r, 2], ops[r, 3], ops[r, 4]
        deg[out] = D
        if code == MUL:
            dd = min(D, deg[a] + deg[b])
            jet_mul(W, a, W, b, W, out, dd, space)
            for m in range(counts[dd], M):
                W[out, m] = 0.0
            deg[out] = dd
        elif code == ADD or code == SUB:
            deg[out] = max(deg[a], deg[b])
            if code == ADD:
                for m in range(M):
                    W[out, m] = W[a, m] + W[b, m]
            else:
                for m in range(M):
                    W[out, m] = W[a, m] - W[b, m]
        elif code == MULC:
            deg[out] = deg[a]
            f = fpar[r]
            for m in range(M):
                W[out, m] = f * W[a, m]
        elif code == ADDC:
            deg[out] = deg[a]
            for m in range(M):
                W[out, m] = W[a, m]
            W[out, 0] += fpar[r]
        elif code == CONST:
            deg[out] = 0
            for m in range(M):
                W[out, m] = 0.0
            W[out, 0] = fpar[r]
        elif code == NEG:
            deg[out] = deg[a]
            for m in range(M):
                W[out, m] = -W[a, m]
        elif code == DIV:
            _pow_coef(W[b, 0], -1.0, D, coef)
            jet_compose(coef, W, b, S, np.int64(3), D, space, S)
            jet_mul(W, a, S, np.int64(3), W, out, D, space)
        elif code == EXP:
            e = math.exp(W[a, 0])
            f = 1.0
            for q in range(D + 1):
                if q > 0:
                    f /= q
                coef[q] = e * f
            jet_compose(coef, W, a, W, out, D, space, S)
        elif code == LOG:
            u0 = W[a, 0]
            coef[0] = math.log(u0) if u0 > 0.0 else np.nan
            for q in range(1, D + 1):
                coef[q] = (-1.0) ** (q + 1) / (q * u0 ** q)
            jet_compose(coef, W, a, W, out, D, space, S)
        elif code == SIN or code == COS:
            u0 = W[a, 0] + (0.5 * math.pi if code == COS else 0.0)
            f = 1.0
            for q in range(D + 1):
                if q > 0:
                    f /= q
                coef[q] = math.sin(u0 + 0.5 * math.pi * q) * f
            jet_compose(coef, W, a, W, out, D, space, S)
        elif code == SQRT or code == POWR:
            u0 = W[a, 0]
            power = 0.5 if code == SQRT else fpar[r]
            if u0 > 0.0:
                _pow_coef(u0, power, D, coef)
            elif u0 == 0.0 and D == 0 and power > 0.0:
                coef[0] = 0.0
            else:
                for q in range(D + 1):
                    coef[q] = np.nan
            jet_compose(coef, W, a, W, out, D, space, S)
        elif code == POWI:
            if k == 0:
                for m in range(M):
                    W[out, m] = 0.0
                W[out, 0] = 1.0
                deg[out] = 0
            elif k > 0:
                for m in range(M):
                    S[3, m] = W[a, m]
                for _ in range(k - 1):
                    jet_mul(S, np.int64(3), W, a, W, out, D, space)
                    for m in range(M):
                        S[3, m] = W[out, m]
                for m in range(M):
                    W[out, m] = S[3, m]
                deg[out] = min(D, k * deg[a])
            else:
                _pow_coef(W[a, 0], float(k), D, coef)
                jet_compose(coef, W, a, W, out, D, space, S)
        elif code == CRB:
            u_hi, u_lo = W[a, 0], 0.0
            if b >= 0:  # u = |p|^2 with p in args[b : b + k]: recompute u0 in double-double
                u_hi, u_lo = _sum_of_squares(W, args, b, k)
            crb_coef(u_hi, u_lo, D, coef)
            jet_compose(coef, W, a, W, out, D, space, S)
        elif code == PHIMV:
            _phimv(W, out, a, k, args, D, space, S)
            for i in range(k):
                deg[out + i] = D


@nb.njit(**NJIT_NORC)
def _run_values(tape, W, space, S):
    """`run_tape` at degree 0 (values only, W[:, 0]): the same floating-point operations as the
    jet kernels at D = 0, without their loops, degree bounds and scratch rows (the engine's
    value-only evaluations of alpha and beta)."""
    ops, fpar, args = tape[0], tape[1], tape[2]
    coef = S[S.shape[0] - 1]
    for r in range(ops.shape[0]):
        code, out, a, b, k = ops[r, 0], ops[r, 1], ops[r, 2], ops[r, 3], ops[r, 4]
        if code == MUL:
            W[out, 0] = 0.0 + W[a, 0] * W[b, 0]
        elif code == ADD:
            W[out, 0] = W[a, 0] + W[b, 0]
        elif code == SUB:
            W[out, 0] = W[a, 0] - W[b, 0]
        elif code == MULC:
            W[out, 0] = fpar[r] * W[a, 0]
        elif code == ADDC:
            W[out, 0] = W[a, 0] + fpar[r]
        elif code == CONST:
            W[out, 0] = fpar[r]
        elif code == NEG:
            W[out, 0] = -W[a, 0]
        elif code == DIV:
            W[out, 0] = 0.0 + W[a, 0] * W[b, 0] ** -1.0
        elif code == EXP:
            W[out, 0] = math.exp(W[a, 0]) * 1.0
        elif code == LOG:
            u0 = W[a, 0]
            W[out, 0] = math.log(u0) if u0 > 0.0 else np.nan
        elif code == SIN or code == COS:
            u0 = W[a, 0] + (0.5 * math.pi if code == COS else 0.0)
            W[out, 0] = math.sin(u0 + 0.0) * 1.0
        elif code == SQRT or code == POWR:
            u0 = W[a, 0]
            power = 0.5 if code == SQRT else fpar[r]
            if u0 > 0.0:
                W[out, 0] = u0 ** power
            elif u0 == 0.0 and power > 0.0:
                W[out, 0] = 0.0
            else:
                W[out, 0] = np.nan
        elif code == POWI:
            if k == 0:
                W[out, 0] = 1.0
            elif k > 0:
                v = W[a, 0]
                for _ in range(k - 1):
                    v = 0.0 + v * W[a, 0]
                W[out, 0] = v
            else:
                W[out, 0] = W[a, 0] ** float(k)
        elif code == CRB:
            u_hi, u_lo = W[a, 0], 0.0
            if b >= 0:
                u_hi, u_lo = _sum_of_squares(W, args, b, k)
            crb_coef(u_hi, u_lo, np.int64(0), coef)
            W[out, 0] = coef[0]
        elif code == PHIMV:
            _phimv(W, out, a, k, args, np.int64(0), space, S)


def scratch_rows(n: int) -> int:
    """Rows of scratch space `run_tape` needs for a system of dimension n (engine: 5 + 2n)."""
    return 5 + 2 * n


def evaluate(tape, inputs: np.ndarray, degree: int = 0, n_vars: int = 0):
    """Evaluate a tape (Python-level helper).

    With degree 0 returns the output values for the given input values. With degree 1 and
    n_vars = len(inputs) returns (values, Jacobian (outputs x inputs)) by forward mode.
    """
    inputs = np.asarray(inputs, dtype=np.float64)
    nv = n_vars if degree > 0 else 0
    space = jet_space(nv, degree)
    W = np.zeros((tape.n_slots, space.size))
    W[: len(inputs), 0] = inputs
    if degree > 0:
        for i in range(len(inputs)):
            W[i, 1 + i] = 1.0
    scratch = np.zeros((scratch_rows(tape.n_inputs) + tape.n_inputs, space.size))
    run_tape(tape.packed(), W, degree, space.packed(), scratch)
    out = W[tape.outputs]
    if degree == 0:
        return out[:, 0].copy()
    return out[:, 0].copy(), out[:, 1: 1 + nv].copy()
