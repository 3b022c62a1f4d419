"""A modified Hamiltonian evaluated on a system: H~_N(x) = sum_(|t|<=N) h^(|t|-1) c(t) F(t)(x)
(docs/theory.md §11, docs/modified.md).

The series comes exact from :mod:`rkhp.series.modified`; the F(t)(x) of the system are the THP tower's
(:mod:`rkhp.integrators.taylor`: the compiled tape interpreter on Taylor jets), evaluated with
values only (jet margin 0) on the series' trees and their subtrees. Its class must be the one of
the system's realisation (``rkhp.studies.methods.condition_class``).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..series.modified import NotATreeSeries, modified_hamiltonian


@dataclass
class ModifiedEnergy:
    """x -> H~_N(x) on one system for one step size h."""

    system: object
    series: object
    h: float

    def __post_init__(self):
        from .taylor import _Tower

        terms = self.series.float_terms()
        self._weights = [(t, self.h ** (t.order - 1) * c) for t, c in terms]
        trees = _subtree_closure([t for t, _ in terms])
        self._tower = _Tower(self.system, self.series.order, self.series.cls != "general", trees, margin=0)

    def __call__(self, x) -> float:
        F = self._tower.elementary(np.asarray(x, dtype=np.float64))
        return float(sum(w * F[t][0] for t, w in self._weights))

    def along(self, states, advance=None) -> np.ndarray:
        """H~_N at every state of a trajectory (``advance()`` called after each, for progress)."""
        out = np.empty(len(states))
        for k, x in enumerate(states):
            out[k] = self(x)
            if advance:
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
