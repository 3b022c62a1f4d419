"""Sympy expressions as programs over tape values (`rkhp.taylor.tape`).

The expressions come from the safe reader (`rkhp.base.expressions`), so they hold only numbers, the
variables x1..xn, + - * / and powers, and the functions of the opcode table
(`rkhp.taylor.ops.FUNCTIONS`), recorded by `rkhp.taylor.tape.RECORDERS`. A program takes a
list x of n values of any arithmetic with + - * / ** (tape Vars, or the series of
`rkhp.systems.spray`) and calls the tape functions `tp.exp` etc., which dispatch to that
arithmetic.
"""

from __future__ import annotations

from functools import reduce

import numpy as np

from ..taylor import tape as tp


def expression_program(expr, symbols):
    """A program x -> value of the sympy expression in `symbols`; a constant expression gives a
    float (so that constant entries of a matrix cost nothing)."""
    index = {s: i for i, s in enumerate(symbols)}

    def conv(e, x):
        if not e.free_symbols:
            return float(e.evalf(20))
        if e.is_Symbol:
            return x[index[e]]
        args = [conv(a, x) for a in e.args]
        if e.is_Add:
            return reduce(lambda a, b: a + b, args)
        if e.is_Mul:
            return reduce(lambda a, b: a * b, args)
        if e.is_Pow:
            base, power = args
            if isinstance(base, float):
                return tp.exp(power * float(np.log(base)))
            return base ** power
        (a,) = args
        return tp.RECORDERS[type(e).__name__](a)

    def expression_values(x):
        return conv(expr, x)

    return expression_values


def to_program(expr, symbols):
    """A program x -> tape Var computing the sympy expression (for `build_system`: a constant
    is recorded as x1 * 0 + c so that the result is always a Var)."""
    value = expression_program(expr, symbols)

    def tape_value(x):
        v = value(x)
        return v if isinstance(v, tp.Var) else x[0] * 0.0 + v

    tape_value.expression = str(expr)
    return tape_value


def matrix_program(entries, symbols):
    """A program y -> n x n entries (floats where constant) of a matrix of sympy expressions."""
    programs = [[expression_program(e, symbols) for e in row] for row in entries]

    def matrix_values(y):
        return [[f(y) for f in row] for row in programs]

    return matrix_values


def numeric_function(expr, symbols):
    """A float64 function x -> float of a sympy expression (numpy), e.g. a Casimir."""
    import sympy

    f = sympy.lambdify(symbols, expr, "numpy")

    def value(x):
        return float(f(*np.asarray(x, dtype=np.float64)))

    return value
