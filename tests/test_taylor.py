"""The Taylor machinery (rkhp.taylor): every elementary function's jets against sympy at every
degree, the value path against the jet path, the tape's sub-programs, and the layers."""

from __future__ import annotations

import math

import numpy as np
import pytest
import sympy

from rkhp.taylor import tape as tp
from rkhp.taylor.interpreter import evaluate, run_tape, tape_work
from rkhp.taylor.jets import jet_space
from rkhp.taylor.ops import ARITHMETIC, DIV, FUNCTION, OPS, PHIMV

U0 = 0.7
DEGREES = range(0, 7)
S = sympy.Symbol("u", positive=True)

#: FUNCTION ops that mathematical text does not call by name: how to record them, what they are
SPECIAL = {
    "powi": (lambda u: u ** -3, S ** -3),
    "powr": (lambda u: u ** 1.5, S ** sympy.Rational(3, 2)),
    "crb": (lambda u: tp.crb([u]), (1 - S / 2 * sympy.cot(S / 2)) / S ** 2),  # c(|p|^2), p = (u)
}
CASES = {op.name: (tp.RECORDERS[op.sympy], getattr(sympy, op.sympy)(S)) if op.sympy else SPECIAL[op.name]
         for op in OPS if op.kind == FUNCTION}
CASES["div"] = (lambda u: 2.0 / u, 2 / S)
CASES.update({name: (tp.RECORDERS[name], getattr(sympy, name)(S)) for name in ("tan", "sinh", "cosh", "tanh")})


def _jet(record, D):
    builder = tp.TapeBuilder(1)
    (u,) = builder.inputs()
    tape = builder.finish([record(u)])
    space = jet_space(1, D)
    work = tape_work((tape,), space.size)
    work.W[0, 0] = U0
    if D:
        work.W[0, 1] = 1.0
    run_tape(tape, D, space, work)
    return work.W[tape.outputs[0]].copy()


def test_every_function_op_is_covered():
    assert {op.name for op in OPS if op.kind == FUNCTION} <= set(CASES)
    assert {op.code for op in OPS if op.kind == ARITHMETIC} >= {DIV}


@pytest.mark.parametrize("name", sorted(CASES))
def test_jets_of_every_function_against_sympy(name):
    """The degree-D jet of g(u0 + v) holds g^(q)(u0)/q! for q <= D (sympy, 30 digits), and its
    value is the degree-0 path's to the last bit."""
    record, expr = CASES[name]
    value = _jet(record, 0)[0]
    for D in DEGREES:
        jet = _jet(record, D)
        assert jet[0] == value, (name, D)
        for q in range(D + 1):
            exact = float(sympy.diff(expr, S, q).subs(S, sympy.Rational(7, 10)).evalf(30)) / math.factorial(q)
            assert jet[q] == pytest.approx(exact, rel=1e-12, abs=1e-14), (name, D, q)


def test_subprograms_are_recorded_apart_and_not_run_by_the_main_loop():
    builder = tp.TapeBuilder(2)
    x, y = builder.inputs()
    sub = builder.subprogram(2, lambda v: [tp.exp(v[0]) * v[1] + 1.0])
    out = x * y + 3.0
    tape = builder.finish([out, tp.Var(builder, sub.outputs[0])])
    assert tape.main == sub.hi - sub.lo == 3  # exp, mul, add a constant
    assert sub.lo == 0 and set(sub.inputs).isdisjoint({0, 1}) and len(sub.outputs) == 1
    assert sub.operands() == [0, 3, 2, *sub.inputs, 1, *sub.outputs]
    values = evaluate(tape, [2.0, 5.0])
    assert values[0] == 13.0 and values[1] == 0.0  # the sub-program runs only inside a composite


def test_a_subprogram_runs_on_jets_as_a_composite_kernel_runs_it():
    """run_rows evaluates a sub-program's rows on its own slots, as often as asked: X(y, p) =
    cos(y) p at two points, as degree-2 jets in (y, p), against the derivatives by hand."""
    from rkhp.taylor.rows import run_rows, subprogram_at

    builder = tp.TapeBuilder(2)
    x, p = builder.inputs()
    sub = builder.subprogram(2, lambda v: [tp.cos(v[0]) * v[1]])
    tape = builder.finish([x])
    lo, hi, first_in, n_in, first_out, n_out, _ = subprogram_at(np.array(sub.operands()), 0)
    assert (lo, hi, n_in, n_out) == (sub.lo, sub.hi, 2, 1)
    space = jet_space(2, 2)
    work = tape_work((tape,), space.size)
    for y0, p0 in ((0.3, 2.0), (1.1, -0.5)):
        work.W[sub.inputs[0], :] = [y0, 1.0, 0.0, 0.0, 0.0, 0.0]
        work.W[sub.inputs[1], :] = [p0, 0.0, 1.0, 0.0, 0.0, 0.0]
        work.deg[list(sub.inputs)] = 1
        run_rows(tape, lo, hi, work.W, 2, space, work.S, work.deg)
        # cos(y0 + u) (p0 + v) to degree 2 in (u, v): monomials 1, u, v, u^2, uv, v^2
        c, s = math.cos(y0), math.sin(y0)
        expected = [c * p0, -s * p0, c, -c * p0 / 2, -s, 0.0]
        assert np.allclose(work.W[sub.outputs[0]], expected, rtol=1e-15, atol=1e-15)


def test_subprogram_rules():
    builder = tp.TapeBuilder(1)
    (x,) = builder.inputs()
    with pytest.raises(ValueError, match="only use its own"):
        builder.subprogram(1, lambda v: [v[0] * x])
    with pytest.raises(ValueError, match="composite"):
        builder.subprogram(3, lambda v: tp.phimv([[v[0]]], [v[1]]))
    with pytest.raises(ValueError, match="do not nest"):
        builder.subprogram(1, lambda v: [builder.subprogram(1, lambda w: w).outputs])


def test_composite_operand_list_starts_with_its_subprograms():
    builder = tp.TapeBuilder(2)
    x, y = builder.inputs()
    sub = builder.subprogram(1, lambda v: [tp.sin(v[0])])
    (z,) = builder.composite(PHIMV, [0.5, x], 1, k=1, subprograms=(sub,))
    tape = builder.finish([z])
    code, out, a, b, k = tape.ops[tape.main + 1]  # after the constant 0.5
    assert code == PHIMV and k == 1 and out == z.slot
    assert tape.args[a: a + b].tolist() == sub.operands() + [tape.ops[tape.main, 1], x.slot]
    assert tape.scratch_rows == 5 + 3  # the base rows and phimv's 2n + 1


def test_value_path_matches_jets_on_a_system_tape():
    """On the rigid body's alpha tape (crb, products, sums), evaluate at degree 0 equals the
    degree-1 values to the last bit."""
    from rkhp.systems import get_system

    system = get_system("rigid-body")
    xp = np.array([0.3, -0.2, 0.9, 0.4, 1.1, -0.7])
    values = evaluate(system.alpha_tape, xp)
    jet_values, _ = evaluate(system.alpha_tape, xp, 1, 6)
    assert np.array_equal(values, jet_values)
