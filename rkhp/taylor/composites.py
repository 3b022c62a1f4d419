"""Kernels of the composite operations (kind COMPOSITE in `rkhp.taylor.ops`).

A kernel has the signature ``kernel(tape, r, W, D, space, S, deg)``: it reads its row
``tape.ops[r]`` = (code, out, a, b, k), its operand list ``tape.args[a : a + b]`` (references of
its sub-programs first, then operand slots; numbers were recorded as constant slots, read as
W[slot, 0]), writes its results to the slots out, out + 1, ... with their degree bounds in deg,
and uses the scratch rows from SCRATCH_BASE on (as many as its `Op.scratch(k)` declares; rows
below are the elementary rows' and may be overwritten by a sub-program evaluation).

A kernel evaluates a sub-program by setting its input slots (jets of degree D, and their deg
bounds) and calling `rkhp.taylor.rows.run_rows(tape, lo, hi, ...)` on its row range, then reading
its output slots; it may do so as often as it needs (a fixed-point iteration, several collocation
nodes). Registering one: a code and an `rkhp.taylor.ops.OPS` row (kind COMPOSITE, its scratch
need), the kernel here, and one branch in `rkhp.taylor.interpreter._composite`
(docs/engine.md "Composite operations").
"""

from __future__ import annotations

import math

import numpy as np

from .compiler import NJIT_NORC
from .compiler import numba as nb
from .elementary import PHI_COEF, TWO_PI
from .jets import jet_mul
from .ops import SCRATCH_BASE


@nb.njit(**NJIT_NORC)
def phimv(tape, r, W, D, space, S, deg):
    """phi(K) x by its power series sum_k PHI_COEF[k] K^k x, for ||K0||_F < 0.9 * 2 pi (NaN
    beyond); operands: K (k x k, row-major), then x (k); results: the k components.

    Scratch rows from SCRATCH_BASE: v = K^k x (n rows), K v (n rows), one product."""
    out, start, n = tape.ops[r, 1], tape.ops[r, 2], tape.ops[r, 4]
    args = tape.args
    M = space.counts[D]
    for i in range(n):
        deg[out + i] = D
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
    v = SCRATCH_BASE
    kv = SCRATCH_BASE + n
    acc = SCRATCH_BASE + 2 * n
    for i in range(n):
        xi = args[start + n * n + i]
        for m in range(M):
            S[v + i, m] = W[xi, m]
            W[out + i, m] = W[xi, m]
    for k in range(1, terms + 1):
        for i in range(n):
            for m in range(M):
                S[kv + i, m] = 0.0
            for j in range(n):
                jet_mul(W, args[start + i * n + j], S, v + j, S, acc, D, space)
                for m in range(M):
                    S[kv + i, m] += S[acc, m]
        c = PHI_COEF[k]
        for i in range(n):
            for m in range(M):
                S[v + i, m] = S[kv + i, m]
                W[out + i, m] += c * S[v + i, m]
