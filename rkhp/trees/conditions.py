"""Order conditions of RKHP methods in Butcher's form, over a class of trees.

Paper §5 (Theorem "order conditions" and Table 1): an RKHP method with coefficient map a has order
N when a(t) = e(t) = 1/gamma(t) for every tree t of T with |t| <= N (general birealisations), or
for every t of T_0 under the degeneracy condition (eq. (degen)). The third class, "symmetric"
(docs/theory.md §8), replaces the T_0 conditions of each order by fewer linear combinations of the
residuals r(t) = gamma(t) a(t) - 1; its rows come from :mod:`rkhp.trees.relations`.

The Butcher form folds the leaves into c_i = sum_j a_ij (docs/theory.md §2):
``b[b[b,b]]`` -> ``sum_{i,j} b_i a_ij c_j^2``. Index letters follow a depth-first walk over the
vertices that are not leaves, children in increasing canonical order (the paper's writing order).
"""

from __future__ import annotations

from dataclasses import dataclass
from fractions import Fraction

from ..base.errors import InputError
from ..base.exact_text import combination_text, fraction_latex, fraction_text
from .relations import MAX_SHIPPED_ORDER, symmetric_condition_rows
from .rooted import Tree, check_order, trees_of_order

#: Condition classes: all trees T, the degenerate subset T_0, symmetric birealisations.
CLASSES = ("general", "degenerate", "symmetric")

_LETTERS = "ijklmnopqruvwxyz"


@dataclass(frozen=True)
class OrderCondition:
    """One order condition: sum_k weights[k] * r(trees[k]) = 0 with r(t) = gamma(t) a(t) - 1.

    For the general and degenerate classes each condition is a single tree with weight 1, i.e.
    a(t) = 1/gamma(t) (paper, Table 1).
    """

    order: int
    trees: tuple[Tree, ...]
    weights: tuple[Fraction, ...]

    @property
    def is_single(self) -> bool:
        return len(self.trees) == 1

    @property
    def tree(self) -> Tree:
        """The tree of a single-tree condition."""
        if not self.is_single:
            raise ValueError("a combined condition has several trees")
        return self.trees[0]

    @property
    def rhs(self) -> Fraction:
        """Right-hand side in the form sum_k weights[k] gamma_k a(t_k) = rhs."""
        if self.is_single:
            return Fraction(1, self.trees[0].gamma)
        return sum(self.weights, Fraction(0))

    def text(self) -> str:
        """Plain-text Butcher form, e.g. ``sum_i b_i c_i^2 = 1/3``."""
        if self.is_single:
            return f"{butcher_form(self.tree)} = {fraction_text(self.rhs)}"
        terms = [(w * t.gamma, butcher_form(t)) for w, t in zip(self.weights, self.trees)]
        return f"{combination_text(terms)} = {fraction_text(self.rhs)}"

    def latex(self) -> str:
        """LaTeX Butcher form, e.g. ``\\sum_{i,j=1}^s b_i a_{ij} c_j^2 = \\frac{1}{12}``."""
        if self.is_single:
            return f"{latex_form(self.tree)} = {fraction_latex(self.rhs)}"
        terms = [(w * t.gamma, latex_form(t)) for w, t in zip(self.weights, self.trees)]
        return f"{combination_text(terms, fraction_latex)} = {fraction_latex(self.rhs)}"


def check_class(cls: str) -> str:
    """Validate a class name."""
    if cls not in CLASSES:
        raise InputError(f"unknown condition class {cls!r} (expected one of {', '.join(CLASSES)})")
    return cls


def condition_trees(n: int, cls: str = "general") -> tuple[Tree, ...]:
    """The trees whose weights enter the conditions of order n: T for general, T_0 otherwise."""
    return trees_of_order(n, degenerate=check_class(cls) != "general")


def conditions_of_order(n: int, cls: str = "general") -> tuple[OrderCondition, ...]:
    """The order conditions of order exactly n in the class (paper Thm 5.1–5.2; docs/theory.md §8)."""
    check_class(cls)
    if cls == "symmetric":
        return symmetric_order_conditions(n)
    one = Fraction(1)
    return tuple(OrderCondition(n, (t,), (one,)) for t in condition_trees(n, cls))


def order_conditions(order: int, cls: str = "general", exact_order: bool = False) -> tuple[OrderCondition, ...]:
    """All conditions of order <= ``order`` (only == ``order`` when exact_order), by order; the
    symmetric class up to the shipped order of its relations (InputError beyond it, before any
    work)."""
    check_order(order)
    if cls == "symmetric" and order > MAX_SHIPPED_ORDER:
        raise InputError(f"the symmetric conditions ship up to order {MAX_SHIPPED_ORDER}, asked for order {order}: "
                         f"derive them with `rkhp relations --order {order} --regenerate`")
    orders = [order] if exact_order else range(1, order + 1)
    return tuple(c for n in orders for c in conditions_of_order(n, cls))


def symmetric_order_conditions(n: int) -> tuple[OrderCondition, ...]:
    """The symmetric order conditions of order n (the shipped rows of `rkhp.trees.relations`)."""
    return tuple(OrderCondition(n, trees, weights) for trees, weights in symmetric_condition_rows(n))


# ----------------------------------------------------------------------------- Butcher form


def _index_name(k: int) -> str:
    return _LETTERS[k] if k < len(_LETTERS) else f"{_LETTERS[k % len(_LETTERS)]}{k // len(_LETTERS)}"


def _factors(t: Tree):
    """Yield (kind, indices, power) factors of the folded elementary weight, root index 0.

    kind is "c" (c_x^power) or "a" (a_xy). Depth-first over non-leaf vertices, children in
    increasing canonical order, c before the a-factors at each vertex (paper, Table 1).
    """
    counter = [0]

    def walk(v: Tree, index: int):
        kids = v.children[::-1]
        leaves = sum(1 for c in kids if c.order == 1)
        if leaves:
            yield ("c", (index,), leaves)
        for c in kids:
            if c.order > 1:
                counter[0] += 1
                j = counter[0]
                yield ("a", (index, j), 1)
                yield from walk(c, j)

    factors = list(walk(t, 0))
    return factors, counter[0] + 1


def _folded_product(t: Tree, a_factor) -> tuple[list[str], list[str]]:
    """Index names and the factors b_i, c_x^m, a_xy of the folded elementary weight of t."""
    factors, n_idx = _factors(t)
    names = [_index_name(k) for k in range(n_idx)]
    parts = [f"b_{names[0]}"]
    for kind, idx, power in factors:
        if kind == "c":
            parts.append(f"c_{names[idx[0]]}" + (f"^{power}" if power > 1 else ""))
        else:
            parts.append(a_factor(names[idx[0]], names[idx[1]]))
    return names, parts


def butcher_form(t: Tree) -> str:
    """Left-hand side in plain text: ``sum_{i,j} b_i c_i a_ij c_j^2`` (docs/theory.md §2)."""
    names, parts = _folded_product(t, lambda x, y: f"a_{x}{y}" if len(x) == len(y) == 1 else f"a_{{{x},{y}}}")
    head = f"sum_{names[0]}" if len(names) == 1 else "sum_{" + ",".join(names) + "}"
    return head + " " + " ".join(parts)


def latex_form(t: Tree) -> str:
    """Left-hand side in LaTeX: ``\\sum_{i,j=1}^s b_i a_{ij} c_j^2`` (paper, Table 1)."""
    names, parts = _folded_product(t, lambda x, y: f"a_{{{x}{y}}}")
    return "\\sum_{" + ",".join(names) + "=1}^s " + " ".join(parts)


