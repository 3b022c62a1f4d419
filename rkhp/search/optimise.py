"""Error-optimal methods: minimise the principal error norm on the solution set of the conditions.

The principal error of a method of order N is the vector (a(t) - 1/gamma(t)) / sigma(t) over the
trees of order N+1 of the class (NOTES §2). On the family of tableaux satisfying the conditions up
to order N, its squared 2-norm is minimised by SLSQP with the conditions as equality constraints
(exact gradients from the forward pass), from several solutions found by the multistart.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .system import ResidualSystem


@dataclass(frozen=True)
class Optimum:
    """The best point found: unknowns (float64), principal error norm, max constraint residual."""

    x: tuple[float, ...]
    error_norm: float
    residual: float
    starts: int


def error_norm(system: ResidualSystem, x) -> float:
    """2-norm of the principal error at order N+1 (float64)."""
    e, _ = system.principal_error(np.asarray(x, dtype=float), jacobian=False)
    return float(np.linalg.norm(e))


def minimise_error(system: ResidualSystem, starts, max_iterations: int = 500) -> Optimum | None:
    """SLSQP from each start (solutions of the conditions); the best feasible optimum or None."""
    from scipy.optimize import minimize

    def objective(x):
        e, J = system.principal_error(x)
        return float(e @ e), 2.0 * (J.T @ e)

    constraint = {"type": "eq", "fun": lambda x: system.residuals(x, jacobian=False)[0],
                  "jac": lambda x: system.residuals(x)[1]}
    best = None
    starts = [np.asarray(s, dtype=float) for s in starts]
    for x0 in starts:
        with np.errstate(all="ignore"):
            res = minimize(objective, x0, jac=True, method="SLSQP", constraints=[constraint],
                           options={"maxiter": max_iterations, "ftol": 1e-16})
        x = res.x
        residual = float(np.max(np.abs(system.residuals(x, jacobian=False)[0])))
        if not np.all(np.isfinite(x)) or residual > 1e-10 or np.max(np.abs(x)) > 20:
            continue
        norm = error_norm(system, x)
        if best is None or norm < best.error_norm:
            best = Optimum(tuple(float(v) for v in x), norm, residual, len(starts))
    return best


@dataclass(frozen=True)
class KnownMethod:
    """A built-in tableau satisfying the same conditions: its name and principal error norm."""

    name: str
    error_norm: float


def known_methods(system: ResidualSystem) -> list[KnownMethod]:
    """Built-in tableaux with the same stages (and kind) meeting every condition up to order N."""
    from ..tablefiles import builtin_names, load_tableau

    out = []
    for name in builtin_names():
        tab = load_tableau(name)
        if tab.stages != system.stages or (tab.kind != "explicit" and not system.implicit):
            continue
        x = system.pack(tab.A_float, tab.b_float)
        A, b = system.unpack(x)
        if not (np.array_equal(A, tab.A_float) and np.array_equal(b, tab.b_float)):
            continue
        r, _ = system.residuals(x, jacobian=False)
        if np.max(np.abs(r)) < 1e-12:
            out.append(KnownMethod(tab.name, error_norm(system, x)))
    return sorted(out, key=lambda m: m.error_norm)
