"""Plain tapes on scalars: values, and values with a gradient by forward mode (dual numbers).

The interpreter (`rkhp.taylor.interpreter`) evaluates any tape on jets of any degree; its degree-0
path computes every FUNCTION row from its Taylor coefficients. Where only values, or values and
first derivatives, of a tape without composite operations are needed in a hot loop (the direct
Euler step of the spray realisation, `rkhp.integrators.spray_euler`), the functions here evaluate
the rows directly with `math`: one branch per opcode, a value (W[slot, 0]) and, with a gradient,
the `nd` first-order coefficients W[slot, 1..nd], the layout of the interpreter's degree-1 jets.
They agree with the interpreter to round-off (tests/test_spray_euler.py); NaN where the
interpreter's recurrences give NaN (log, sqrt and real powers outside their domain).

:func:`shared` removes repeated rows from a plain tape (common subexpressions: the spray field
X = pi(y) p records each entry of pi apart, so a factor shared by several entries is computed
several times), which changes no value.

Every FUNCTION opcode of `rkhp.taylor.ops` but CRB (so(3)*'s closed form, never in a plain tape of
mathematical text) has its branch: :data:`SCALAR_CODES`; a new function needs one here too.
"""

from __future__ import annotations

import math

import numpy as np

from .compiler import NJIT_NORC
from .compiler import numba as nb
from .ops import (
    ADD,
    ADDC,
    ATAN,
    CONST,
    COS,
    DIV,
    EXP,
    LOG,
    MUL,
    MULC,
    NEG,
    POWI,
    POWR,
    SIN,
    SQRT,
    SUB,
)
from .tape import Tape

#: the opcodes evaluated here
SCALAR_CODES = frozenset({CONST, ADD, SUB, MUL, NEG, MULC, ADDC, DIV, EXP, LOG, SIN, COS, SQRT,
                          POWI, POWR, ATAN})


@nb.njit(inline="always", **NJIT_NORC)
def _power_int(u, k):
    """u^k by repeated products (k >= 0), 1 / u^|k| for k < 0."""
    m = k if k >= 0 else -k
    v = 1.0
    for _ in range(m):
        v *= u
    return v if k >= 0 else 1.0 / v


@nb.njit(inline="always", **NJIT_NORC)
def _value_derivative(code, u, f, k):
    """(f(u), f'(u)) of a FUNCTION row (DIV: 1/u, its reciprocal's), NaN outside the domain."""
    if code == EXP:
        v = math.exp(u)
        return v, v
    if code == SIN:
        return math.sin(u), math.cos(u)
    if code == COS:
        return math.cos(u), -math.sin(u)
    if code == LOG:
        if u > 0.0:
            return math.log(u), 1.0 / u
        return np.nan, np.nan
    if code == DIV:
        v = 1.0 / u
        return v, -v * v
    if code == POWI:
        return _power_int(u, k), k * _power_int(u, k - 1) if k != 0 else 0.0
    if code == SQRT or code == POWR:
        power = 0.5 if code == SQRT else f
        if u > 0.0:
            v = math.sqrt(u) if code == SQRT else u ** power
            return v, power * v / u
        if u == 0.0 and power > 0.0:
            return 0.0, np.inf if power < 1.0 else (1.0 if power == 1.0 else 0.0)
        return np.nan, np.nan
    if code == ATAN:
        return math.atan(u), 1.0 / (1.0 + u * u)
    return np.nan, np.nan


@nb.njit(**NJIT_NORC)
def values(tape, W):
    """The rows of a plain tape at the values W[:, 0] (inputs W[0:n_inputs, 0] set by the
    caller)."""
    ops, fpar = tape.ops, tape.fpar
    for r in range(tape.main, ops.shape[0]):
        code, out, a, b = ops[r, 0], ops[r, 1], ops[r, 2], ops[r, 3]
        if code == MUL:
            W[out, 0] = W[a, 0] * W[b, 0]
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
            W[out, 0] = W[a, 0] / W[b, 0]
        elif code == POWI:
            W[out, 0] = _power_int(W[a, 0], ops[r, 4])
        else:
            W[out, 0] = _value_derivative(code, W[a, 0], fpar[r], ops[r, 4])[0]


@nb.njit(**NJIT_NORC)
def gradients(tape, W, nd):
    """The rows of a plain tape with first-order coefficients: W[slot, 0] the value,
    W[slot, 1..nd] its derivatives (inputs set by the caller, including their derivatives)."""
    ops, fpar = tape.ops, tape.fpar
    for r in range(tape.main, ops.shape[0]):
        code, out, a, b = ops[r, 0], ops[r, 1], ops[r, 2], ops[r, 3]
        if code == MUL:
            x, y = W[a, 0], W[b, 0]
            for d in range(1, nd + 1):
                W[out, d] = x * W[b, d] + y * W[a, d]
            W[out, 0] = x * y
        elif code == ADD:
            for d in range(nd + 1):
                W[out, d] = W[a, d] + W[b, d]
        elif code == SUB:
            for d in range(nd + 1):
                W[out, d] = W[a, d] - W[b, d]
        elif code == MULC:
            c = fpar[r]
            for d in range(nd + 1):
                W[out, d] = c * W[a, d]
        elif code == ADDC:
            for d in range(1, nd + 1):
                W[out, d] = W[a, d]
            W[out, 0] = W[a, 0] + fpar[r]
        elif code == CONST:
            for d in range(1, nd + 1):
                W[out, d] = 0.0
            W[out, 0] = fpar[r]
        elif code == NEG:
            for d in range(nd + 1):
                W[out, d] = -W[a, d]
        elif code == DIV:
            y = W[b, 0]
            v = W[a, 0] / y
            for d in range(1, nd + 1):
                W[out, d] = (W[a, d] - v * W[b, d]) / y
            W[out, 0] = v
        else:
            v, dv = _value_derivative(code, W[a, 0], fpar[r], ops[r, 4])
            for d in range(1, nd + 1):
                W[out, d] = dv * W[a, d]
            W[out, 0] = v


_COMMUTATIVE = frozenset({ADD, MUL})


def polynomial_degree(tape: Tape, output: int = 0) -> float:
    """The degree of the polynomial that output `output` of a plain tape (main = 0) is in the
    tape's inputs, or inf when it is not a polynomial (a function of a non-constant, a division by
    a non-constant, a non-integer power): a quadratic H has a constant Hessian
    (`rkhp.integrators.closed_euler`)."""
    degree = {k: 1.0 for k in range(tape.n_inputs)}
    for code, out, a, b, k in tape.ops[tape.main:].tolist():
        da, db = degree.get(a, 0.0), degree.get(b, 0.0)
        if code in (ADD, SUB):
            d = max(da, db)
        elif code == MUL:
            d = da + db
        elif code in (MULC, ADDC, NEG):
            d = da
        elif code == CONST:
            d = 0.0
        elif code == DIV:
            d = da if db == 0.0 else math.inf
        elif code == POWI:
            d = da * k if k >= 0 else (0.0 if da == 0.0 else math.inf)
        else:
            d = 0.0 if da == 0.0 else math.inf
        degree[out] = d
    return degree.get(int(tape.outputs[output]), 0.0)


def shared(tape: Tape) -> Tape:
    """The same plain tape with each repeated row (same opcode, operands, parameters) computed
    once, its later copies' readers reading the first (the rows' order is kept; outputs
    follow). A sub-program-free tape only (main = 0); slot numbers are kept."""
    if tape.main != 0 or type(tape).composites:
        raise ValueError("shared() takes a plain tape without sub-programs")
    alias: dict[int, int] = {}
    seen: dict[tuple, int] = {}
    rows, fpar = [], []
    for row, f in zip(tape.ops.tolist(), tape.fpar.tolist(), strict=True):
        code, out, a, b, k = row
        a, b = alias.get(a, a), alias.get(b, b)
        operands = (min(a, b), max(a, b)) if code in _COMMUTATIVE else (a, b)
        key = (code, *operands, k, f)
        if key in seen:
            alias[out] = seen[key]
            continue
        seen[key] = out
        rows.append((code, out, a, b, k))
        fpar.append(f)
    outputs = np.array([alias.get(int(s), int(s)) for s in tape.outputs], dtype=np.int64)
    return Tape(np.array(rows, dtype=np.int64).reshape(-1, 5), np.array(fpar, dtype=np.float64),
                tape.args, outputs, tape.n_inputs, tape.n_slots, 0, tape.scratch_rows)
