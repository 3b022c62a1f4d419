"""Error-optimal methods: minimise the principal error norm on the solution set of the conditions.

The principal error of a method of order N is the vector (a(t) - 1/gamma(t)) / sigma(t) over the
trees of order N+1 of the class (docs/theory.md §2). On the family of tableaux satisfying the conditions up
to order N, its squared 2-norm is minimised by SLSQP with the conditions as equality constraints
(exact gradients from the forward pass), from several solutions found by the multistart. The
best optimum is then refined in mpmath by Newton's method on the Karush–Kuhn–Tucker system
grad |E|^2 + J^T lambda = 0, R = 0 (the Hessian of the Lagrangian by differences of the exact
gradients at twice the working precision), so that it is stationary to D digits, not only in
float64.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .polish import Polished, newton_step, to_mp
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
class PhaseOptimum:
    """--optimize phase: unknowns (float64), the phase order reached and the leading phase constant
    (theta(z) - z = constant z^(p+1) + ..., docs/stability.md), the powers of z annihilated, the max
    residual of the conditions and of those powers, the number of starts."""

    x: tuple[float, ...]
    phase_order: int
    phase_constant: float
    zeros: tuple[int, ...]
    residual: float
    starts: int


#: a phase coefficient below this (float64) is taken as annihilated: the next one is minimised
PHASE_ZERO = 1e-13


def _phase_equations(system: ResidualSystem, top: int):
    from ..tableaux.stability import phase_coefficients_numeric

    def coefficients(x):
        A, b = system.unpack(np.asarray(x))
        return phase_coefficients_numeric(A, b, top)

    return coefficients


def minimise_phase(system: ResidualSystem, starts, max_iterations: int = 500) -> PhaseOptimum | None:
    """Lexicographic minimisation of the phase error theta(z) - z on the solution family (docs/
    stability.md): from each start, the coefficient of z^(N+1) is annihilated with the conditions
    (least squares, a solution of the enlarged system) while the family has room, then the next odd
    power, and so on; the first power that cannot be annihilated is minimised in square (SLSQP, the
    conditions and the annihilated powers as equality constraints). The best optimum over the
    starts (highest phase order, then smallest constant) or None."""
    from scipy.optimize import least_squares, minimize

    top = system.order + 2 + 2 * max(1, system.n_unknowns - system.n_conditions)
    coefficients = _phase_equations(system, top)

    def phase_equations(x, zeros):
        return np.concatenate([system.residuals(np.asarray(x, dtype=float), jacobian=False)[0],
                               coefficients(np.asarray(x, dtype=float))[zeros]])

    def feasible(x, zeros):
        return (bool(np.all(np.isfinite(x))) and np.max(np.abs(x)) <= 20
                and np.max(np.abs(phase_equations(x, zeros))) <= PHASE_ZERO)

    best = None
    for x in (np.asarray(s, dtype=float) for s in starts):
        zeros, power = [], system.order + 1
        while power <= top:
            if system.n_conditions + len(zeros) < system.n_unknowns:
                with np.errstate(all="ignore"):
                    res = least_squares(phase_equations, x, args=(zeros + [power],), xtol=1e-15, ftol=1e-15,
                                        gtol=1e-15)
                if feasible(res.x, zeros + [power]):
                    x, zeros, power = res.x, zeros + [power], power + 2
                    continue
            constraints = [{"type": "eq", "fun": lambda x, z=tuple(zeros): phase_equations(x, list(z))}]
            with np.errstate(all="ignore"):
                res = minimize(lambda x, k=power: coefficients(x)[k] ** 2 * 1e8, x, method="SLSQP",
                               constraints=constraints, options={"maxiter": max_iterations, "ftol": 1e-30})
            if feasible(res.x, zeros) and abs(coefficients(res.x)[power]) < abs(coefficients(x)[power]):
                x = res.x
            break
        if not feasible(x, zeros):
            continue
        c = coefficients(x)
        k = next((j for j in range(system.order + 1, top + 1) if abs(c[j]) > PHASE_ZERO), None)
        if k is None:
            continue
        candidate = PhaseOptimum(tuple(float(v) for v in x), k - 1, float(c[k]), tuple(zeros),
                                 float(np.max(np.abs(phase_equations(x, zeros)))), len(starts))
        if best is None or (candidate.phase_order, -abs(candidate.phase_constant)) > \
                (best.phase_order, -abs(best.phase_constant)):
            best = candidate
    return best


def polish_phase(system: ResidualSystem, optimum: PhaseOptimum, digits: int, max_iterations: int = 40):
    """Newton in mpmath (minimum-norm steps) on the conditions and the annihilated phase powers
    together, until every residual is below 10^-digits: a :class:`~rkhp.search.polish.Polished`."""
    import mpmath

    zeros = list(optimum.zeros)
    top = max(zeros, default=system.order + 1)
    coefficients = _phase_equations(system, top)
    with mpmath.workdps(2 * digits + 20):
        x = to_mp(optimum.x)
        tol = mpmath.mpf(10) ** (-digits)
        eps = mpmath.mpf(10) ** (-(digits + 10))
        size = mpmath.inf
        for iterations in range(max_iterations + 1):
            r, J = system.residuals(x)
            c = coefficients(x)[zeros]
            rows = []
            for k in range(len(x)):
                step = np.zeros(len(x), dtype=object) + mpmath.mpf(0)
                step[k] = eps
                rows.append((coefficients(x + step)[zeros] - coefficients(x - step)[zeros]) / (2 * eps))
            Jp = np.array(rows, dtype=object).T.reshape(len(zeros), len(x))
            size = max(abs(v) for v in list(r) + list(c))
            if size < tol or iterations == max_iterations:
                break
            x = x + newton_step(np.vstack([J, Jp]), np.concatenate([r, c]))
        text = tuple(mpmath.nstr(v, digits, strip_zeros=False) for v in x)
        return Polished(text, digits, float(size), bool(size < tol), iterations)


@dataclass(frozen=True)
class Refined:
    """A KKT point to D digits: unknowns as strings, max |KKT residual|, Newton iterations."""

    x: tuple[str, ...]
    kkt_residual: float
    converged: bool
    iterations: int


def _lagrangian_gradient(system: ResidualSystem, x, lam):
    e, JE = system.principal_error(x)
    r, J = system.residuals(x)
    return 2 * (JE.T @ e) + J.T @ lam, r, J


def refine_optimum(system: ResidualSystem, x0, digits: int, max_iterations: int = 30) -> Refined:
    """Newton on the KKT system from a float64 optimum, until |KKT residual| < 10^-digits."""
    import mpmath

    with mpmath.workdps(2 * digits + 20):
        x = to_mp(x0)
        n = len(x)
        g0, r, J = _lagrangian_gradient(system, x, np.zeros(system.n_conditions, dtype=object))
        Jm = mpmath.matrix(J.tolist())
        lam0 = mpmath.lu_solve(Jm * Jm.T, -(Jm * mpmath.matrix(list(g0))))
        lam = np.array([lam0[k] for k in range(system.n_conditions)], dtype=object)
        h = mpmath.mpf(10) ** (-(digits + 10))
        tol = mpmath.mpf(10) ** (-digits)
        size = mpmath.inf
        iterations = 0
        for iterations in range(max_iterations + 1):
            g, r, J = _lagrangian_gradient(system, x, lam)
            size = max(max(abs(v) for v in g), max((abs(v) for v in r), default=0))
            if size < tol or iterations == max_iterations:
                break
            H = mpmath.matrix(n, n)
            for k in range(n):
                xk = x.copy()
                xk[k] += h
                gk, _, _ = _lagrangian_gradient(system, xk, lam)
                for i in range(n):
                    H[i, k] = (gk[i] - g[i]) / h
            m = len(r)
            K = mpmath.matrix(n + m, n + m)
            for i in range(n):
                for j in range(n):
                    K[i, j] = (H[i, j] + H[j, i]) / 2
                for j in range(m):
                    K[i, n + j] = J[j, i]
                    K[n + j, i] = J[j, i]
            step = mpmath.lu_solve(K, mpmath.matrix([-v for v in g] + [-v for v in r]))
            x = x + np.array([step[k] for k in range(n)], dtype=object)
            lam = lam + np.array([step[n + k] for k in range(m)], dtype=object)
        text = tuple(mpmath.nstr(v, digits, strip_zeros=False) for v in x)
        return Refined(text, float(size), bool(size < tol), iterations)


@dataclass(frozen=True)
class KnownMethod:
    """A built-in tableau satisfying the same conditions: its name and principal error norm."""

    name: str
    error_norm: float

    json_keys = ("name", ("principal_error", "error_norm"))


def known_methods(system: ResidualSystem) -> list[KnownMethod]:
    """Built-in tableaux with the same stages (and kind) meeting every condition up to order N."""
    from ..tableaux.files import builtin_names, load_tableau

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
