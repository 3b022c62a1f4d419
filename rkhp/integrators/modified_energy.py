"""A modified Hamiltonian evaluated on a system: H~_N(x) = sum_(|t|<=N) h^(|t|-1) c(t) F(t)(x)
(docs/theory.md §11, docs/modified.md).

The series comes exact from :mod:`rkhp.series.modified`; the F(t)(x) of the system are those of the
THP step (:mod:`rkhp.integrators.tree_jets`: the compiled tape interpreter on Taylor jets), evaluated
with values only (jet margin 0) on the series' trees and their subtrees, by its compiled loop over
the states (`tree_values`). Its class must be the one of
the system's realisation (``rkhp.studies.methods.condition_class``).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..series.modified import NotATreeSeries, modified_hamiltonian

ALONG_BLOCK = 256
"""States evaluated by one call of the compiled loop between progress reports."""


@dataclass
class ModifiedEnergy:
    """x -> H~_N(x) on one system for one step size h."""

    system: object
    series: object
    h: float

    def __post_init__(self):
        from .tree_jets import tree_jets

        terms = self.series.float_terms()
        trees = _subtree_closure([t for t, _ in terms])
        position = {t: i for i, t in enumerate(trees)}
        self._terms = np.array([position[t] for t, _ in terms], dtype=np.int64)
        self._weights = np.array([self.h ** (t.order - 1) * c for t, c in terms], dtype=np.float64)
        self._jets = tree_jets(self.system, trees, self.series.order, 0)

    def __call__(self, x) -> float:
        return float(self.along(np.asarray(x, dtype=np.float64).reshape(1, -1))[0])

    def along(self, states, advance=None) -> np.ndarray:
        """H~_N at every state of a trajectory (``advance()`` called once per state, after each
        block of ALONG_BLOCK states, for progress)."""
        from .tree_jets import tree_values

        states = np.ascontiguousarray(states, dtype=np.float64).reshape(-1, self.system.dim)
        out = np.empty(len(states))
        for lo in range(0, len(states), ALONG_BLOCK):
            hi = min(lo + ALONG_BLOCK, len(states))
            tree_values(self._jets, self._terms, self._weights, states[lo:hi], out[lo:hi])
            if advance:
                for _ in range(hi - lo):
                    advance()
        return out


def energy_errors(system, series, h: float, states, advance=None) -> dict:
    """max over the states of |H~_N(y_n) - H~_N(y_0)| and of |H(y_n) - H(y_0)| (JSON keys of
    ``rkhp integrate --modified``, docs/modified.md)."""
    values = ModifiedEnergy(system, series, h).along(states, advance)
    energy = np.array([system.hamiltonian(x) for x in states])
    return {"modified_order": series.order, "modified_class": series.cls,
            "modified_energy_error": float(np.max(np.abs(values - values[0]))),
            "energy_error_max": float(np.max(np.abs(energy - energy[0])))}


def method_series(character, order: int, cls: str, seed: int = 0):
    """The modified Hamiltonian of a character to ``order``, or to the largest order below at
    which it is a tree series (rkhp.series.modified.NotATreeSeries stops it there)."""
    try:
        return modified_hamiltonian(character, order, cls, seed)
    except NotATreeSeries as exc:
        return modified_hamiltonian(character, exc.order - 1, cls, seed)


def _subtree_closure(trees) -> list:
    """The trees and all their subtrees, by increasing order."""
    seen = set()
    stack = list(trees)
    while stack:
        t = stack.pop()
        if t not in seen:
            seen.add(t)
            stack.extend(t.children)
    return sorted(seen, key=lambda t: (t.order, t.key))
