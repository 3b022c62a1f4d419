"""Order conditions in Butcher's form: the paper's Table 1 and the forms quoted in docs/theory.md §2."""

from __future__ import annotations

from fractions import Fraction

import pytest

from rkhp.base.errors import InputError
from rkhp.trees.conditions import butcher_form, conditions_of_order, latex_form, order_conditions
from rkhp.trees.rooted import parse_tree as P

# The paper's Table 1: the 8 trees of T_0 up to order 5 and their conditions (LaTeX as printed).
PAPER_TABLE_1 = [
    (1, "b", r"\sum_{i=1}^s b_i", Fraction(1)),
    (3, "b[b,b]", r"\sum_{i=1}^s b_i c_i^2", Fraction(1, 3)),
    (4, "b[b[b,b]]", r"\sum_{i,j=1}^s b_i a_{ij} c_j^2", Fraction(1, 12)),
    (4, "b[b,b,b]", r"\sum_{i=1}^s b_i c_i^3", Fraction(1, 4)),
    (5, "b[b[b[b,b]]]", r"\sum_{i,j,k=1}^s b_i a_{ij} a_{jk}c_k^2", Fraction(1, 60)),
    (5, "b[b[b,b,b]]", r"\sum_{i,j=1}^s b_i a_{ij} c_j^3", Fraction(1, 20)),
    (5, "b[b,b[b,b]]", r"\sum_{i,j=1}^s b_i c_i a_{ij} c_j^2", Fraction(1, 15)),
    (5, "b[b,b,b,b]", r"\sum_{i=1}^s b_i c_i^4", Fraction(1, 5)),
]


def squash(s):
    return "".join(s.split())


def test_paper_table_1_exactly():
    conds = order_conditions(5, "degenerate")
    assert len(conds) == 8
    for c, (order, tree, lhs, rhs) in zip(conds, PAPER_TABLE_1):
        assert (c.order, str(c.tree), c.rhs) == (order, tree, rhs)
        assert squash(latex_form(c.tree)) == squash(lhs)


@pytest.mark.parametrize("tree, text", [
    ("b[b,b]", "sum_i b_i c_i^2 = 1/3"),
    ("b[b[b,b]]", "sum_{i,j} b_i a_ij c_j^2 = 1/12"),
    ("b[b,b[b,b]]", "sum_{i,j} b_i c_i a_ij c_j^2 = 1/15"),
    ("b[b[b]]", "sum_{i,j} b_i a_ij c_j = 1/6"),      # Hairer–Nørsett–Wanner Table II.2.1
    ("b[b[b[b]]]", "sum_{i,j,k} b_i a_ij a_jk c_k = 1/24"),
    ("b[b[b],b[b]]", "sum_{i,j,k} b_i a_ij c_j a_ik c_k = 1/20"),
])
def test_butcher_form_text(tree, text):
    t = P(tree)
    assert f"{butcher_form(t)} = {t.e.numerator}/{t.e.denominator}" == text


def test_latex_of_issue_example():
    c = [c for c in order_conditions(4) if str(c.tree) == "b[b[b,b]]"][0]
    assert c.latex() == r"\sum_{i,j=1}^s b_i a_{ij} c_j^2 = \frac{1}{12}"


def test_counts_per_class():
    assert [len(conditions_of_order(n)) for n in range(1, 9)] == [1, 1, 2, 4, 9, 20, 48, 115]
    assert [len(conditions_of_order(n, "degenerate")) for n in range(1, 9)] == [1, 0, 1, 2, 4, 8, 17, 36]
    assert len(order_conditions(10)) == 1205  # sum of A000081 to 10
    assert len(order_conditions(6, exact_order=True)) == 20


def test_index_names_are_distinct_and_do_not_use_s():
    t = P("b[b[b[b[b[b[b[b[b[b[b[b[b[b[b[b,b]]]]]]]]]]]]]]]")
    form = butcher_form(t)
    assert " s" not in form and "_s" not in form
    assert t.order == 17 and form.count(" a_") == 14  # one a-factor per edge between non-leaves
    assert len(set(form.split("}")[0][5:].split(","))) == 15


def test_unknown_class_is_input_error():
    with pytest.raises(InputError):
        order_conditions(3, "bogus")


def test_symmetric_conditions_past_the_shipped_order_are_refused_for_the_order_asked():
    """The shipped relations reach order 8 (rkhp.trees.relations.MAX_SHIPPED_ORDER): asked for 12,
    the refusal names 12 and the command that derives them, before any order is built."""
    with pytest.raises(InputError, match=r"ship up to order 8, asked for order 12: .*--order 12 --regenerate"):
        order_conditions(12, "symmetric")


def test_only_trees_offers_a_count_past_the_enumeration_order(run_cli):
    """`trees --count` reaches orders past the enumeration's; `conditions` has no --count."""
    code, out, _ = run_cli("conditions", "--help")
    assert code == 0 and "--count" not in out
    code, out, _ = run_cli("trees", "--help")
    assert code == 0 and "with --count" in " ".join(out.split())
