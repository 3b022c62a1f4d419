"""The Taylor machinery (rkhp.taylor): every elementary opcode's jets against sympy at every
degree, the value path against the jet path, the tape's sub-programs."""

from __future__ import annotations

import math

import numpy as np
import pytest
import sympy

from rkhp.taylor import tape as tp
from rkhp.taylor.interpreter import evaluate, interpreter, tape_work
from rkhp.taylor.jets import jet_space, monomials
from rkhp.taylor.ops import BY_NAME, COMPOSITE, DERIVED, FUNCTION, OPS, PHIMV, SPRAY

DEGREES = range(0, 7)
X, Y = sympy.symbols("x y", real=True)
W = sympy.Symbol("w", positive=True)
#: the inner functions every operation is composed with: polynomials in (x, y), positive near 0
INNER = (sympy.Rational(7, 10) + sympy.Rational(3, 10) * X - Y / 5 + X * Y / 10 + X ** 2 / 20,
         sympy.Rational(6, 5) - X / 4 + Y ** 2 / 2)


def _inner(x, y):
    """INNER on tape values (the same polynomials, their coefficients rounded to float64)."""
    return 0.7 + 0.3 * x - 0.2 * y + 0.1 * (x * y) + 0.05 * (x * x), 1.2 - 0.25 * x + 0.5 * (y * y)


G, H = INNER
#: every elementary opcode (ARITHMETIC and FUNCTION kinds of the opcode table): how to record it
#: on the inner values g, h, and the composed function it computes (sympy)
CASES = {
    "const": (lambda g, h: g.builder.const(0.25), sympy.Rational(1, 4)),
    "add": (lambda g, h: g + h, G + H),
    "sub": (lambda g, h: g - h, G - H),
    "mul": (lambda g, h: g * h, G * H),
    "neg": (lambda g, h: -g, -G),
    "mulc": (lambda g, h: 2.5 * g, sympy.Rational(5, 2) * G),
    "addc": (lambda g, h: g + 1.5, G + sympy.Rational(3, 2)),
    "div": (lambda g, h: g / h, G / H),
    "powi": (lambda g, h: g ** -3, G ** -3),
    "powr": (lambda g, h: g ** 1.5, G ** sympy.Rational(3, 2)),
    # c(|p|^2), p = (g, h) (docs/theory.md §4): c(w) composed with w = g^2 + h^2 (see _coefficients)
    "crb": (lambda g, h: tp.crb([g, h]), ((1 - sympy.sqrt(W) / 2 * sympy.cot(sympy.sqrt(W) / 2)) / W,
                                          G ** 2 + H ** 2)),
    **{op.name: (lambda g, h, f=tp.RECORDERS[op.sympy]: f(g), getattr(sympy, op.sympy)(G))
       for op in OPS if op.kind == FUNCTION and op.sympy},
    # recorded as compositions of the table's functions (rkhp.taylor.ops.DERIVED)
    **{d.name: (lambda g, h, f=tp.RECORDERS[d.sympy]: f(g), getattr(sympy, d.sympy)(G)) for d in DERIVED},
}
#: the other branches of the same opcodes: POWI with k >= 0 (repeated products), and CRB's closed
#: form (20 <= |p|^2 < (2 pi)^2; its power series below)
BRANCHES = {"powi+": (lambda g, h: g ** 3, G ** 3), "powi0": (lambda g, h: g ** 0 + h, 1 + H),
            "crb-far": (lambda g, h: tp.crb([5.0 * g, 4.0 * h]),
                        (CASES["crb"][1][0], 25 * G ** 2 + 16 * H ** 2))}


def _record(record):
    builder = tp.TapeBuilder(2)
    x, y = builder.inputs()
    return builder.finish([record(*_inner(x, y))])


def _jet(tape, D):
    """The jet at (0, 0) of the tape's output in (x, y) truncated at degree D."""
    space = jet_space(2, D)
    work = tape_work((tape,), space.size)
    if D:
        work.W[0, 1] = work.W[1, 2] = 1.0  # x = 0 + dx, y = 0 + dy
    interpreter(tape)(tape, D, space, work)
    return work.W[tape.outputs[0]].copy()


def _taylor_coefficients(expr, D):
    """{(a, b): d^a_x d^b_y F(0, 0) / (a! b!)} for a + b <= D, by sympy at 30 digits. F is `expr`,
    or for a pair (f(w), u(x, y)) the composition f(u): then sympy takes the derivatives of f at
    u(0, 0) and composes its Taylor polynomial with u exactly (differentiating the composed
    closed form of c(|p|^2) takes minutes)."""
    if isinstance(expr, tuple):
        f, u = expr
        u0 = u.subs({X: 0, Y: 0})
        series = sum(sympy.diff(f, W, q).subs(W, u0).evalf(30) / math.factorial(q) * (u - u0) ** q
                     for q in range(D + 1))
        poly = sympy.Poly(sympy.expand(series), X, Y)
        return {(a, b): float(poly.coeff_monomial(X ** a * Y ** b))
                for a in range(D + 1) for b in range(D + 1 - a)}
    out = {}
    dx = expr
    for a in range(D + 1):
        dxy = dx
        for b in range(D + 1 - a):
            value = dxy.subs({X: 0, Y: 0}).evalf(30)
            out[a, b] = float(value) / (math.factorial(a) * math.factorial(b))
            dxy = sympy.diff(dxy, Y)
        dx = sympy.diff(dx, X)
    return out


def test_every_elementary_opcode_is_covered():
    """Every ARITHMETIC and FUNCTION row of the opcode table is exercised by its case."""
    elementary = {op.name for op in OPS if op.kind != COMPOSITE}
    assert elementary <= set(CASES)
    for name in elementary:
        assert BY_NAME[name].code in _record(CASES[name][0]).ops[:, 0], name


@pytest.mark.parametrize("name", sorted(CASES) + sorted(BRANCHES))
def test_every_opcode_at_every_degree_against_sympy(name):
    """f(g(x, y), h(x, y)) as a jet at degree D = 0..6 holds the Taylor coefficients of the
    composed function (sympy's derivatives, 30 digits) of every monomial of degree <= D, and its
    value is the degree-0 path's (the value-only interpreter) to the last bit."""
    record, expr = {**CASES, **BRANCHES}[name]
    tape = _record(record)
    value = _jet(tape, 0)[0]
    exact = _taylor_coefficients(expr, DEGREES[-1])
    for D in DEGREES:
        jet = _jet(tape, D)
        assert jet[0] == value, (name, D)
        for m, (a, b) in enumerate(monomials(2, D)):
            assert jet[m] == pytest.approx(exact[a, b], rel=1e-12, abs=1e-13), (name, D, (a, b))


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
    cos(y) p at two points, as degree-2 jets in (y, p), against the derivatives by hand. The tape
    is of the spray class, as the spray kernel's tapes are: the compiled run_rows it calls."""
    from rkhp.taylor.rows import run_rows, subprogram_at

    builder = tp.TapeBuilder(2)
    x, p = builder.inputs()
    sub = builder.subprogram(2, lambda v: [tp.cos(v[0]) * v[1]])
    tape = tp.tape_class((SPRAY,))(*builder.finish([x]))
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
        builder.subprogram(3, lambda v: tp.record_phimv([[v[0]]], [v[1]]))
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
