"""Relations among elementary differentials of symmetric birealisations (docs/theory.md §8)."""

from __future__ import annotations

import json
from fractions import Fraction

import numpy as np
import pytest
from cli_run import rkhp

from rkhp.base.errors import InputError
from rkhp.base.modular import (
    PRIMES,
    crt_pair,
    nullspace_mod,
    rational_reconstruction,
    rref_fraction,
    rref_mod,
    to_residue,
)
from rkhp.series.relation_derivation import derive_relations
from rkhp.trees.relations import (
    MAX_SHIPPED_ORDER,
    conditions_from_relations,
    relation_space,
    shipped_relations,
    symmetric_condition_rows,
)
from rkhp.trees.rooted import LEAF, from_children, parse_tree, trees_of_order

T = parse_tree


def _rank(rows) -> int:
    return len(rref_fraction(rows)[1]) if rows else 0


def _in_span(vector, rows) -> bool:
    return _rank(list(rows) + [vector]) == _rank(list(rows))


# ----------------------------------------------------------------------------- modular arithmetic


def test_primes_are_prime_and_below_2_31():
    import sympy

    assert all(sympy.isprime(p) and p < 2**31 for p in PRIMES)
    assert len(set(PRIMES)) == len(PRIMES)


@pytest.mark.parametrize("q", [Fraction(0), Fraction(1), Fraction(-7, 3), Fraction(12345, 678), Fraction(-1, 2**14)])
def test_rational_reconstruction_recovers_small_fractions(q):
    p1, p2 = PRIMES[:2]
    assert rational_reconstruction(to_residue(q, p1), p1) == q
    both = crt_pair(to_residue(q, p1), p1, to_residue(q, p2), p2)
    assert both % p1 == to_residue(q, p1) and both % p2 == to_residue(q, p2)
    assert rational_reconstruction(both, p1 * p2) == q


def test_a_fraction_too_large_for_the_modulus_is_caught_by_the_next_prime():
    """Too small a modulus yields a wrong fraction or none; a further prime exposes it."""
    q = Fraction(2**20 + 1, 2**20 - 3)
    p1, p2 = PRIMES[:2]
    try:
        wrong = rational_reconstruction(to_residue(q, p1), p1)
    except ValueError:
        wrong = None
    assert wrong != q
    assert wrong is None or to_residue(wrong, p2) != to_residue(q, p2)
    with pytest.raises(ValueError):
        rational_reconstruction(5, 7)


def test_rref_modulo_p_agrees_with_exact_rref():
    rng = np.random.default_rng(3)
    for _ in range(20):
        rows, cols, rank = (int(x) for x in rng.integers(1, 7, size=3))
        m = rng.integers(-5, 6, size=(rows, min(rank, rows))) @ rng.integers(-5, 6, size=(min(rank, rows), cols))
        exact, pivots = rref_fraction(m.tolist())
        red, piv = rref_mod(m, PRIMES[0])
        assert piv == pivots
        assert [[to_residue(x, PRIMES[0]) for x in row] for row in exact] == red.tolist()
        null = nullspace_mod(m, PRIMES[0])
        assert null.shape[0] == cols - len(pivots)
        assert all(sum(int(a) * int(b) for a, b in zip(row, v)) % PRIMES[0] == 0 for row in m for v in null)


# ----------------------------------------------------------------------------- elementary differentials


def test_jets_match_the_definition_by_symbolic_differentiation():
    """F(t)(0) on jets equals docs/theory.md §5's definition differentiated by sympy (constant pi)."""
    import sympy

    from rkhp.series.differentials import constant_pi_jets, monomial_basis

    dim, order = 3, 5
    x = sympy.symbols("x0:3")
    rng = np.random.default_rng(7)
    basis = monomial_basis(dim, order - 1)
    coeffs = rng.integers(-3, 4, size=basis.sizes[-1])
    H = sympy.Poly(sum(int(c) * sympy.prod([xi**int(e) for xi, e in zip(x, exps)])
                       for c, exps in zip(coeffs, basis.exponents)), *x)
    upper = rng.integers(-3, 4, size=(dim, dim))
    pi = upper - upper.T
    memo = {}

    def F(t):  # (-2)^(|t|-1) F(t) as a polynomial, straight from the definition
        if t in memo:
            return memo[t]
        if not t.children:
            return H
        vecs = []
        for c in t.children:
            g = [F(c).diff(xi) for xi in x]
            vecs.append([sum((int(pi[i, j]) * g[j] for j in range(dim)), sympy.Poly(0, *x)) for i in range(dim)])
        total = sympy.Poly(0, *x)
        for idx in np.ndindex(*([dim] * len(vecs))):
            term = H
            for i in idx:
                term = term.diff(x[i])
            for v, i in zip(vecs, idx):
                term = term * v[i]
            total = total + term
        memo[t] = total
        return total

    trees = [t for n in (3, 4, 5) for t in trees_of_order(n, True)]
    got = constant_pi_jets(trees, order, np.array(coeffs, dtype=object)[:, None],
                           np.array(pi, dtype=object)[:, :, None], None)
    for t in trees:
        assert got[t][0] == F(t).coeff_monomial(1), str(t)


def test_order_four_oddness_on_every_family():
    """F(b[b,b,b]) + F(b[b[b,b]]) = 0 (docs/theory.md §8) on constant pi, so(3)* and log-canonical."""
    from rkhp.series.differentials import constant_pi_values, general_values

    trees = trees_of_order(4, True)
    p = PRIMES[2]
    rng = np.random.default_rng(11)
    for values in (constant_pi_values(trees, 4, 6, 4, rng, p), general_values(trees, 4, "lie-poisson", 4, rng, p),
                   general_values(trees, 4, "log-canonical", 4, rng, p, dim=3)):
        a, b = (values[t] for t in trees)
        assert np.all((a + b) % p == 0)
        assert np.all(a % p != 0)


def test_quartic_realisation_breaks_the_symmetric_relations():
    """Degenerate but not symmetric (docs/theory.md §8): trees outside T_0 still vanish, the relations fail."""
    from rkhp.series.differentials import general_values

    p = PRIMES[1]
    trees = [t for n in range(1, 6) for t in trees_of_order(n)]
    values = general_values(trees, 5, "constant", 12, np.random.default_rng(4), p, dim=3, realisation="quartic")
    assert all(np.all(values[t] % p == 0) for t in trees if not t.in_t0)  # paper, Thm superconvergence
    a, b = (values[t] for t in trees_of_order(4, True))
    assert np.all((a + b) % p != 0)
    for n in (4, 5):
        tn = trees_of_order(n, True)
        assert nullspace_mod(np.array([values[t] for t in tn]).T, p).shape[0] == 0


@pytest.mark.parametrize("family", ["lie-poisson", "log-canonical"])
def test_trees_outside_t0_vanish_on_symmetric_families(family):
    from rkhp.series.differentials import general_values

    p = PRIMES[1]
    trees = [t for n in range(1, 6) for t in trees_of_order(n)]
    values = general_values(trees, 5, family, 3, np.random.default_rng(5), p)
    assert all(np.all(values[t] % p == 0) == (not t.in_t0) for t in trees)


# ----------------------------------------------------------------------------- shipped relations


def test_shipped_counts_add_up_to_t0():
    data = shipped_relations()
    assert data.max_order == MAX_SHIPPED_ORDER == 8
    counts = [len(o.trees) for o in data.orders]
    assert counts == [1, 0, 1, 2, 4, 8, 17, 36]  # paper Table 1 and docs/theory.md §1
    for o in data.orders:
        assert len(o.relations) + len(o.conditions) == len(o.trees)
        assert _rank(o.relations) == len(o.relations)


def test_conditions_up_to_order_five_are_those_of_notes_section_8():
    rows = {n: {(tuple(map(str, ts)), ws) for ts, ws in symmetric_condition_rows(n)} for n in range(1, 6)}
    one = Fraction(1)
    assert rows[1] == {(("b",), (one,))}
    assert rows[2] == set()
    assert rows[3] == {(("b[b,b]",), (one,))}
    # order 4: r(b[b,b,b]) = r(b[b[b,b]])
    assert rows[4] == {(("b[b[b,b]]", "b[b,b,b]"), (one, -one))}
    # order 5: r(b[b,b,b,b]) = 0, r(b[b,b[b,b]]) = 0, r(b[b[b,b,b]]) = r(b[b[b[b,b]]])
    assert rows[5] == {(("b[b,b,b,b]",), (one,)), (("b[b,b[b,b]]",), (one,)),
                       (("b[b[b[b,b]]]", "b[b[b,b,b]]"), (one, -one))}


def test_relations_of_order_four_and_five():
    assert relation_space(4) == ((Fraction(1), Fraction(1)),)
    trees = trees_of_order(5, True)
    (rel,) = relation_space(5)
    assert {str(t): c for t, c in zip(trees, rel) if c} == {"b[b[b,b,b]]": 1, "b[b[b[b,b]]]": 1}


@pytest.mark.parametrize("n", [2, 4, 6, 8])
def test_exact_flow_is_odd_at_every_even_order(n):
    """sum over T_0 of e(t)/sigma(t) F(t) = 0 at even orders: the generating function is odd in h."""
    trees = trees_of_order(n, True)
    if not trees:
        return
    vector = [Fraction(1, t.gamma * t.sigma) for t in trees]
    assert _in_span(vector, relation_space(n))


@pytest.mark.parametrize("n", [3, 5, 7])
def test_exact_flow_is_not_a_relation_at_odd_orders(n):
    trees = trees_of_order(n, True)
    assert not _in_span([Fraction(1, t.gamma * t.sigma) for t in trees], relation_space(n))


@pytest.mark.parametrize("n", range(3, MAX_SHIPPED_ORDER))
def test_relations_propagate_by_grafting(n):
    """F(b[t, rest]) is linear in F(t): a relation at order n gives one at order n + |rest| + 1."""
    contexts = [(), (LEAF,), (LEAF, LEAF), (from_children([LEAF, LEAF]),)]
    for rest in contexts:
        m = n + 1 + sum(c.order for c in rest)
        if m > MAX_SHIPPED_ORDER:
            continue
        target = trees_of_order(m, True)
        col = {t: k for k, t in enumerate(target)}
        for rel in relation_space(n):
            v = [Fraction(0)] * len(target)
            for c, t in zip(rel, trees_of_order(n, True)):
                v[col[from_children((t,) + rest)]] += c
            assert _in_span(v, relation_space(m)), (n, rest)


def test_conditions_annihilate_exactly_the_relations():
    for o in shipped_relations().orders:
        col = {t: k for k, t in enumerate(o.trees)}
        for ts, ws in o.conditions:
            # weights on r(t) = gamma sigma * (weights on d); d in L_n must be orthogonal
            p = [Fraction(0)] * len(o.trees)
            for t, w in zip(ts, ws):
                p[col[t]] = w * t.gamma * t.sigma
            assert all(sum(a * b for a, b in zip(p, rel)) == 0 for rel in o.relations)
        assert conditions_from_relations(o.trees, o.relations) == o.conditions


def test_symmetric_order_conditions_for_the_conditions_module():
    from rkhp.trees.conditions import OrderCondition, order_conditions, symmetric_order_conditions

    (c,) = symmetric_order_conditions(4)
    assert isinstance(c, OrderCondition)
    assert c.trees == (T("b[b[b,b]]"), T("b[b,b,b]")) and c.weights == (1, -1)
    assert [len(order_conditions(n, "symmetric", exact_order=True)) for n in range(1, 9)] == \
        [len(o.conditions) for o in shipped_relations().orders]


def test_above_the_shipped_order_is_an_input_error():
    with pytest.raises(InputError, match="regenerate"):
        relation_space(MAX_SHIPPED_ORDER + 1)
    with pytest.raises(InputError):
        symmetric_condition_rows(0)


@pytest.mark.parametrize("name, order", [("paper-three-stage", 4), ("paper-two-stage", 3), ("euler", 2)])
def test_paper_methods_symmetric_order(name, order):
    """The paper's methods keep their degenerate order, and no more, under the symmetric class."""
    import sympy

    from rkhp.tableaux.files import load_tableau
    from rkhp.tableaux.weights import elementary_weights

    a = elementary_weights(load_tableau(name), order + 1, precision="exact")

    def holds(n):
        return all(sympy.simplify(sum(w * (t.gamma * a[t] - 1) for t, w in zip(ts, ws))) == 0
                   for ts, ws in symmetric_condition_rows(n))

    assert all(holds(n) for n in range(1, order + 1))
    assert not holds(order + 1)


# ----------------------------------------------------------------------------- regeneration


def test_regeneration_reproduces_the_shipped_data_to_order_six():
    data = derive_relations(6, seed=5)
    for o in data.orders:
        shipped = shipped_relations().of_order(o.order)
        assert o.relations == shipped.relations and o.conditions == shipped.conditions
        assert o.checks["lie_poisson_so3"]["equal"]
        assert o.checks["exact_instances"] == 2


def test_relations_do_not_depend_on_the_dimension_or_family():
    """Constant pi in dimension 4 and log-canonical in dimension 4 give the same spaces (order <= 6)."""
    from rkhp.series.differentials import constant_pi_values, general_values

    p = PRIMES[3]
    trees = [t for n in range(1, 7) for t in trees_of_order(n, True)]
    rng = np.random.default_rng(2)
    for values in (constant_pi_values(trees, 6, 4, 14, rng, p), general_values(trees, 6, "log-canonical", 14, rng, p,
                                                                              dim=4)):
        for n in range(3, 7):
            tn = trees_of_order(n, True)
            null = nullspace_mod(np.array([values[t] for t in tn]).T, p)
            expected = [[to_residue(c, p) for c in row] for row in relation_space(n)]
            assert null.tolist() == rref_mod(np.array(expected, dtype=np.int64), p)[0].tolist() if expected \
                else null.shape[0] == 0


@pytest.mark.slow
def test_regeneration_reproduces_the_shipped_data_to_order_eight():
    data = derive_relations(8, seed=1)
    for o in data.orders:
        shipped = shipped_relations().of_order(o.order)
        assert o.relations == shipped.relations and o.conditions == shipped.conditions
        assert o.checks["lie_poisson_so3"]["contains_all"]


# ----------------------------------------------------------------------------- command line


def _rkhp(*args):
    return rkhp(*args)


def test_cli_relations_json():
    out = _rkhp("relations", "--order", "5", "--format", "json")
    assert out.returncode == 0, out.stderr
    doc = json.loads(out.stdout)
    assert doc["source"] == "shipped" and doc["max_order"] == 5
    assert [o["conditions_count"] for o in doc["orders"]] == [1, 0, 1, 1, 3]
    assert doc["orders"][3]["relations"][0]["text"] == "F(b[b[b,b]]) + F(b[b,b,b]) = 0"
    assert set(doc["orders"][4]) >= {"order", "trees", "t0_count", "relations_count", "conditions_count",
                                     "relations", "conditions", "checks"}


def test_cli_relations_table_prints_brackets_verbatim():
    out = _rkhp("relations", "--order", "4")
    assert out.returncode == 0, out.stderr
    assert "r(b[b[b,b]]) - r(b[b,b,b]) = 0" in out.stdout


@pytest.mark.parametrize("args", [("--order", "9"), ("--order", "0"), ("--order", "3", "--output", "x.json")])
def test_cli_relations_bad_input_is_one_line(args):
    out = _rkhp("relations", *args)
    assert out.returncode == 2
    assert out.stderr.count("\n") == 1 and "Traceback" not in out.stderr
