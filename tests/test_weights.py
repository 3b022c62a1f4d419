"""Elementary weights: the one-pass plan against the definition, every arithmetic, symbolic."""

from __future__ import annotations

from fractions import Fraction

import numpy as np
import pytest
import sympy
from hypothesis import given, settings
from hypothesis import strategies as st

from rkhp.tableaux.files import load_tableau
from rkhp.tableaux.tableau import Tableau
from rkhp.tableaux.weights import (
    FixedPointArithmetic,
    elementary_weights,
    symbolic_weights,
    tableau_symbols,
    tree_plan,
    weights_by_order,
)
from rkhp.trees.rooted import count_trees, in_t0, parse_tree, trees_up_to


def direct_weight(A, b, t):
    """a(t) straight from the definition (docs/theory.md §2), recursively, no sharing."""

    def phi(u):
        out = np.ones(len(b))
        for child in u.children:
            out = out * (A @ phi(child))
        return out

    return float(b @ phi(t))


def test_plan_indices_and_t0():
    plan = tree_plan(9)
    assert plan.starts[10] == sum(count_trees(n) for n in range(1, 10))
    for k, t in enumerate(plan.trees):
        assert bool(plan.in_t0[k]) == in_t0(t)
        if k:
            c1, r = plan.trees[plan.first[k]], plan.trees[plan.rest[k]]
            assert c1 == t.children[0] and r.children == t.children[1:]
    for n in range(1, 10):
        assert int(plan.in_t0[plan.block(n)].sum()) == count_trees(n, degenerate=True)


@settings(max_examples=20, deadline=None)
@given(st.integers(1, 4), st.booleans(), st.integers(0, 2 ** 32 - 1))
def test_one_pass_equals_the_definition(s, explicit, seed):
    rng = np.random.default_rng(seed)
    A = rng.uniform(-1, 1, (s, s))
    if explicit:
        A = np.tril(A, -1)
    b = rng.uniform(-1, 1, s)
    t = Tableau.from_arrays(A, b)
    weights = elementary_weights(t, 6)
    for tree in trees_up_to(6):
        assert weights[tree] == pytest.approx(direct_weight(t.A_float, t.b_float, tree), abs=1e-13)


def test_closed_forms_explicit_and_implicit():
    # Euler (b = [1], A = [[0]]): a(b) = 1 and a(t) = 0 for every larger tree.
    w = elementary_weights(load_tableau("euler"), 5, "exact")
    assert all(w[t] == (1 if t.order == 1 else 0) for t in w)
    # One implicit stage A = [[theta]], b = [1]: Phi(t) = theta^(|t|-1).
    w = elementary_weights(load_tableau("paper-implicit"), 5, "exact")
    theta = 1 / sympy.sqrt(3)
    assert all(sympy.simplify(w[t] - theta ** (t.order - 1)) == 0 for t in w)


def test_exact_weights_of_the_two_stage_method():
    # A = [[0,0],[1/sqrt3,0]], b = [0,1]: a(b[b]) = c_2 = 1/sqrt3, a(b[b,b]) = 1/3, a(b[b[b]]) = 0.
    w = elementary_weights(load_tableau("paper-two-stage"), 3, "exact")
    assert sympy.simplify(w[parse_tree("b[b]")] - 1 / sympy.sqrt(3)) == 0
    assert w[parse_tree("b[b,b]")] == sympy.Rational(1, 3) and w[parse_tree("b[b[b]]")] == 0


def test_arithmetics_agree_on_a_rational_tableau():
    t = load_tableau("dopri5")
    exact = elementary_weights(t, 7, "exact")
    floats = elementary_weights(t, 7, "float")
    fixed = elementary_weights(t, 7, 60)
    for tree, value in exact.items():
        assert isinstance(value, Fraction)
        assert abs(floats[tree] - float(value)) < 1e-13
        assert abs(fixed[tree] - value) < Fraction(1, 10 ** 60)


def test_fixed_point_keeps_sixty_digits_on_feagin():
    # At 60 digits the order conditions of order <= 6 hold to ~1e-58 (the coefficients' digits).
    t = load_tableau("feagin10")
    plan = tree_plan(6)
    ar = FixedPointArithmetic(60)
    for _, blk, a in weights_by_order(t, 6, ar):
        r = ar.to_floats(ar.residuals(a, plan.gamma[blk]))
        assert np.abs(r).max() < 1e-55


def test_symbolic_weights_match_numbers():
    A, b, _ = tableau_symbols(2)
    w = symbolic_weights(trees_up_to(3), 2)
    a21, b1, b2 = A[1][0], b[0], b[1]
    assert w[parse_tree("b")] == b1 + b2
    assert w[parse_tree("b[b]")] == b2 * a21
    assert sympy.expand(w[parse_tree("b[b,b]")] - b2 * a21 ** 2) == 0
    assert w[parse_tree("b[b[b]]")] == 0
    # substituting RK4 gives its exact weights
    rk4 = load_tableau("rk4")
    A4, b4, _ = tableau_symbols(4)
    values = {A4[i][j]: sympy.Rational(rk4.A[i][j].numerator, rk4.A[i][j].denominator)
              for i in range(4) for j in range(i)}
    values |= {b4[i]: sympy.Rational(rk4.b[i].numerator, rk4.b[i].denominator) for i in range(4)}
    exact = elementary_weights(rk4, 5, "exact")
    symbolic = symbolic_weights(list(exact), 4)
    for tree, value in exact.items():
        assert symbolic[tree].subs(values) == value


def test_symbolic_implicit_and_c_symbols():
    A, b, _ = tableau_symbols(1, explicit=False)
    w = symbolic_weights([parse_tree("b[b]"), parse_tree("b[b[b]]")], 1, explicit=False)
    assert w[parse_tree("b[b]")] == b[0] * A[0][0]
    assert w[parse_tree("b[b[b]]")] == b[0] * A[0][0] ** 2
    _, b2, c2 = tableau_symbols(2)
    w = symbolic_weights([parse_tree("b[b,b]")], 2, c_symbols=True)
    assert w[parse_tree("b[b,b]")] == b2[0] * c2[0] ** 2 + b2[1] * c2[1] ** 2
