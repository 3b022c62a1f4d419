"""The explicit Taylor tower (paper §5.2, docs/theory.md §5): at the Newton iterate x0, each stage
function g_i(x) = f(x, Z_i(x)), f = H o alpha, is held as its Taylor polynomial in dx = x - x0,
truncated at degree s + 2 - i (1-based i); g_1 = H; Z_i = h sum_{j<i} a_ij grad g_j is read off
the coefficients (`stage_jet`). psi = h sum_i b_i grad g_i and its Jacobian are the degree-0 and
degree-1 coefficients, alpha(x0, psi) and the Jacobian of x -> alpha(x, psi(x)) follow from
them (`psi_alpha`). Each stage is computed once. The implicit tower
(`rkhp.integrators.implicit_tower`) computes its stages with `stage_jet` and ends with
`psi_alpha` too.
"""

from __future__ import annotations

import numpy as np

from ..taylor.compiler import NJIT_NORC
from ..taylor.compiler import numba as nb
from ..taylor.interpreter import run_from
from .engine_state import MEMO_FACTORED


@nb.njit(**NJIT_NORC)
def _set_x(W, x0, n, D, M):
    """Input rows 0..n-1: the jets x0_k + dx_k (degree <= D, M coefficients)."""
    for k in range(n):
        for m in range(M):
            W[k, m] = 0.0
        W[k, 0] = x0[k]
        if D >= 1:
            W[k, 1 + k] = 1.0


@nb.njit(inline="always", **NJIT_NORC)
def stage_jet(i, x0, A, h, D, j_end, tapes, space, buf):
    """g_i = f(x0 + dx, Z_i), Z_i = h sum_{j < j_end} a_ij G[j], in jets of degree D (G[j] read up
    to degree D), into the work arrays; returns the slot of g_i."""
    W, G = buf.work.W, buf.G
    n = x0.shape[0]
    M = space.counts[D]
    _set_x(W, x0, n, D, M)
    zero_row = True
    for j in range(j_end):
        if A[i, j] != 0.0:
            zero_row = False
    for k in range(n):
        for m in range(M):
            W[n + k, m] = 0.0
        for j in range(j_end):
            c = h * A[i, j]
            if c != 0.0:
                for m in range(M):
                    W[n + k, m] += c * G[j, k, m]
    run_from(tapes.run, tapes.h_at if zero_row else tapes.f_at, D, tapes.space_at, tapes.work_at)
    return tapes.h.outputs[0] if zero_row else tapes.f.outputs[0]


@nb.njit(inline="always", **NJIT_NORC)
def _explicit_stage(i, x0, A, h, D, tapes, space, buf):
    """Stage i of an explicit tableau at x0 (`stage_jet`, the stages j < i): G[i] := grad g_i up
    to degree D - 1."""
    W, G = buf.work.W, buf.G
    g = stage_jet(i, x0, A, h, D, i, tapes, space, buf)
    up, expo = space.up, space.expo
    for k in range(x0.shape[0]):
        for m in range(space.counts[D - 1]):
            G[i, k, m] = (expo[m, k] + 1) * W[g, up[m, k]]


@nb.njit(inline="always", **NJIT_NORC)
def psi_alpha(x0, b, h, tapes, space, buf, jacobian):
    """psi = h sum_i b_i G[i](0) and alpha(x0, psi) into buf.psi, buf.alpha; with `jacobian`,
    also Dpsi (degree-1 coefficients) and the Jacobian of x -> alpha(x, psi(x))."""
    G, psi, Jpsi = buf.G, buf.psi, buf.Jpsi
    s = b.shape[0]
    n = x0.shape[0]
    for k in range(n):
        psi[k] = 0.0
        for i in range(s):
            psi[k] += h * b[i] * G[i, k, 0]
        if jacobian:
            for l in range(n):
                acc = 0.0
                for i in range(s):
                    acc += h * b[i] * G[i, k, 1 + l]
                Jpsi[k, l] = acc
    alpha_at_psi(x0, tapes, space, buf, jacobian)


@nb.njit(inline="always", **NJIT_NORC)
def alpha_at_psi(x0, tapes, space, buf, jacobian):
    """alpha(x0, buf.psi) into buf.alpha; with `jacobian`, also the Jacobian of
    x -> alpha(x, psi(x)) from Dpsi = buf.Jpsi into buf.Jalpha."""
    W, psi, Jpsi = buf.work.W, buf.psi, buf.Jpsi
    n = x0.shape[0]
    extra = np.int64(1) if jacobian else np.int64(0)
    _set_x(W, x0, n, extra, n + 1)
    for k in range(n):
        W[n + k, 0] = psi[k]
        for l in range(n):
            W[n + k, 1 + l] = Jpsi[k, l] if jacobian else 0.0
    run_from(tapes.run, tapes.alpha_at, extra, tapes.space_at, tapes.work_at)
    for k in range(n):
        a = tapes.alpha.outputs[k]
        buf.alpha[k] = W[a, 0]
        if jacobian:
            for l in range(n):
                buf.Jalpha[k, l] = W[a, 1 + l]
    if jacobian:
        buf.memo[MEMO_FACTORED] = 0.0


@nb.njit(inline="always", **NJIT_NORC)
def tower(x0, A, b, h, tapes, space, buf, jacobian):
    """The explicit tower: psi and alpha(x0, psi(x0)) at x0 into buf.psi, buf.alpha (see module);
    with `jacobian`, also Dpsi and the Jacobian of x -> alpha(x, psi(x)) (stage degrees
    s + 2 - i; without, s + 1 - i: each stage exact, computed once)."""
    s = b.shape[0]
    extra = np.int64(1) if jacobian else np.int64(0)
    for i in range(s):
        _explicit_stage(i, x0, A, h, s + extra - i, tapes, space, buf)
    psi_alpha(x0, b, h, tapes, space, buf, jacobian)
