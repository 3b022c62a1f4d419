"""Trees: counts against OEIS, T_0 against its definition, notation, sigma and gamma (docs/theory.md §1)."""

from __future__ import annotations

from fractions import Fraction
from math import factorial

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from rkhp.base.errors import InputError
from rkhp.trees.rooted import (
    LEAF,
    Tree,
    count_trees,
    from_children,
    in_t0,
    parse_tree,
    trees_of_order,
    trees_up_to,
)

# OEIS A000081, number of rooted trees with n nodes, n = 1..16
A000081 = [1, 1, 2, 4, 9, 20, 48, 115, 286, 719, 1842, 4766, 12486, 32973, 87811, 235381]
# The paper's Table 1 lists 1, 0, 1, 2, 4 trees of T_0 for orders 1..5.
PAPER_T0 = [1, 0, 1, 2, 4]


def test_counts_match_oeis_a000081_to_order_16():
    assert [count_trees(n) for n in range(1, 17)] == A000081


def test_enumeration_matches_oeis_to_order_12():
    assert [len(trees_of_order(n)) for n in range(1, 13)] == A000081[:12]


def test_enumeration_to_order_16_is_complete_and_distinct():
    all_trees = trees_up_to(16)
    assert len(all_trees) == sum(A000081) == 376464
    assert len({t.key for t in trees_of_order(14)}) == A000081[13]


def test_t0_counts_match_paper_table_1():
    assert [count_trees(n, degenerate=True) for n in range(1, 6)] == PAPER_T0
    assert [len(trees_of_order(n, degenerate=True)) for n in range(1, 6)] == PAPER_T0


def test_t0_direct_enumeration_equals_filtered_t_to_order_12():
    for n in range(1, 13):
        direct = trees_of_order(n, degenerate=True)
        filtered = [t for t in trees_of_order(n) if in_t0(t)]
        assert list(direct) == filtered  # same trees, same canonical order
        assert count_trees(n, degenerate=True) == len(direct)


def test_paper_table_1_tree_order():
    # The paper lists order 4 as b[b[b,b]], b[b,b,b] and order 5 as below (Table 1).
    assert [str(t) for t in trees_of_order(4, True)] == ["b[b[b,b]]", "b[b,b,b]"]
    assert [str(t) for t in trees_of_order(5, True)] == [
        "b[b[b[b,b]]]", "b[b[b,b,b]]", "b[b,b[b,b]]", "b[b,b,b,b]"]


def test_b_b_is_not_in_t0():
    assert not parse_tree("b[b]").in_t0
    assert not parse_tree("b[b,b[b]]").in_t0
    assert parse_tree("b[b,b[b,b]]").in_t0


@pytest.mark.parametrize(
    "text, sigma, gamma",
    [
        # Butcher (2016), Table 301(I) / Hairer–Nørsett–Wanner Table II.2.1
        ("b", 1, 1), ("b[b]", 1, 2), ("b[b,b]", 2, 3), ("b[b[b]]", 1, 6),
        ("b[b,b,b]", 6, 4), ("b[b,b[b]]", 1, 8), ("b[b[b,b]]", 2, 12), ("b[b[b[b]]]", 1, 24),
        ("b[b,b,b,b]", 24, 5), ("b[b,b[b,b]]", 2, 15), ("b[b[b],b[b]]", 2, 20),
        ("b[b[b,b,b]]", 6, 20), ("b[b[b[b,b]]]", 2, 60),
    ],
)
def test_sigma_gamma_of_small_trees(text, sigma, gamma):
    t = parse_tree(text)
    assert (t.sigma, t.gamma) == (sigma, gamma)
    assert t.e == Fraction(1, gamma)


def test_multiplicities_sum_to_n_minus_1_factorial():
    # Butcher: sum over trees of order n of alpha(t) = (n-1)! (number of recursive trees).
    for n in range(1, 11):
        assert sum(t.multiplicity for t in trees_of_order(n)) == factorial(n - 1)


def test_sigma_counts_labelled_trees():
    # Cayley: n^(n-1) rooted labelled trees = sum n!/sigma(t).
    for n in range(1, 10):
        assert sum(factorial(n) // t.sigma for t in trees_of_order(n)) == n ** (n - 1)


def test_non_planar_equality_and_spaces():
    assert parse_tree("b[b,b[b]]") == parse_tree("b[ b[b] , b ]")
    assert hash(parse_tree("b[b,b[b]]")) == hash(parse_tree("b[b[b],b]"))
    assert str(parse_tree("b[b[b],b]")) == "b[b,b[b]]"
    assert parse_tree("\\forest{b[b,b[b]]}").latex() == "\\forest{b[b,b[b]]}"
    assert Tree([LEAF, parse_tree("b[b]")]) == parse_tree("b[b,b[b]]")


@pytest.mark.parametrize("bad", ["", "c", "b[", "b[]", "b[b,,b]", "b]b", "b[b]]", "bb", "b[b;b]", "x[b]"])
def test_malformed_trees_raise_input_error(bad):
    with pytest.raises(InputError):
        parse_tree(bad)


def test_trees_are_immutable():
    t = parse_tree("b[b]")
    with pytest.raises((AttributeError, TypeError)):
        t.order = 3


@st.composite
def random_trees(draw, depth=4):
    if depth == 0:
        return LEAF
    kids = draw(st.lists(random_trees(depth=depth - 1), max_size=3))
    return from_children(kids)


@given(random_trees())
@settings(max_examples=200, deadline=None)
def test_parse_format_round_trip(t):
    assert parse_tree(str(t)) == t
    u = parse_tree(str(t))
    assert (u.order, u.sigma, u.gamma, u.key) == (t.order, t.sigma, t.gamma, t.key)


@given(random_trees())
@settings(max_examples=100, deadline=None)
def test_random_tree_is_enumerated(t):
    if t.order <= 9:
        assert t in set(trees_of_order(t.order))
        assert (t in set(trees_of_order(t.order, True))) == in_t0(t)
