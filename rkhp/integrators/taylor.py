"""The Taylor Hamiltonian Poisson integrator (THP) of order N (paper Thm 5.1, docs/theory.md §5).

S(x) = sum_{|t| <= N} h^|t| e(t)/sigma(t) F(t)(x) over T (general birealisations) or T_0
(degenerate ones), F(b) = H, F(b[t1..tm])(x) = d^m_p f(x, 0)[grad F(t1)(x), ..., grad F(tm)(x)],
f = H o alpha; psi = grad S; solve alpha(x, psi(x)) = y; y_next = beta(x, psi(x)).

Each F(t) is a jet in dx = x - x0 (Newton iterate x0), truncated at degree 2 + N - |t| (enough for
every use as a subtree, and degree 2 at the root gives psi and its Jacobian). The multilinear
derivative of a node is read off f(x0 + dx, sum_r eps_r grad F(u_r)) in the variables (dx, eps),
one eps_r per distinct child u_r: the coefficient of prod eps_r^k_r times prod k_r!. This runs
the same compiled tape interpreter as the RKHP engine, from Python (a reference method: its cost
grows with the number of trees).
"""

from __future__ import annotations

import time
from functools import lru_cache
from itertools import groupby
from math import factorial

import numpy as np

from ..base.bounds import check_step
from ..base.errors import InputError
from ..taylor.interpreter import interpreter, tape_work
from ..taylor.jets import jet_space, monomials
from ..trees.rooted import trees_up_to
from .engine_state import state_failure
from .failure import Failure, failure_status
from .newton import NEWTON_MAX_ITERATIONS, NEWTON_TOLERANCE
from .trajectory import Trajectory, checked


@lru_cache(maxsize=256)
def _index(n_vars: int, degree: int) -> dict[tuple[int, ...], int]:
    return {m: i for i, m in enumerate(monomials(n_vars, degree))}


class _Tower:
    """Per-system buffers and the tree list of a THP of order N."""

    def __init__(self, system, order: int, degenerate: bool, trees=None, margin: int = 2):
        """``trees``: the trees to evaluate, closed under taking subtrees and sorted by order
        (default: all of T or T_0 up to ``order``); ``margin``: the jet degree beyond N - |t|
        (2: psi and its Jacobian; 0: values only, as for a modified Hamiltonian)."""
        self.system = system
        self.n = system.dim
        self.order = order
        self.trees = trees_up_to(order, degenerate) if trees is None else tuple(trees)
        self.margin = margin

    def _run(self, tape, n_vars: int, degree: int, inputs: list[np.ndarray]):
        space = jet_space(n_vars, degree)
        work = tape_work((tape,), space.size)
        for i, jet in enumerate(inputs):
            work.W[i, : len(jet)] = jet[: space.size]
        interpreter(tape)(tape, degree, space, work)
        return work.W[tape.outputs]

    def _x_jet(self, x0, k: int, size: int) -> np.ndarray:
        jet = np.zeros(size)
        jet[0] = x0[k]
        if size > 1:
            jet[1 + k] = 1.0
        return jet

    def elementary(self, x0) -> dict:
        """F(t) as a jet in dx (degree margin + N - |t|) for every tree t."""
        n, N = self.n, self.order
        F: dict = {}
        for t in self.trees:
            D = self.margin + N - t.order
            small = jet_space(n, D).size
            if t.order == 1:
                inputs = [self._x_jet(x0, k, small) for k in range(n)] + [np.zeros(1)] * n
                F[t] = self._run(self.system.h_tape, n, D, inputs)[0].copy()
                continue
            groups = [(u, len(list(g))) for u, g in groupby(t.children)]
            q, m = len(groups), len(t.children)
            nb, Db = n + q, D + m
            size = jet_space(nb, Db).size
            inputs = [self._x_jet(x0, k, size) for k in range(n)]
            for k in range(n):
                p = np.zeros(size)
                for r, (u, _) in enumerate(groups):
                    grad = _gradient(F[u], n, self.margin + N - u.order, k)
                    rows = _slot_rows(n, q, Db, r)
                    common = min(len(rows), len(grad))
                    p[rows[:common]] = grad[:common]
                inputs.append(p)
            out = self._run(self.system.f_tape, nb, Db, inputs)[0]
            weight = float(np.prod([factorial(c) for _, c in groups]))
            F[t] = weight * out[_coefficient_rows(n, tuple(c for _, c in groups), D)]
        return F

    def psi(self, x0, h: float):
        """psi(x0) and its Jacobian from S = sum h^|t| e(t)/sigma(t) F(t)."""
        n = self.n
        F = self.elementary(x0)
        S = np.zeros(jet_space(n, 2).size)
        for t in self.trees:
            S += h ** t.order * float(t.e) / t.sigma * F[t][: S.size]
        idx = _index(n, 2)
        psi = S[1: 1 + n].copy()
        J = np.empty((n, n))
        for k in range(n):
            for l in range(n):
                e = tuple((1 if j == k else 0) + (1 if j == l else 0) for j in range(n))
                J[k, l] = S[idx[e]] * (2.0 if k == l else 1.0)
        return psi, J

    def alpha(self, x, p0, Jp):
        """alpha(x, p0 + Jp dx) and its Jacobian in dx at dx = 0."""
        n = self.n
        size = n + 1
        inputs = [self._x_jet(x, k, size) for k in range(n)]
        inputs += [np.concatenate([[p0[k]], Jp[k]]) for k in range(n)]
        out = self._run(self.system.alpha_tape, n, 1, inputs)
        return out[:, 0].copy(), out[:, 1: 1 + n].copy()


@lru_cache(maxsize=1024)
def _slot_rows(n: int, q: int, degree: int, r: int) -> np.ndarray:
    """Rows of the (dx, eps) jet space of degree ``degree`` holding dx^a eps_r, for the monomials a
    of degree <= degree - 1 in their order."""
    big = _index(n + q, degree)
    eps = tuple(1 if j == r else 0 for j in range(q))
    return np.array([big[a + eps] for a in monomials(n, degree - 1)], dtype=np.intp)


@lru_cache(maxsize=1024)
def _coefficient_rows(n: int, ks: tuple[int, ...], degree: int) -> np.ndarray:
    """Rows of the (dx, eps) jet space holding dx^a prod eps_r^k_r, for the monomials a of degree
    <= ``degree``."""
    big = _index(n + len(ks), degree + sum(ks))
    return np.array([big[a + ks] for a in monomials(n, degree)], dtype=np.intp)


def _gradient(jet: np.ndarray, n: int, degree: int, k: int) -> np.ndarray:
    space = jet_space(n, degree)
    size = jet_space(n, degree - 1).size
    return (space.expo[:size, k] + 1) * jet[space.up[:size, k]]


def thp_step(tower: _Tower, y, h: float, tol: float, max_iter: int):
    """One THP step: (y_next or None, Newton iterations, Failure)."""
    n = tower.n
    x = y.copy()
    scale = max(1.0, float(np.abs(y).max()))
    previous = np.inf
    for it in range(1, max_iter + 1):
        psi, Jpsi = tower.psi(x, h)
        a, J = tower.alpha(x, psi, Jpsi)
        with np.errstate(all="ignore"):
            try:
                delta = np.linalg.solve(J, y - a)
            except np.linalg.LinAlgError:
                return None, it, Failure.SINGULAR
        size = float(np.abs(delta).max())
        if not np.isfinite(size):
            return None, it, Failure.NEWTON_NON_FINITE
        x = x + delta
        predicted = size ** 3 / previous ** 2 if np.isfinite(previous) else np.inf
        if size <= tol * scale or (size < 0.5 * previous and predicted <= tol * scale):
            p = psi + Jpsi @ delta
            for _ in range(3):  # with p fixed, alpha(x, p) = y to round-off (as the engine)
                a, J = tower.alpha(x, p, np.zeros((n, n)))
                step = np.linalg.solve(J, y - a)
                x = x + step
                if not np.abs(step).max() > 4e-16 * scale:
                    break
            out = tower._run(tower.system.beta_tape, n, 0, [np.array([v]) for v in x]
                             + [np.array([v]) for v in p])
            y_next = out[:, 0].copy()
            cause = state_failure(y_next, tower.system.domain_code)
            return (y_next if cause == Failure.OK else None), it, cause
        if size > 1e8 * scale:
            break
        previous = size
    return None, max_iter, Failure.NEWTON_NO_CONVERGENCE


def integrate_taylor(system, order: int, degenerate: bool, h, n_steps, x0=None, *,
                     tol: float = NEWTON_TOLERANCE,
                     max_iter: int = NEWTON_MAX_ITERATIONS) -> Trajectory:
    """THP of order `order` over T_0 (`degenerate`) or T, as a Trajectory (paper Thm 5.1)."""
    if not isinstance(order, int) or not 1 <= order <= 8:
        raise InputError(f"THP order must be an integer from 1 to 8, got {order!r}")
    h, n_steps = check_step(h, n_steps, system.dim)
    y = system.start(x0)
    t0 = time.perf_counter()
    tower = _Tower(system, order, degenerate)
    tower.psi(y, h)  # compiles or loads the interpreter
    compile_seconds = time.perf_counter() - t0
    states = [y]
    iterations = []
    status, failed, cause = "ok", None, Failure.OK
    t0 = time.perf_counter()
    for step in range(n_steps):
        y_next, it, cause = thp_step(tower, states[-1], h, tol, max_iter)
        iterations.append(it)
        if cause != Failure.OK:
            status, failed = failure_status(cause, step, h, system.domain), step
            break
        states.append(y_next)
    run_seconds = time.perf_counter() - t0
    return checked(Trajectory(times=h * np.arange(len(states)), states=np.array(states),
                              newton_iterations=np.array(iterations, dtype=np.int64), status=status,
                              failed_step=failed, cause=cause, compile_seconds=compile_seconds,
                              run_seconds=run_seconds,
                              method=f"THP{order}" + (" (T_0)" if degenerate else " (T)"),
                              system=system.name, extra={"realisation": system.realisation}, poisson=system), system)
