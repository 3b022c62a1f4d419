"""Derivation of the linear relations among elementary differentials of symmetric
birealisations from random instances (docs/theory.md §8; the method is described in
:mod:`rkhp.trees.relations`, which reads the shipped result)."""

from __future__ import annotations

from ..base.bounds import seed as check_seed
from ..base.errors import InputError, NumericalFailure
from ..base.executors import InProcess
from ..trees.relations import (
    MAX_REGENERATE_ORDER,
    OrderRelations,
    RelationData,
    conditions_from_relations,
    primitive_row,
    relation_equation,
    shipped_order,
    shipped_relations,
)
from ..trees.rooted import check_order, trees_of_order


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
    from ..systems.families import LIE_POISSON

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
    lie = (executor.submit(_general_null_spaces, all_trees, max_order, LIE_POISSON, batch, streams[-1], PRIMES[0])
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
        rels = tuple(primitive_row(r) for r in relations[n])
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

    from .differentials import constant_pi_values

    values = constant_pi_values(all_trees, max_order, dim, batch, np.random.default_rng(stream), p)
    return _null_spaces(values, max_order, p)


def _general_null_spaces(all_trees, max_order: int, family: str, batch: int, stream, p: int) -> dict:
    """A task: the null spaces modulo p of F(t) on ``batch`` instances of another ``family``."""
    import numpy as np

    from .differentials import general_values

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

    from .differentials import constant_pi_values

    exact = constant_pi_values(all_trees, max_order, dim, count, np.random.default_rng(stream), None)
    for n in range(1, max_order + 1):
        trees = trees_of_order(n, True)
        for row in relations[n]:
            for i in range(count):
                total = sum(c * exact[t][i] for c, t in zip(row, trees))
                if total != 0:
                    raise NumericalFailure(f"order {n}: relation {relation_equation(trees, row)} fails in exact "
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


