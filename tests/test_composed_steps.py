"""The series of a composition of RKHP steps against the Butcher product
(docs/modified.md, docs/theory.md §11).

Outside values: the harmonic oscillator, where a generating function S = c H is the Cayley
rotation by 2 arctan(c/2), so two implicit midpoint steps (RKHP Euler) have c = 2h/(1 - h^2/4);
the exact flow's group property (two steps of h are one of 2h: c(t) = 2^|t| e(t)/sigma(t)); the
Butcher product of rkhp.trees.algebra (checked against the paper's example in tests/test_algebra.py).
"""

from __future__ import annotations

import json
from fractions import Fraction

import pytest

from rkhp.base.errors import InputError
from rkhp.series.composed_steps import composition_series
from rkhp.series.modified import method_character
from rkhp.tableaux.files import load_tableau
from rkhp.trees.algebra import exact_flow_character
from rkhp.trees.rooted import parse_tree

T = parse_tree


def _method(name, order):
    return method_character(load_tableau(name), order)


@pytest.fixture(scope="module")
def euler_twice():
    return composition_series([_method("euler", 5)] * 2, 5, "symmetric", ["euler", "euler"])


def test_two_midpoint_steps_are_the_cayley_rotation_by_4_arctan(euler_twice, oscillator):
    """S = c H with c = 2h/(1 - h^2/4) = 2h + h^3/2 + h^5/8 on the harmonic oscillator."""
    assert euler_twice.groupoid_order == 5
    assert oscillator(euler_twice.groupoid, 5) == [2, 0, Fraction(1, 2), 0, Fraction(1, 8)]


def test_the_butcher_product_is_the_concatenated_tableau_not_the_two_steps(euler_twice, oscillator):
    """The 2h step of the concatenated tableau gives 2h H + h^3/4 H (docs/theory.md §11): the
    Butcher product; its h^3 term is half the composed steps'."""
    assert oscillator(euler_twice.butcher, 5)[:3] == [2, 0, Fraction(1, 4)]
    assert euler_twice.groupoid[T("b[b,b]")] == 2 * euler_twice.butcher[T("b[b,b]")]
    assert euler_twice.first_difference("groupoid", "butcher") == 3
    assert euler_twice.first_difference("groupoid", "butcher_reversed") == 3


def test_the_hamilton_jacobi_composition_is_the_butcher_product(euler_twice):
    assert euler_twice.first_difference("restart", "butcher") is None
    three = composition_series([_method("heun", 4), _method("rk4", 4), _method("euler", 4)], 4, "general")
    assert three.first_difference("restart", "butcher") is None
    assert three.first_difference("restart", "butcher_reversed") == 3  # the order matters


def test_two_exact_steps_are_one_exact_step_of_2h():
    e = exact_flow_character(5)
    series = composition_series([e, e], 5, "symmetric")
    for level in series.basis:
        for t in level:
            assert series.groupoid.get(t, 0) == series.butcher.get(t, 0)
    assert series.groupoid[T("b[b,b]")] == Fraction(2**3, 3 * 2)  # 2^|t| e(t)/sigma(t)


def test_an_exact_flow_applied_first_composes_by_the_papers_product():
    """Paper Prop. 4.2 with eq. (9): the map phi_2 o phi_1 gets a_2 * a_1; this holds when phi_1
    is the exact flow (the Hamilton–Jacobi equation restarted from a bisection is its product with
    the flow's), and fails otherwise."""
    heun = _method("heun", 4)
    exact_first = composition_series([exact_flow_character(4), heun], 4, "general")
    assert exact_first.first_difference("groupoid", "butcher_reversed") is None
    assert exact_first.first_difference("groupoid", "butcher") == 4
    heun_first = composition_series([heun, exact_flow_character(4)], 4, "symmetric")
    assert heun_first.groupoid_order == 4
    assert heun_first.first_difference("groupoid", "butcher_reversed") == 4
    assert heun_first.first_difference("groupoid", "butcher") == 4


def test_radical_weights_and_degenerate_realisations():
    a = _method("paper-three-stage", 4)
    series = composition_series([a, a], 4, "degenerate")
    assert series.restart is None
    assert series.groupoid_order == 4
    assert series.first_difference("groupoid", "butcher") == 3


def test_compose_cli(run_cli):
    code, out, err = run_cli("compose", "euler,euler", "--order", "4", "--symmetric", "--format", "json")
    assert code == 0, err
    doc = json.loads(out)
    assert doc["methods"] == ["euler", "euler"] and doc["class"] == "symmetric" and doc["order"] == 4
    assert doc["first_difference"] == {"composition_vs_butcher_product": 3,
                                       "composition_vs_butcher_product_reversed": 3,
                                       "hamilton_jacobi_vs_butcher_product": None}
    row = next(t for t in doc["terms"] if t["tree"] == "b[b,b]")
    assert row == {"tree": "b[b,b]", "order": 3, "composition": "1", "hamilton_jacobi": "1/2",
                   "butcher_product": "1/2", "butcher_product_reversed": "1/2"}
    for args in (["euler"], ["euler,nosuch"], ["euler,euler", "--order", "9"], [",euler"]):
        code, out, err = run_cli("compose", *args)
        assert code == 2 and len(err.strip().splitlines()) == 1, (args, err)


def test_bad_input():
    with pytest.raises(InputError):
        composition_series([_method("euler", 3)], 3)
