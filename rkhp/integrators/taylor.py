"""The Taylor Hamiltonian Poisson integrator (THP) of order N (paper Thm 5.1, docs/theory.md §5) as
a substep provider of the driver (`rkhp.integrators.substeps`, docs/engine.md "One driver, many
substeps").

S(x) = sum_{|t| <= N} h^|t| e(t)/sigma(t) F(t)(x) over T (general birealisations) or T_0
(degenerate ones), f = H o alpha; psi = grad S; solve alpha(x, psi(x)) = y; y_next = beta(x, psi(x)).

At each Newton iterate x0 the F(t) are jets in dx = x - x0 (`rkhp.integrators.tree_jets`, margin
2: degree 2 at the roots), so S's degree-1 and degree-2 coefficients give psi and its Jacobian, and
alpha(x, psi + Jpsi dx) in jets of degree 1 the Newton matrix. Newton stops when the correction
is at most tol max(1, |y|), or when it halved and the next one, predicted |dx|^3 / |dx_prev|^2,
is; then x is polished with p = psi + Jpsi dx fixed (alpha(x, p) = y to round-off, at most three
corrections) and y_next = beta(x, p).

Compiled data: `ThpSubstep` (the trees' jets, the step's work arrays, the state y); `begin` (inlined
into the driver's loop: the addresses of the tapes and spaces are taken on its stack) and
`substep` are the provider's compiled functions; `thp_substep` builds the data once per system,
order and tree set (`ThpMethod`, `thp_method`).
"""

from __future__ import annotations

from functools import cache
from typing import NamedTuple

import numpy as np

from ..base.errors import InputError
from ..taylor.compiler import NJIT_NORC
from ..taylor.compiler import numba as nb
from ..taylor.interpreter import run_from
from ..taylor.linalg import lu_factor, lu_solve, max_abs
from ..trees.rooted import trees_up_to
from .engine_state import state_failure
from .failure import Failure
from .newton import NEWTON_TOLERANCE
from .tree_jets import TreeJets, addresses, elementary, tree_jets

MAX_ORDER = 8
"""The largest THP order N."""
POLISH_CORRECTIONS = 3
"""Newton corrections of x with p fixed after the iteration has converged (alpha(x, p) = y to
round-off, as the RKHP engine's polish)."""


class ThpMethod(NamedTuple):
    """The THP of order N over T_0 (`degenerate`) or T: what the driver's prepared data is kept
    for (`thp_method`: one object per method, the key is its identity) and its name."""

    order: int
    degenerate: bool
    name: str


@cache
def thp_method(order: int, degenerate: bool) -> ThpMethod:
    """The `ThpMethod` of order N (1 to MAX_ORDER; InputError otherwise), one per (N, degenerate)."""
    if isinstance(order, bool) or not isinstance(order, int) or not 1 <= order <= MAX_ORDER:
        raise InputError(f"THP order must be an integer from 1 to {MAX_ORDER}, got {order!r}")
    return ThpMethod(order, bool(degenerate), f"THP{order}" + (" (T_0)" if degenerate else " (T)"))


class ThpWork(NamedTuple):
    """The work arrays of a THP step (n: dimension): S (jet of degree 2 in n variables); psi,
    Jpsi; a, J: alpha and its Jacobian; LU, perm, v: the linear solve's; x, delta: Newton's
    iterate and correction; p: psi at the solution; y_next."""

    S: np.ndarray
    psi: np.ndarray
    Jpsi: np.ndarray
    a: np.ndarray
    J: np.ndarray
    LU: np.ndarray
    perm: np.ndarray
    v: np.ndarray
    x: np.ndarray
    delta: np.ndarray
    p: np.ndarray
    y_next: np.ndarray


class ThpSubstep(NamedTuple):
    """What the THP substeps of one run use: the trees' jets (`rkhp.integrators.tree_jets.TreeJets`,
    margin 2), the work arrays and the state y the substeps advance."""

    jets: TreeJets
    work: ThpWork
    y: np.ndarray


def thp_substep(system, method: ThpMethod, substeps: int = 1) -> ThpSubstep:
    """The data of THP substeps of `method` on `system` (every substep is the same step: no
    memory per substep)."""
    n = system.dim
    trees = trees_up_to(method.order, method.degenerate)
    jets = tree_jets(system, trees, method.order, 2)
    v, m = (n,), (n, n)
    work = ThpWork(np.zeros(int(jets.spaces[0].counts[2])), *(np.zeros(shape) for shape in (v, m, v, m, m)),
                   np.zeros(n, np.int64), *(np.zeros(v) for _ in range(5)))
    return ThpSubstep(jets, work, np.zeros(n))


def thp_extra(data: ThpSubstep) -> dict:
    """What a run reports of its THP substeps: the number of trees summed."""
    return {"trees": int(data.jets.table.degree.shape[0])}


@nb.njit(inline="always", **NJIT_NORC)
def _psi(jets, at, x, h, work):
    """psi(x) and its Jacobian into work.psi, work.Jpsi from S = sum h^|t| e(t)/sigma(t) F(t)."""
    elementary(jets, at, x)
    table, F, S = jets.table, jets.F, work.S
    n = x.shape[0]
    for m in range(S.shape[0]):
        S[m] = 0.0
    for t in range(table.degree.shape[0]):
        c = h ** table.power[t] * table.e[t] / table.sigma[t]
        for m in range(S.shape[0]):
            S[m] += c * F[t, m]
    for k in range(n):
        work.psi[k] = S[1 + k]
        for l in range(n):
            work.Jpsi[k, l] = S[table.hessian[k, l]] * (2.0 if k == l else 1.0)


@nb.njit(inline="always", **NJIT_NORC)
def _alpha(jets, at, x, p, Jp, with_Jp, work):
    """alpha(x + dx, p + Jp dx) (Jp taken as 0 unless `with_Jp`) and its Jacobian in dx at 0 into
    work.a, work.J."""
    W = jets.work.W
    n = x.shape[0]
    for k in range(n):
        for m in range(n + 1):
            W[k, m] = 0.0
        W[k, 0] = x[k]
        W[k, 1 + k] = 1.0
        W[n + k, 0] = p[k]
        for l in range(n):
            W[n + k, 1 + l] = Jp[k, l] if with_Jp else 0.0
    run_from(jets.run, at.alpha, np.int64(1), at.spaces[0], at.work)
    for k in range(n):
        out = jets.tapes.alpha.outputs[k]
        work.a[k] = W[out, 0]
        for l in range(n):
            work.J[k, l] = W[out, 1 + l]


@nb.njit(inline="always", **NJIT_NORC)
def _newton_correction(y, work, out):
    """out = J^-1 (y - a) (LU with partial pivoting); Failure.SINGULAR for a singular J,
    NEWTON_NON_FINITE for one with a non-finite entry."""
    n = y.shape[0]
    finite = True
    for i in range(n):
        out[i] = y[i] - work.a[i]
        for j in range(n):
            work.LU[i, j] = work.J[i, j]
            finite = finite and np.isfinite(work.J[i, j])
    if not finite:
        return Failure.NEWTON_NON_FINITE
    if not lu_factor(work.LU, work.perm):
        return Failure.SINGULAR
    lu_solve(work.LU, work.perm, out, work.v)
    return Failure.OK


@nb.njit(inline="always", **NJIT_NORC)
def _finish(jets, at, y, scale, work, domain):
    """The polish with p = work.p fixed and y_next = beta(x, p) (see the module); the Failure of
    y_next (`state_failure`)."""
    x, step = work.x, work.delta
    n = y.shape[0]
    for _ in range(POLISH_CORRECTIONS):
        _alpha(jets, at, x, work.p, work.Jpsi, False, work)
        cause = _newton_correction(y, work, step)
        if cause != Failure.OK:
            return cause
        for k in range(n):
            x[k] += step[k]
        if not max_abs(step) > 4e-16 * scale:
            break
    W = jets.work.W
    for k in range(n):
        W[k, 0] = x[k]
        W[n + k, 0] = work.p[k]
    run_from(jets.run, at.beta, np.int64(0), at.spaces[0], at.work)
    for k in range(n):
        work.y_next[k] = W[jets.tapes.beta.outputs[k], 0]
    return state_failure(work.y_next, domain)


@nb.njit(inline="always", **NJIT_NORC)
def _thp_newton(data, at, h, solver):
    """One THP step of size h from data.y (into data.y when it succeeds); returns (Failure,
    Newton iterations)."""
    jets, work, y = data.jets, data.work, data.y
    x, delta = work.x, work.delta
    n = y.shape[0]
    for k in range(n):
        x[k] = y[k]
    scale = max(1.0, max_abs(y))
    tol = solver.tol * scale
    previous = np.inf
    for it in range(1, solver.max_iter + 1):
        _psi(jets, at, x, h, work)
        _alpha(jets, at, x, work.psi, work.Jpsi, True, work)
        cause = _newton_correction(y, work, delta)
        if cause != Failure.OK:
            return cause, it
        size = max_abs(delta)
        if not np.isfinite(size):
            return Failure.NEWTON_NON_FINITE, it
        for k in range(n):
            x[k] += delta[k]
        predicted = size ** 3.0 / previous ** 2.0 if np.isfinite(previous) else np.inf
        if size <= tol or (size < 0.5 * previous and predicted <= tol):
            for k in range(n):
                acc = 0.0
                for l in range(n):
                    acc += work.Jpsi[k, l] * delta[l]
                work.p[k] = work.psi[k] + acc
            cause = _finish(jets, at, y, scale, work, solver.domain)
            if cause == Failure.OK:
                for k in range(n):
                    y[k] = work.y_next[k]
            return cause, it
        if size > 1e8 * scale:
            break
        previous = size
    return Failure.NEWTON_NO_CONVERGENCE, solver.max_iter


@nb.njit(inline="always", **NJIT_NORC)
def resume(data, y0):
    """The state set to y0 (data.y): a THP step keeps nothing from the steps before."""
    for k in range(y0.shape[0]):
        data.y[k] = y0[k]


@nb.njit(inline="always", **NJIT_NORC)
def begin(data, y0):
    """Start a run at y0 (`resume`); returns the addresses of the tapes, spaces and work
    arrays (`rkhp.integrators.tree_jets.addresses`: copies on the stack of the loop this is
    inlined into)."""
    resume(data, y0)
    return addresses(data.jets)


@nb.njit(inline="always", **NJIT_NORC)
def substep(data, at, i, hs, solver):
    """A THP step of size hs from data.y; returns (Failure, Newton iterations, 0 stage sweeps)."""
    cause, it = _thp_newton(data, at, hs, solver)
    return cause, it, 0


TOLERANCE = NEWTON_TOLERANCE
"""The default tolerance of THP's Newton iteration (`rkhp.integrators.newton`)."""
