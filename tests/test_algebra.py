"""The paper's tree algebra (§3–4): its worked examples and the algebraic identities."""

from __future__ import annotations

from fractions import Fraction

from hypothesis import given, settings
from hypothesis import strategies as st

from rkhp.trees.algebra import (
    butcher_product,
    compose,
    coproduct,
    exact_flow_character,
    forest,
    graft,
    graft_linear,
    hamilton_jacobi_expansion,
    inverse,
)
from rkhp.trees.rooted import LEAF, trees_of_order, trees_up_to
from rkhp.trees.rooted import parse_tree as P


def combo(d):
    return {str(t): c for t, c in d.items()}


def test_paper_grafting_examples():
    # paper §3: b[b] -> b[b] = b[b,b[b]] + b[b[b[b]]], b -> b[b,b] = b[b,b,b] + 2 b[b,b[b]],
    # b[b,b] -> b = b[b[b,b]]
    assert combo(graft(P("b[b]"), P("b[b]"))) == {"b[b,b[b]]": 1, "b[b[b[b]]]": 1}
    assert combo(graft(P("b"), P("b[b,b]"))) == {"b[b,b,b]": 1, "b[b,b[b]]": 2}
    assert combo(graft(P("b[b,b]"), P("b"))) == {"b[b[b,b]]": 1}


def test_paper_hamilton_jacobi_expansion_order_4():
    # paper eq. after (HJ): t^4/4! (b[b[b[b]]] + b[b[b,b]] + 3 b[b,b[b]] + b[b,b,b])
    assert combo(hamilton_jacobi_expansion(4)[4]) == {
        "b[b[b[b]]]": 1, "b[b[b,b]]": 1, "b[b,b[b]]": 3, "b[b,b,b]": 1}
    assert combo(hamilton_jacobi_expansion(3)[3]) == {"b[b[b]]": 1, "b[b,b]": 1}


def test_paper_degenerate_expansion_order_5():
    # paper, degenerate expansion: t^5/5! (b[b[b[b,b]]] + b[b[b,b,b]] + 4 b[b,b[b,b]] + b[b,b,b,b])
    exp = hamilton_jacobi_expansion(5, degenerate=True)
    assert combo(exp[5]) == {"b[b[b[b,b]]]": 1, "b[b[b,b,b]]": 1, "b[b,b[b,b]]": 4, "b[b,b,b,b]": 1}
    assert combo(exp[4]) == {"b[b[b,b]]": 1, "b[b,b,b]": 1}
    assert exp[2] == {}


def test_expansion_coefficients_are_butcher_multiplicities():
    for n, terms in hamilton_jacobi_expansion(8).items():
        assert terms == {t: t.multiplicity for t in trees_of_order(n)}


def test_paper_bck_coproduct_examples():
    # paper eq. (BCK_ex)
    def rendered(t):
        return {(tuple(str(x) for x in f), None if s is None else str(s)): m
                for (f, s), m in coproduct(t).items()}

    assert rendered(P("b[b[b]]")) == {
        ((), "b[b[b]]"): 1, (("b",), "b[b]"): 1, (("b[b]",), "b"): 1, (("b[b[b]]",), None): 1}
    assert rendered(P("b[b,b[b]]")) == {
        ((), "b[b,b[b]]"): 1, (("b",), "b[b,b]"): 1, (("b",), "b[b[b]]"): 1,
        (("b", "b"), "b[b]"): 1, (("b[b]",), "b[b]"): 1, (("b[b]", "b"), "b"): 1,
        (("b[b,b[b]]",), None): 1}


def test_paper_butcher_product_example():
    # paper §4: a1*a2(b[b,b[b]]) = a2(t) + a1(b)a2(b[b,b]) + a1(b)a2(b[b[b]]) + a1(b)^2 a2(b[b])
    #   + a1(b[b])a2(b[b]) + a1(b)a1(b[b])a2(b) + a1(t), checked with generic values
    names = ["b", "b[b]", "b[b,b]", "b[b[b]]", "b[b,b[b]]"]
    a1 = {P(n): Fraction(2 + k, 3 + 2 * k) for k, n in enumerate(names)}
    a2 = {P(n): Fraction(5 + 3 * k, 7 + k) for k, n in enumerate(names)}
    A1 = lambda s: a1[P(s)]
    A2 = lambda s: a2[P(s)]
    expected = (A2("b[b,b[b]]") + A1("b") * A2("b[b,b]") + A1("b") * A2("b[b[b]]")
                + A1("b") ** 2 * A2("b[b]") + A1("b[b]") * A2("b[b]")
                + A1("b") * A1("b[b]") * A2("b") + A1("b[b,b[b]]"))
    assert butcher_product(a1.__getitem__, a2.__getitem__, P("b[b,b[b]]")) == expected


def test_exact_flow_is_a_one_parameter_group():
    # e^{h} * e^{h} = e^{2h}: (e*e)(t) = 2^|t| e(t) (Butcher group, flow property)
    e = exact_flow_character(7)
    ee = compose(e, e, 7)
    assert all(ee[t] == 2 ** t.order * e[t] for t in e)


trees5 = st.sampled_from(trees_up_to(5))
values = st.fractions(min_value=-3, max_value=3, max_denominator=7)


@given(trees5, trees5, trees5)
@settings(max_examples=60, deadline=None)
def test_pre_lie_identity(x, y, z):
    # (x -> y) -> z - x -> (y -> z) is symmetric in x and y (grafting is pre-Lie, paper §3)
    X, Y, Z = {x: 1}, {y: 1}, {z: 1}

    def assoc(u, v, w):
        left = graft_linear(graft_linear(u, v), w)
        right = graft_linear(u, graft_linear(v, w))
        keys = set(left) | set(right)
        return {k: left.get(k, 0) - right.get(k, 0) for k in keys if left.get(k, 0) != right.get(k, 0)}

    assert assoc(X, Y, Z) == assoc(Y, X, Z)


@given(st.sampled_from(trees_up_to(6)))
@settings(max_examples=60, deadline=None)
def test_coassociativity(t):
    # (Delta ⊗ id) Delta = (id ⊗ Delta) Delta, forests expanded multiplicatively
    from collections import Counter

    def delta_forest(f):
        out = Counter({((), ()): 1})
        for tree in f:
            nxt = Counter()
            for (l1, r1), m1 in out.items():
                for (cut, sub), m2 in coproduct(tree).items():
                    nxt[(forest(l1 + cut), forest(r1 + (() if sub is None else (sub,))))] += m1 * m2
            out = nxt
        return out

    left, right = Counter(), Counter()
    for (cut, sub), m in coproduct(t).items():
        s = () if sub is None else (sub,)
        for (a, b), m2 in delta_forest(cut).items():
            left[(a, b, forest(s))] += m * m2
        for (a, b), m2 in delta_forest(s).items():
            right[(forest(cut), a, b)] += m * m2
    assert left == right


def random_character(data, order):
    return {t: data.draw(values) for t in trees_up_to(order)}


@given(st.data())
@settings(max_examples=25, deadline=None)
def test_butcher_product_is_associative(data):
    a, b, c = (random_character(data, 5) for _ in range(3))
    ab = compose(a, b, 5)
    bc = compose(b, c, 5)
    assert compose(ab, c, 5) == compose(a, bc, 5)


@given(st.data())
@settings(max_examples=25, deadline=None)
def test_antipode_inverts(data):
    a = random_character(data, 6)
    inv = inverse(a, 6)
    assert all(v == 0 for v in compose(a, inv, 6).values())
    assert all(v == 0 for v in compose(inv, a, 6).values())


def test_inverse_of_exact_flow_is_backward_flow():
    # (e^{h})^{-1} = e^{-h}: e^{-1}(t) = (-1)^|t| e(t)
    e = exact_flow_character(6)
    assert inverse(e, 6) == {t: (-1) ** t.order * e[t] for t in e}


def test_leaf_graft_is_root_attachment():
    assert graft(LEAF, LEAF) == {P("b[b]"): 1}


def _weights(A, b, order):
    """Elementary weights a(t) = sum_i b_i Phi_i(t) by the recursion of docs/theory.md §2 (test oracle)."""
    s = len(b)
    phi = {}
    out = {}
    for t in trees_up_to(order):
        v = [Fraction(1)] * s
        for c in t.children:
            u = [sum(A[i][j] * phi[c][j] for j in range(s)) for i in range(s)]
            v = [v[i] * u[i] for i in range(s)]
        phi[t] = v
        out[t] = sum(b[i] * v[i] for i in range(s))
    return out


def test_composition_of_tableaux_is_the_butcher_product():
    # docs/theory.md §3: one step 2h of the concatenated tableau = method 1 then method 2 with step h, so
    # its weight at t is (a1 * a2)(t) / 2^|t|. Method 1: Heun's RK2, method 2: Kutta's RK3.
    F = Fraction
    A1, b1 = [[F(0), F(0)], [F(1), F(0)]], [F(1, 2), F(1, 2)]
    A2 = [[F(0)] * 3, [F(1, 2), F(0), F(0)], [F(-1), F(2), F(0)]]
    b2 = [F(1, 6), F(2, 3), F(1, 6)]
    s1, s2 = 2, 3
    A = [[F(0)] * (s1 + s2) for _ in range(s1 + s2)]
    for i in range(s1):
        for j in range(s1):
            A[i][j] = A1[i][j] / 2
    for i in range(s2):
        for j in range(s1):
            A[s1 + i][j] = b1[j] / 2
        for j in range(s2):
            A[s1 + i][s1 + j] = A2[i][j] / 2
    b = [x / 2 for x in b1] + [x / 2 for x in b2]
    order = 6
    a1, a2, a = _weights(A1, b1, order), _weights(A2, b2, order), _weights(A, b, order)
    product = compose(a1, a2, order)
    assert all(a[t] == product[t] / 2 ** t.order for t in a)
