"""Evaluation of elementary tape rows (ARITHMETIC and FUNCTION ops) at truncation degree D.

`run_rows(tape, lo, hi, W, D, space, S, deg)` evaluates rows lo..hi-1 of a tape in place on the
slot jets W (one row per slot, the jet coefficients of `space` up to degree D; degree 0 is the
value-only path). It is the loop of the main program between composite operations
(`rkhp.taylor.interpreter.run_tape`) and the whole evaluation of a sub-program, which composite
kernels call as often as they need (`rkhp.taylor.composites`): no recursion.

deg[slot] is a bound on the degree of the slot's polynomial (inputs: read off their coefficients
by the caller), so that products of low-degree values (e.g. H of x0 + dx) stop early.

A FUNCTION row takes the Taylor coefficients of its function at the argument's value from
`rkhp.taylor.elementary.taylor_coefficients` (one call site) and composes them with the argument's
jet by `rkhp.taylor.jets.jet_compose` (one call site), or at degree 0 keeps the value coef[0].
"""

from __future__ import annotations

import numpy as np

from .compiler import NJIT_NORC
from .compiler import numba as nb
from .elementary import taylor_coefficients, two_prod
from .jets import jet_compose, jet_mul
from .ops import ADD, ADDC, COEF_ROW, CONST, CRB, DIV, MUL, MULC, NEG, POWI, SUB, TEMP_ROW


@nb.njit(**NJIT_NORC)
def run_rows(tape, lo, hi, W, D, space, S, deg):
    """Evaluate the elementary rows lo..hi-1 of `tape` at degree D (see the module): for
    composite kernels (the interpreter's main loop inlines `rows`)."""
    rows(tape, lo, hi, W, D, space, S, deg)


@nb.njit(inline="always", **NJIT_NORC)
def rows(tape, lo, hi, W, D, space, S, deg):
    """`run_rows`, inlined where it is called."""
    if D == 0:
        for r in range(lo, hi):
            _value_row(tape, r, W, S)
    else:
        for r in range(lo, hi):
            _row(tape, r, W, D, space, S, deg)


@nb.njit(inline="always", **NJIT_NORC)
def _value_row(tape, r, W, S):
    """A row at degree 0 (values W[:, 0]): arithmetic on scalars, the same operations as the jet
    kernels at degree 0 (a product x*y is their 0.0 + x*y); a FUNCTION row's value is its
    coef[0] (`_function`)."""
    ops = tape.ops
    code, out, a, b, k = ops[r, 0], ops[r, 1], ops[r, 2], ops[r, 3], ops[r, 4]
    if code == MUL:
        W[out, 0] = W[a, 0] * W[b, 0] + 0.0
    elif code == ADD:
        W[out, 0] = W[a, 0] + W[b, 0]
    elif code == SUB:
        W[out, 0] = W[a, 0] - W[b, 0]
    elif code == MULC:
        W[out, 0] = tape.fpar[r] * W[a, 0]
    elif code == ADDC:
        W[out, 0] = W[a, 0] + tape.fpar[r]
    elif code == CONST:
        W[out, 0] = tape.fpar[r]
    elif code == NEG:
        W[out, 0] = -W[a, 0]
    elif code == POWI and k >= 0:
        v = 1.0 if k == 0 else W[a, 0]
        for _ in range(k - 1):
            v = v * W[a, 0] + 0.0
        W[out, 0] = v
    else:
        function_coefficients(tape, r, W, np.int64(0), S)
        coef0 = S[COEF_ROW, 0]
        W[out, 0] = W[a, 0] * coef0 + 0.0 if code == DIV else coef0


@nb.njit(inline="always", **NJIT_NORC)
def _row(tape, r, W, D, space, S, deg):
    ops = tape.ops
    code, out, a, b, k = ops[r, 0], ops[r, 1], ops[r, 2], ops[r, 3], ops[r, 4]
    counts = space.counts
    M = counts[D]
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
        f = tape.fpar[r]
        for m in range(M):
            W[out, m] = f * W[a, m]
    elif code == ADDC:
        deg[out] = deg[a]
        for m in range(M):
            W[out, m] = W[a, m]
        W[out, 0] += tape.fpar[r]
    elif code == CONST:
        deg[out] = 0
        for m in range(M):
            W[out, m] = 0.0
        W[out, 0] = tape.fpar[r]
    elif code == NEG:
        deg[out] = deg[a]
        for m in range(M):
            W[out, m] = -W[a, m]
    elif code == POWI and k >= 0:
        _power(W, out, a, k, D, space, S, deg)
    else:
        _function(tape, r, W, D, space, S)


@nb.njit(inline="always", **NJIT_NORC)
def _power(W, out, a, k, D, space, S, deg):
    """W[out] = W[a]^k for k >= 0 by repeated products (row TEMP_ROW of S)."""
    M = space.counts[D]
    if k == 0:
        for m in range(M):
            W[out, m] = 0.0
        W[out, 0] = 1.0
        deg[out] = 0
        return
    for m in range(M):
        S[TEMP_ROW, m] = W[a, m]
    for _ in range(k - 1):
        jet_mul(S, np.int64(TEMP_ROW), W, a, W, out, D, space)
        for m in range(M):
            S[TEMP_ROW, m] = W[out, m]
    for m in range(M):
        W[out, m] = S[TEMP_ROW, m]
    deg[out] = min(D, k * deg[a])


@nb.njit(inline="always", **NJIT_NORC)
def function_coefficients(tape, r, W, D, S):
    """The Taylor coefficients (row COEF_ROW of S, degrees 0..D) of a FUNCTION row's function at
    its argument's value; returns the argument's slot. The argument: u = W[a] (DIV: the divisor
    W[b], whose reciprocal's coefficients these are; CRB: u = W[args[a]], its value recomputed
    from the p slots listed after it in double-double)."""
    ops = tape.ops
    code, a, b, k = ops[r, 0], ops[r, 2], ops[r, 3], ops[r, 4]
    u = a
    if code == DIV:
        u = b
    elif code == CRB:
        u = tape.args[a]
    u_hi, u_lo = W[u, 0], 0.0
    if code == CRB and b > 1:
        u_hi, u_lo = _sum_of_squares(W, tape.args, a + 1, b - 1)
    taylor_coefficients(code, u_hi, u_lo, tape.fpar[r], k, D, S[COEF_ROW])
    return u


@nb.njit(inline="always", **NJIT_NORC)
def _function(tape, r, W, D, space, S):
    """A FUNCTION row at degree D >= 1: its coefficients composed with the argument's jet
    (DIV: W[a] times the composed reciprocal of W[b])."""
    code, out, a = tape.ops[r, 0], tape.ops[r, 1], tape.ops[r, 2]
    u = function_coefficients(tape, r, W, D, S)
    # DIV: compose 1/u into TEMP_ROW, then multiply; the others compose into W[out]
    Z, z = (S, np.int64(TEMP_ROW)) if code == DIV else (W, out)
    jet_compose(S[COEF_ROW], W, u, Z, z, D, space, S)
    if code == DIV:
        jet_mul(W, a, S, np.int64(TEMP_ROW), W, out, D, space)


@nb.njit(**NJIT_NORC)
def _sum_of_squares(W, args, start, count):
    """sum_i W[args[start + i], 0]^2 as a double-double (hi, lo)."""
    hi = 0.0
    lo = 0.0
    for i in range(count):
        v = W[args[start + i], 0]
        p, e = two_prod(v, v)
        s = hi + p
        bb = s - hi
        lo += (hi - (s - bb)) + (p - bb) + e
        hi = s
    s = hi + lo
    return s, lo - (s - hi)


@nb.njit(**NJIT_NORC)
def subprogram_at(args, pos):
    """The sub-program reference at args[pos] (`rkhp.taylor.tape.SubProgram.operands`):
    (lo, hi, first input position, n_in, first output position, n_out, position after it);
    the input slots are args[first input position + i], the outputs likewise."""
    lo, hi, n_in = args[pos], args[pos + 1], args[pos + 2]
    n_out = args[pos + 3 + n_in]
    return lo, hi, pos + 3, n_in, pos + 4 + n_in, n_out, pos + 4 + n_in + n_out
