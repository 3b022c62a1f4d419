"""The residual system of a tableau search: unknowns, order-condition residuals, exact Jacobian.

Unknowns x = (a_ij over the strict lower triangle, or every (i, j) when implicit; then b_i), with
c = row sums of A (docs/theory.md §2). For each condition of :func:`rkhp.trees.conditions.order_conditions`
(paper, Theorems 5.1–5.2; the "symmetric" class of docs/theory.md §8 plugs in the same way) the residual is
sum_k w_k r(t_k) with r(t) = gamma(t) a(t) - 1, so every residual is of order one.

Elementary weights and their derivatives are computed in one forward pass over the trees, by
increasing order, each tree's stage vector Phi(t) and its Jacobian dPhi(t) (shape s x n_unknowns)
built from its children's: u = A Phi(t_k), du = A dPhi(t_k) + dA Phi(t_k), Phi = prod_k u_k.
The same code runs on float64 arrays and on object arrays of mpmath numbers (polishing).
"""

from __future__ import annotations

from dataclasses import dataclass
from fractions import Fraction

import numpy as np

from ..base.errors import InputError
from ..trees.conditions import condition_trees, order_conditions
from ..trees.rooted import Tree

#: Largest order a search accepts: the conditions over T number 200 up to order 8, 719 more at 9.
MAX_SEARCH_ORDER = 8
#: Largest number of stages a search accepts.
MAX_SEARCH_STAGES = 16


def check_problem(stages, order=None) -> None:
    """Validate the numbers of stages and the order (InputError naming the value)."""
    if isinstance(stages, bool) or not isinstance(stages, int) or stages < 1:
        raise InputError(f"the number of stages must be an integer >= 1, got {stages!r}")
    if stages > MAX_SEARCH_STAGES:
        raise InputError(f"{stages} stages is above the practical limit {MAX_SEARCH_STAGES}")
    if order is not None:
        if isinstance(order, bool) or not isinstance(order, int) or order < 1:
            raise InputError(f"the order must be an integer >= 1, got {order!r}")
        if order > MAX_SEARCH_ORDER:
            raise InputError(f"order {order} is above the practical search limit {MAX_SEARCH_ORDER}")


def unknown_pattern(stages: int, implicit: bool) -> tuple[tuple[int, int], ...]:
    """The positions (i, j) of the unknown a_ij, row by row (strict lower triangle if explicit)."""
    return tuple((i, j) for i in range(stages) for j in range(stages if implicit else i))


@dataclass(frozen=True)
class ResidualSystem:
    """Order conditions up to ``order`` for ``stages`` stages, as a map from unknowns to residuals.

    Attributes:
        stages, order, cls, implicit: the problem.
        pattern: positions of the unknown a_ij (then come the s unknowns b_i).
        conditions: the OrderCondition objects (rkhp.trees.conditions).
        trees: every tree needed (condition trees and their subtrees), children before parents.
        error_trees: the trees of order ``order + 1`` of the class (principal error, docs/theory.md §2).
    """

    stages: int
    order: int
    cls: str
    implicit: bool
    pattern: tuple[tuple[int, int], ...]
    conditions: tuple
    trees: tuple[Tree, ...]
    error_trees: tuple[Tree, ...]
    children: tuple[tuple[int, ...], ...]
    condition_terms: tuple[tuple[tuple[int, Fraction], ...], ...]
    error_index: tuple[int, ...]

    @classmethod
    def build(cls_, stages: int, order: int, cls: str = "general", implicit: bool = False,
              with_error: bool = False) -> ResidualSystem:
        """Set up the system; ``with_error`` adds the trees of order N+1 for the principal error."""
        check_problem(stages, order)
        conds = tuple(order_conditions(order, cls))
        error_trees = tuple(condition_trees(order + 1, cls)) if with_error else ()
        needed: set[Tree] = set()

        def add_with_subtrees(t: Tree) -> None:
            if t not in needed:
                needed.add(t)
                for child in t.children:
                    add_with_subtrees(child)

        for cond in conds:
            for t in cond.trees:
                add_with_subtrees(t)
        for t in error_trees:
            add_with_subtrees(t)
        trees = tuple(sorted(needed, key=lambda t: (t.order, t.key)))
        index = {t: k for k, t in enumerate(trees)}
        children = tuple(tuple(index[c] for c in t.children) for t in trees)
        terms = tuple(tuple((index[t], w) for t, w in zip(c.trees, c.weights, strict=True))
                      for c in conds)
        return cls_(stages, order, cls, implicit, unknown_pattern(stages, implicit), conds, trees,
                    error_trees, children, terms, tuple(index[t] for t in error_trees))

    # ------------------------------------------------------------------ layout

    @property
    def n_unknowns(self) -> int:
        return len(self.pattern) + self.stages

    @property
    def n_conditions(self) -> int:
        return len(self.conditions)

    def unpack(self, x):
        """(A, b) from the unknowns (same element type as x)."""
        s = self.stages
        A = np.zeros((s, s), dtype=x.dtype)
        if self.pattern:
            rows, cols = zip(*self.pattern, strict=True)
            A[list(rows), list(cols)] = x[: len(self.pattern)]
        return A, x[len(self.pattern):].copy()

    def pack(self, A, b) -> np.ndarray:
        """The unknowns from (A, b) (entries outside the pattern must be zero)."""
        A = np.asarray(A)
        return np.concatenate([np.array([A[i, j] for i, j in self.pattern], dtype=A.dtype),
                               np.asarray(b, dtype=A.dtype)])

    def random_start(self, rng: np.random.Generator) -> np.ndarray:
        """A random starting point: a_ij ~ U(-1, 1), b ~ U(0, 2/s) (weights of sum about one)."""
        a = rng.uniform(-1.0, 1.0, len(self.pattern))
        b = rng.uniform(0.0, 2.0 / self.stages, self.stages)
        return np.concatenate([a, b])

    # ------------------------------------------------------------------ evaluation

    def weights(self, x, jacobian: bool = True):
        """a(t) for every needed tree (list, in ``trees`` order) and, with ``jacobian``, the rows
        da(t)/dx (list of arrays of length n_unknowns; None without).

        Stage vectors by increasing order, each from its children's: u = A Phi(c),
        du = A dPhi(c) + (dA) Phi(c), Phi = prod u, dPhi = sum_k (prod_{l != k} u_l) du_k.
        """
        s, n = self.stages, self.n_unknowns
        na = len(self.pattern)
        A, b = self.unpack(x)
        rows = np.array([i for i, _ in self.pattern], dtype=int)
        cols = np.array([j for _, j in self.pattern], dtype=int)
        ar = np.arange(na)
        one = np.ones(s, dtype=x.dtype)
        count = len(self.trees)
        phi: list = [None] * count
        dphi: list = [None] * count
        u_cache: list = [None] * count
        for k, kids in enumerate(self.children):
            if not kids:
                phi[k] = one
                dphi[k] = np.zeros((s, n), dtype=x.dtype) if jacobian else None
                continue
            us = []
            for c in kids:
                if u_cache[c] is None:
                    du = None
                    if jacobian:
                        du = A @ dphi[c]
                        du[rows, ar] += phi[c][cols]
                    u_cache[c] = (A @ phi[c], du)
                us.append(u_cache[c])
            value = us[0][0]
            for u, _ in us[1:]:
                value = value * u
            phi[k] = value
            if jacobian:
                if len(us) == 1:
                    dphi[k] = us[0][1]
                else:
                    d = np.zeros((s, n), dtype=x.dtype)
                    for m, (_, du) in enumerate(us):
                        others = one
                        for l, (u, _) in enumerate(us):
                            if l != m:
                                others = others * u
                        d += others[:, None] * du
                    dphi[k] = d
        values = [b @ v for v in phi]
        if not jacobian:
            return values, None
        grads = []
        for k in range(count):
            g = b @ dphi[k]
            g[na:] += phi[k]
            grads.append(g)
        return values, grads

    def residuals(self, x, jacobian: bool = True):
        """Residuals sum_k w_k (gamma(t_k) a(t_k) - 1), one per condition, and their Jacobian."""
        values, grads = self.weights(x, jacobian)
        conv = _converter(x)
        m, n = self.n_conditions, self.n_unknowns
        r = np.zeros(m, dtype=x.dtype)
        J = np.zeros((m, n), dtype=x.dtype) if jacobian else None
        trees = self.trees
        for k, terms in enumerate(self.condition_terms):
            for i, w in terms:
                wk = 1 if w == 1 else conv(w)
                gamma = trees[i].gamma
                r[k] += wk * (gamma * values[i] - 1)
                if jacobian:
                    J[k] += (wk * gamma) * grads[i]
        return r, J

    def principal_error(self, x, jacobian: bool = True):
        """Entries (a(t) - 1/gamma(t)) / sigma(t) over the trees of order N+1 (docs/theory.md §2)."""
        if not self.error_trees:
            raise ValueError("ResidualSystem built without with_error=True")
        values, grads = self.weights(x, jacobian)
        conv = _converter(x)
        e = np.array([(values[i] - conv(Fraction(1, t.gamma))) / t.sigma
                      for i, t in zip(self.error_index, self.error_trees, strict=True)],
                     dtype=x.dtype)
        if not jacobian:
            return e, None
        return e, np.array([grads[i] / t.sigma
                            for i, t in zip(self.error_index, self.error_trees, strict=True)],
                           dtype=x.dtype)


def _converter(x):
    """Fractions to the element type of x: float, sympy Rational (exact entries) or mpmath mpf."""
    if x.dtype != object:
        return float
    if any(type(v).__module__.startswith("sympy") for v in x):
        import sympy

        return lambda w: sympy.Rational(w.numerator, w.denominator)
    import mpmath

    return lambda w: mpmath.mpf(w.numerator) / w.denominator
