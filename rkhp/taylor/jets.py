"""Truncated multivariate Taylor arithmetic ("jets"): the monomial tables and the jet kernels
(docs/theory.md §7).

A jet in m variables truncated at total degree D is the array of its Taylor coefficients over the
monomials of degree <= D, in graded order (degree 0, then the m monomials of degree 1 in the order
of the variables, ...). Products run over a precomputed list of index pairs sorted by the degree of
the result, so truncating at any D <= Dmax uses a prefix of every table. A univariate function of
a jet u = u0 + v is composed by Horner's rule on its Taylor coefficients at u0
(`rkhp.taylor.elementary`): f(u) = sum_k f^(k)(u0)/k! v^k (v has no constant term, so the sum
stops at k = D).

The kernels are compiled with numba (`rkhp.taylor.compiler`); they allocate nothing and take rows
of 2-d arrays as (array, index) pairs: a view would cost reference counting.
"""

from __future__ import annotations

from functools import lru_cache
from math import comb
from typing import NamedTuple

import numpy as np

from .compiler import NJIT_NORC
from .compiler import numba as nb
from .ops import COMPOSE_ACC, COMPOSE_ARG, COMPOSE_PROD


class JetSpace(NamedTuple):
    """Tables for jets in `n_vars` variables truncated at degree <= `degree`; passed to compiled
    code as it is.

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

    @property
    def size(self) -> int:
        return int(self.counts[-1])


def monomials(n: int, degree: int) -> list[tuple[int, ...]]:
    """The exponent tuples of the monomials in n variables of degree <= `degree`, graded."""
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
    monos = monomials(n_vars, degree)
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


@nb.njit(**NJIT_NORC)
def jet_mul(X, i, Y, j, Z, k, D, space):
    """Z[k] = X[i] * Y[j] truncated at degree D (rows of 2-d arrays; Z[k] not X[i] or Y[j]).

    Rows are passed as (array, index), not as views: a view costs reference counting. The pair
    tables are unsigned, so that indexing skips the negative-index wrap-around. Two partial sums
    (even and odd pairs) halve the chain of dependent additions (the sum's rounding differs from the
    sequential one at round-off level).
    """
    start, pa, pb = space.start, space.pa, space.pb
    one = np.uint64(1)
    for c in range(space.counts[D]):
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
    """Z[k] = sum_q coef[q] (X[i] - X[i, 0])^q truncated at degree D >= 1 (Horner; scratch rows
    COMPOSE_ARG, COMPOSE_ACC, COMPOSE_PROD of S; Z[k] may be X[i]). Inlined at its one call site
    (`rkhp.taylor.rows`): a call passes every array field of its arguments by value, which cost
    7-8% of a step on Lotka–Volterra (three exp and three log rows per tape)."""
    counts = space.counts
    M = counts[D]
    for m in range(M):
        S[COMPOSE_ARG, m] = X[i, m]
        S[COMPOSE_ACC, m] = 0.0
    S[COMPOSE_ARG, 0] = 0.0
    S[COMPOSE_ACC, 0] = coef[D]
    for q in range(D - 1, -1, -1):
        jet_mul(S, np.int64(COMPOSE_ACC), S, np.int64(COMPOSE_ARG), S, np.int64(COMPOSE_PROD),
                D - q, space)
        for m in range(counts[D - q]):
            S[COMPOSE_ACC, m] = S[COMPOSE_PROD, m]
        S[COMPOSE_ACC, 0] += coef[q]
    for m in range(M):
        Z[k, m] = S[COMPOSE_ACC, m]
