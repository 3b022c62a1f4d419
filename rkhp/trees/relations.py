"""Linear relations among elementary differentials of symmetric birealisations (docs/theory.md §8).

For a symmetric birealisation, beta(x, p) = alpha(x, -p), the elementary differentials F(t),
t in T_0 of one order n (paper §5, Theorem "superconvergence"; docs/theory.md §5), satisfy linear relations
beyond those of the degenerate theory: the relation space L_n = {c : sum_t c_t F(t) = 0 for every
symmetric system}. An RKHP method has *symmetric order* N when for every n <= N its error
coefficients d_t = (a(t) - e(t)) / sigma(t) over T_0 of order n form a relation, i.e. P_n d = 0 for
a basis P_n of the annihilator of L_n; with r(t) = gamma(t) a(t) - 1, d_t = r(t) / (gamma sigma).

Derivation (:func:`rkhp.series.relation_derivation.derive_relations`, ``rkhp relations --regenerate``),
exact throughout:
1. F(t) at the base point on random truncated Taylor jets of generic systems with constant pi in
   dimension >= 6 (:mod:`rkhp.series.differentials`), residues modulo primes below 2^31;
2. per order, the null space of the stacked evaluations modulo primes, in reduced row echelon
   form, combined by the Chinese remainder theorem (two primes: a modulus near 2^62) and recovered
   as rationals by rational reconstruction (:mod:`rkhp.base.modular`), then confirmed modulo a third
   prime; more primes are added until a further prime confirms;
3. checks: exact integer evaluation of every relation on fresh instances, and the relation space of
   a second family (Lie–Poisson so(3)*, symmetric realisation alpha = phi(K(p)) x, docs/theory.md §4),
   which must contain L_n (and here equals it).
The result up to order 8 ships as ``rkhp/data/symmetric_relations.json``.
"""

from __future__ import annotations

import json
from dataclasses import dataclass, field
from fractions import Fraction
from functools import lru_cache
from math import gcd, lcm
from pathlib import Path
from typing import NamedTuple

from ..base.errors import InputError
from ..base.exact_text import combination_text
from .rooted import Tree, check_order, format_tree, parse_tree, trees_of_order

#: Orders whose relations ship in ``rkhp/data/symmetric_relations.json``.
MAX_SHIPPED_ORDER = 8
#: Largest order :func:`derive_relations` accepts (order 9, 79 trees: about 4 minutes, 0.7 GB).
MAX_REGENERATE_ORDER = 9
DATA_FILE = "symmetric_relations.json"


class RelationRow(NamedTuple):
    """One relation sum_t c_t F(t) = 0 as a relations document holds it: the coefficients over
    the order's trees, and the equation as text."""

    coefficients: tuple[Fraction, ...]
    text: str


class ConditionRow(NamedTuple):
    """One symmetric order condition sum_k w_k r(t_k) = 0 as a relations document holds it."""

    trees: tuple[Tree, ...]
    weights: tuple[Fraction, ...]
    text: str


@dataclass(frozen=True)
class OrderRelations:
    """Relations and symmetric order conditions of one order n.

    Attributes:
        order: n.
        trees: T_0 of order n in canonical order (the columns).
        relations: a basis of L_n, primitive integer rows in echelon form (sum_t c_t F(t) = 0).
        conditions: (trees, weights) per condition, sum_k weights[k] r(trees[k]) = 0, primitive
            integer rows in reduced echelon form over the columns ``trees``.
        checks: how the relations were confirmed (primes, instances, cross-checks).
    """

    order: int
    trees: tuple[Tree, ...]
    relations: tuple[tuple[Fraction, ...], ...]
    conditions: tuple[tuple[tuple[Tree, ...], tuple[Fraction, ...]], ...]
    checks: dict = field(default_factory=dict, compare=False)

    #: docs/json.md "rkhp relations": the counts beside the rows, each row with its text
    json_keys = ("order", "trees", "t0_count", "relations_count", "conditions_count",
                 ("relations", "relation_rows"), ("conditions", "condition_rows"), "checks")

    @property
    def t0_count(self) -> int:
        return len(self.trees)

    @property
    def relations_count(self) -> int:
        return len(self.relations)

    @property
    def conditions_count(self) -> int:
        return len(self.conditions)

    @property
    def relation_rows(self) -> tuple[RelationRow, ...]:
        return tuple(RelationRow(r, relation_equation(self.trees, r)) for r in self.relations)

    @property
    def condition_rows(self) -> tuple[ConditionRow, ...]:
        return tuple(ConditionRow(ts, ws, condition_text(ts, ws)) for ts, ws in self.conditions)


@dataclass(frozen=True)
class RelationData:
    """Relations of orders 1..max_order and how they were derived."""

    max_order: int
    orders: tuple[OrderRelations, ...]
    method: dict = field(default_factory=dict, compare=False)

    format = "rkhp-symmetric-relations"
    version = 1
    json_keys = ("format", "version", "max_order", "method", "orders")

    def of_order(self, n: int) -> OrderRelations:
        return self.orders[n - 1]


# ----------------------------------------------------------------------------- public API


def relation_space(n: int) -> tuple[tuple[Fraction, ...], ...]:
    """Basis of L_n over ``trees_of_order(n, True)`` from the shipped data (orders <= 8)."""
    return shipped_order(n).relations


def symmetric_condition_rows(n: int) -> list[tuple[tuple[Tree, ...], tuple[Fraction, ...]]]:
    """The symmetric order conditions of order n as (trees, weights) on r(t) = gamma a(t) - 1."""
    return list(shipped_order(n).conditions)


def shipped_order(n: int) -> OrderRelations:
    """The shipped relations of order n; InputError above the shipped order."""
    check_order(n, what="relation order")
    if n > MAX_SHIPPED_ORDER:
        raise InputError(f"symmetric relations ship up to order {MAX_SHIPPED_ORDER}, asked for order {n}: "
                         f"derive them with `rkhp relations --order {n} --regenerate`")
    return shipped_relations().of_order(n)


@lru_cache(maxsize=1)
def shipped_relations() -> RelationData:
    """The relations shipped in ``rkhp/data/symmetric_relations.json``, validated."""
    path = Path(__file__).parent.parent / "data" / DATA_FILE
    try:
        doc = json.loads(path.read_text(encoding="utf-8"))
    except (OSError, ValueError) as exc:
        raise InputError(f"cannot read the shipped relations {DATA_FILE}: {exc}") from exc
    return relations_from_json(doc, DATA_FILE)


def relations_from_json(doc: dict, where: str = "relations document") -> RelationData:
    """Read and validate a relations document (the JSON form of :class:`RelationData`)."""
    try:
        orders = []
        for k, item in enumerate(doc["orders"], start=1):
            if item["order"] != k:
                raise InputError(f"{where}: orders must run 1, 2, ...; entry {k} has order {item['order']}")
            trees = tuple(parse_tree(s) for s in item["trees"])
            if trees != trees_of_order(k, True):
                raise InputError(f"{where}: the trees of order {k} are not T_0 of order {k} in canonical order")
            rels = tuple(tuple(Fraction(c) for c in r["coefficients"]) for r in item["relations"])
            conds = tuple((tuple(parse_tree(s) for s in c["trees"]), tuple(Fraction(w) for w in c["weights"]))
                          for c in item["conditions"])
            if any(len(r) != len(trees) for r in rels):
                raise InputError(f"{where}: a relation of order {k} has the wrong length")
            if len(rels) + len(conds) != len(trees):
                raise InputError(f"{where}: order {k}: relations + conditions must count the T_0 trees")
            orders.append(OrderRelations(k, trees, rels, conds, item.get("checks", {})))
        return RelationData(len(orders), tuple(orders), doc.get("method", {}))
    except (KeyError, TypeError, ValueError, ZeroDivisionError) as exc:
        if isinstance(exc, InputError):
            raise
        raise InputError(f"{where}: malformed relations document ({exc!r})") from exc


# ----------------------------------------------------------------------------- conditions from relations


def conditions_from_relations(trees, relations) -> tuple[tuple[tuple[Tree, ...], tuple[Fraction, ...]], ...]:
    """Rows (trees, weights) of sum w_t r(t) = 0 from a basis of L_n.

    d lies in L_n iff P d = 0 for a basis P of the annihilator of L_n; d_t = r(t)/(gamma sigma), so
    the weights on r are P_t / (gamma(t) sigma(t)); returned in reduced echelon form over the tree
    order, each row scaled to coprime integers with a positive leading entry.
    """
    from ..base.modular import rref_fraction

    ncols = len(trees)
    annihilator = _nullspace_fraction(relations, ncols)
    weighted = [[row[k] / (t.gamma * t.sigma) for k, t in enumerate(trees)] for row in annihilator]
    rows, _ = rref_fraction(weighted)
    out = []
    for row in rows:
        row = primitive_row(row)
        keep = [k for k in range(ncols) if row[k] != 0]
        out.append((tuple(trees[k] for k in keep), tuple(row[k] for k in keep)))
    return tuple(out)


def _nullspace_fraction(rows, ncols: int) -> list[list[Fraction]]:
    from ..base.modular import rref_fraction

    red, pivots = rref_fraction(rows) if rows else ((), ())
    free = [c for c in range(ncols) if c not in pivots]
    basis = []
    for f in free:
        v = [Fraction(0)] * ncols
        v[f] = Fraction(1)
        for row, c in zip(red, pivots):
            v[c] = -row[f]
        basis.append(v)
    return basis


def primitive_row(row) -> tuple[Fraction, ...]:
    """Scale a rational row to coprime integers with a positive first nonzero entry."""
    den = lcm(*(Fraction(x).denominator for x in row)) if row else 1
    ints = [int(Fraction(x) * den) for x in row]
    g = 0
    for x in ints:
        g = gcd(g, x)
    lead = next((x for x in ints if x), 1)
    g = g * (1 if lead > 0 else -1) if g else 1
    return tuple(Fraction(x // g) for x in ints)


# ----------------------------------------------------------------------------- text and JSON


def _terms(trees, coefficients, symbol: str) -> str:
    return combination_text((c, f"{symbol}({format_tree(t)})") for c, t in zip(coefficients, trees))


def relation_equation(trees, coefficients) -> str:
    """``F(b[b[b,b]]) + F(b[b,b,b]) = 0``."""
    return _terms(trees, coefficients, "F") + " = 0"


def condition_text(trees, weights) -> str:
    """``r(b[b[b,b]]) - r(b[b,b,b]) = 0`` with r(t) = gamma(t) a(t) - 1."""
    return _terms(trees, weights, "r") + " = 0"


def relation_text(order: OrderRelations, k: int) -> str:
    return relation_equation(order.trees, order.relations[k])
