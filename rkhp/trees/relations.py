"""Linear relations among elementary differentials of symmetric birealisations (docs/theory.md §8).

For a symmetric birealisation, beta(x, p) = alpha(x, -p), the elementary differentials F(t),
t in T_0 of one order n (paper §5, Theorem "superconvergence"; docs/theory.md §5), satisfy linear relations
beyond those of the degenerate theory: the relation space L_n = {c : sum_t c_t F(t) = 0 for every
symmetric system}. An RKHP method has *symmetric order* N when for every n <= N its error
coefficients d_t = (a(t) - e(t)) / sigma(t) over T_0 of order n form a relation, i.e. P_n d = 0 for
a basis P_n of the annihilator of L_n; with r(t) = gamma(t) a(t) - 1, d_t = r(t) / (gamma sigma).

Derivation (:func:`derive_relations`, ``rkhp relations --regenerate``), exact throughout:
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

from ..base.bounds import seed as check_seed
from ..base.errors import InputError, NumericalFailure
from ..base.exact_text import combination_text, fraction_text
from ..base.executors import InProcess
from .rooted import Tree, check_order, format_tree, parse_tree, trees_of_order

#: Orders whose relations ship in ``rkhp/data/symmetric_relations.json``.
MAX_SHIPPED_ORDER = 8
#: Largest order :func:`derive_relations` accepts (order 9, 79 trees: about 4 minutes, 0.7 GB).
MAX_REGENERATE_ORDER = 9
DATA_FILE = "symmetric_relations.json"


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


@dataclass(frozen=True)
class RelationData:
    """Relations of orders 1..max_order and how they were derived."""

    max_order: int
    orders: tuple[OrderRelations, ...]
    method: dict = field(default_factory=dict, compare=False)

    def of_order(self, n: int) -> OrderRelations:
        return self.orders[n - 1]

    def to_json(self) -> dict:
        return {"format": "rkhp-symmetric-relations", "version": 1, "max_order": self.max_order,
                "method": self.method, "orders": [_order_json(o) for o in self.orders]}


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
    """Read and validate a relations document (the format of :meth:`RelationData.to_json`)."""
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


def relations_for(max_order: int, regenerate: bool = False, seed: int = 0, progress=None,
                  executor=None) -> RelationData:
    """Shipped relations up to max_order, or freshly derived ones when ``regenerate`` (on
    ``executor``, see :func:`derive_relations`)."""
    if regenerate:
        check_seed(seed)
        return derive_relations(max_order, seed, progress=progress, executor=executor)
    check_order(max_order, what="relation order")
    shipped_order(max_order)
    data = shipped_relations()
    return RelationData(max_order, data.orders[:max_order], data.method)


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
        row = _primitive(row)
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


def _primitive(row) -> tuple[Fraction, ...]:
    """Scale a rational row to coprime integers with a positive first nonzero entry."""
    den = lcm(*(Fraction(x).denominator for x in row)) if row else 1
    ints = [int(Fraction(x) * den) for x in row]
    g = 0
    for x in ints:
        g = gcd(g, x)
    lead = next((x for x in ints if x), 1)
    g = g * (1 if lead > 0 else -1) if g else 1
    return tuple(Fraction(x // g) for x in ints)


# ----------------------------------------------------------------------------- derivation


def derive_relations(max_order: int, seed: int = 0, dim: int = 6, extra: int = 10,
                     cross_check: bool = True, exact_instances: int = 2,
                     progress=None, executor=None) -> RelationData:
    """Derive the relations and symmetric conditions of orders 1..max_order from scratch.

    Args:
        max_order: largest order (<= MAX_REGENERATE_ORDER).
        seed: seed of every random instance (reproducible).
        dim: dimension of the constant-pi systems (6 by default; the relations found agree for
            dimensions 4..8 up to order 8).
        extra: instances beyond the number of trees of the largest order.
        cross_check: check the relation space on Lie–Poisson so(3)* (symmetric realisation).
        exact_instances: instances on which each relation is checked in exact integers.
        progress: optional callable(step: str) told about each stage.
        executor: where the independent evaluations run (rkhp.base.executors; default: in this
            process): the first three primes and the Lie–Poisson instances at once, then one prime
            at a time, then the exact check; the result does not depend on it (each prime has its
            own seeded stream).
    Raises NumericalFailure when the primes disagree, reconstruction fails or a check fails.
    """
    import numpy as np

    from ..base.modular import PRIMES

    check_order(max_order, MAX_REGENERATE_ORDER, what="relation order")
    if dim < 2:
        raise InputError(f"dimension must be at least 2, got {dim}")
    tell = progress or (lambda step: None)
    executor = executor or InProcess()
    all_trees = [t for n in range(1, max_order + 1) for t in trees_of_order(n, True)]
    batch = len(trees_of_order(max_order, True)) + extra
    streams = np.random.SeedSequence(seed).spawn(len(PRIMES) + 2)

    def prime_task(k):
        return (all_trees, max_order, dim, batch, streams[k], PRIMES[k])

    # 1-2. null spaces modulo primes (the first three and the Lie–Poisson instances at once); CRT
    # and rational reconstruction, one more prime at a time until a further prime confirms
    first = 3
    tell(f"constant pi, dimension {dim}, {batch} instances modulo {', '.join(map(str, PRIMES[:first]))}"
         + (f"; Lie–Poisson so(3)*, {batch} instances modulo {PRIMES[0]}" if cross_check else ""))
    tasks = [executor.submit(_prime_null_spaces, *prime_task(k)) for k in range(first)]
    lie = (executor.submit(_general_null_spaces, all_trees, max_order, "lie-poisson", batch, streams[-1], PRIMES[0])
           if cross_check else None)
    try:
        spaces = [t.result() for t in tasks]
        result = _reconstruct(spaces, PRIMES[:first], max_order)
        for k in range(first, len(PRIMES)):
            if result is not None:
                break
            tell(f"constant pi, dimension {dim}, {batch} instances modulo {PRIMES[k]}")
            spaces.append(executor.submit(_prime_null_spaces, *prime_task(k)).result())
            result = _reconstruct(spaces, PRIMES[: k + 1], max_order)
        if result is None:
            raise NumericalFailure(f"rational reconstruction of the relations did not stabilise with "
                                   f"{len(PRIMES)} primes")
        relations, used = result
        checks = {n: {"primes": list(used[:-1]), "confirmed_modulo": used[-1], "instances": batch,
                      "dimension": dim} for n in range(1, max_order + 1)}
        # 3. exact integers on fresh instances; another family of symmetric birealisations
        if exact_instances:
            tell(f"exact integer check on {exact_instances} instances")
            executor.submit(_exact_check, relations, all_trees, max_order, dim, exact_instances,
                            streams[-2]).result()
            for n in checks:
                checks[n]["exact_instances"] = exact_instances
        if lie is not None:
            for n, found in _lie_poisson_check(relations, lie.result(), max_order).items():
                checks[n]["lie_poisson_so3"] = found
    except BaseException:
        executor.cancel([*tasks, *([lie] if lie is not None else [])])
        raise
    orders = []
    for n in range(1, max_order + 1):
        trees = trees_of_order(n, True)
        rels = tuple(_primitive(r) for r in relations[n])
        orders.append(OrderRelations(n, trees, rels, conditions_from_relations(trees, rels), checks[n]))
    method = {"family": "constant pi (alpha = x - pi p / 2), random antisymmetric pi, random polynomial H",
              "dimension": dim, "seed": seed,
              "arithmetic": "integers modulo primes below 2^31, CRT, rational reconstruction, exact integer check",
              "cross_check": "Lie–Poisson so(3)*" if cross_check else None,
              "regenerate": f"rkhp relations --order {max_order} --regenerate --seed {seed}"}
    return RelationData(max_order, tuple(orders), method)


def _prime_null_spaces(all_trees, max_order: int, dim: int, batch: int, stream, p: int) -> dict:
    """A task: the null spaces modulo p of F(t) on ``batch`` constant-pi instances from ``stream``."""
    import numpy as np

    from ..series.differentials import constant_pi_values

    values = constant_pi_values(all_trees, max_order, dim, batch, np.random.default_rng(stream), p)
    return _null_spaces(values, max_order, p)


def _general_null_spaces(all_trees, max_order: int, family: str, batch: int, stream, p: int) -> dict:
    """A task: the null spaces modulo p of F(t) on ``batch`` instances of another ``family``."""
    import numpy as np

    from ..series.differentials import general_values

    values = general_values(all_trees, max_order, family, batch, np.random.default_rng(stream), p)
    return _null_spaces(values, max_order, p)


def _null_spaces(values, max_order: int, p: int) -> dict:
    """Per order, the RREF basis modulo p of the relations among the evaluated F(t)."""
    import numpy as np

    from ..base.modular import nullspace_mod

    out = {}
    for n in range(1, max_order + 1):
        trees = trees_of_order(n, True)
        if not trees:
            out[n] = np.zeros((0, 0), dtype=np.int64)
            continue
        out[n] = nullspace_mod(np.array([values[t] for t in trees], dtype=np.int64).T, p)
    return out


def _reconstruct(spaces, primes, max_order):
    """Rational RREF bases per order from the RREFs modulo ``primes[:-1]``, confirmed by the last.

    Returns (relations by order, primes used) or None when reconstruction fails or disagrees.
    """
    from ..base.modular import crt_pair, rational_reconstruction, to_residue

    relations = {}
    for n in range(1, max_order + 1):
        mats = [s[n] for s in spaces]
        shapes = {m.shape for m in mats}
        if len(shapes) != 1:
            raise NumericalFailure(f"order {n}: the relation spaces modulo different primes differ in dimension "
                                   f"({sorted(shapes)}); rerun with another --seed")
        rows = []
        for i in range(mats[0].shape[0]):
            row = []
            for j in range(mats[0].shape[1]):
                value, modulus = int(mats[0][i, j]), primes[0]
                for m, p in zip(mats[1:-1], primes[1:-1]):
                    value, modulus = crt_pair(value, modulus, int(m[i, j]), p), modulus * p
                try:
                    q = rational_reconstruction(value, modulus)
                except ValueError:
                    return None
                if to_residue(q, primes[-1]) != int(mats[-1][i, j]):
                    return None
                row.append(q)
            rows.append(tuple(row))
        relations[n] = tuple(rows)
    return relations, tuple(primes)


def _exact_check(relations, all_trees, max_order, dim, count, stream) -> None:
    """Every relation, evaluated in exact integers on ``count`` fresh constant-pi instances, is 0."""
    import numpy as np

    from ..series.differentials import constant_pi_values

    exact = constant_pi_values(all_trees, max_order, dim, count, np.random.default_rng(stream), None)
    for n in range(1, max_order + 1):
        trees = trees_of_order(n, True)
        for row in relations[n]:
            for i in range(count):
                total = sum(c * exact[t][i] for c, t in zip(row, trees))
                if total != 0:
                    raise NumericalFailure(f"order {n}: relation {_relation_text(trees, row)} fails in exact "
                                           f"arithmetic (value {total})")


def _lie_poisson_check(relations, other, max_order) -> dict:
    """Per order: the relation space ``other`` of so(3)* (symmetric realisation, modulo the first
    prime) must contain the relations."""
    import numpy as np

    from ..base.modular import PRIMES, to_residue

    p = PRIMES[0]
    out = {}
    for n in range(1, max_order + 1):
        mine = np.array([[to_residue(c, p) for c in row] for row in relations[n]], dtype=np.int64)
        theirs = other[n]
        contained = bool(np.all(_in_row_space(mine, theirs, p))) if len(mine) else True
        if not contained:
            raise NumericalFailure(f"order {n}: a relation derived on constant pi fails on Lie–Poisson so(3)*")
        out[n] = {"relations": int(theirs.shape[0]), "contains_all": contained,
                  "equal": int(theirs.shape[0]) == len(mine)}
    return out


def _in_row_space(rows, basis, p):
    """For each row, whether it lies in the row space of ``basis`` modulo p."""
    import numpy as np

    from ..base.modular import rref_mod

    rank = rref_mod(basis, p)[0].shape[0] if basis.size else 0
    out = []
    for row in rows:
        stacked = np.vstack([basis, row[None, :]]) if basis.size else row[None, :]
        out.append(rref_mod(stacked, p)[0].shape[0] == rank)
    return np.array(out)


# ----------------------------------------------------------------------------- text and JSON


def _terms(trees, coefficients, symbol: str) -> str:
    return combination_text((c, f"{symbol}({format_tree(t)})") for c, t in zip(coefficients, trees))


def _relation_text(trees, coefficients) -> str:
    """``F(b[b[b,b]]) + F(b[b,b,b]) = 0``."""
    return _terms(trees, coefficients, "F") + " = 0"


def condition_text(trees, weights) -> str:
    """``r(b[b[b,b]]) - r(b[b,b,b]) = 0`` with r(t) = gamma(t) a(t) - 1."""
    return _terms(trees, weights, "r") + " = 0"


def relation_text(order: OrderRelations, k: int) -> str:
    return _relation_text(order.trees, order.relations[k])


def _order_json(o: OrderRelations) -> dict:
    return {
        "order": o.order,
        "trees": [str(t) for t in o.trees],
        "t0_count": len(o.trees),
        "relations_count": len(o.relations),
        "conditions_count": len(o.conditions),
        "relations": [{"coefficients": [fraction_text(c) for c in r], "text": _relation_text(o.trees, r)}
                      for r in o.relations],
        "conditions": [{"trees": [str(t) for t in ts], "weights": [fraction_text(w) for w in ws],
                        "text": condition_text(ts, ws)} for ts, ws in o.conditions],
        "checks": o.checks,
    }
