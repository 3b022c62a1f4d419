"""The RKHP step as a compiled "Taylor tower" (paper §5.2, docs/theory.md §5, §7 and §10).

At the Newton iterate x0, each stage function g_i(x) = f(x, Z_i(x)), f = H o alpha, is held as its
Taylor polynomial in dx = x - x0, truncated at degree s + 2 - i (1-based i) for an explicit
tableau; g_1 = H; Z_i = h sum_{j<i} a_ij grad g_j is read off the coefficients. For an implicit
tableau every g_i is truncated at one degree D and the stage polynomials are solved by Picard
sweeps of Z_i = h sum_j a_ij grad g_j, warm-started from the previous iterate (`implicit_tower`,
docs/implicit.md). psi = h sum_i b_i grad g_i and its
Jacobian are the degree-0 and degree-1 coefficients. Newton solves alpha(x, psi(x)) = y (Jacobian
by the same jets) from a predicted start, then chord steps with value-only towers, stopping when
the predicted next correction is below the tolerance (then psi + Dpsi dx is reused at the new x,
docs/theory.md §7); a last cheap correction of x at fixed p makes alpha(x, p) = y hold to
round-off (so the Casimirs are kept); y_next = beta(x, p). Each stage is computed once: the cost
is polynomial in s (see `rkhp_step`).

The tableau, h and the states are data: one compilation serves every system and tableau. The
compiled data are named: `SystemTapes` (the four tapes), `rkhp.taylor.jets.JetSpace`,
`StepBuffers` (every work array of the step loop, allocated once by `step_buffers`). A run ends
with a `rkhp.integrators.failure.Failure`; `state_failure` is the one step validator (finite
values, the system's domain) of every integrator.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np

from ..systems.core import DOMAINS
from ..taylor.compiler import NJIT_NORC
from ..taylor.compiler import numba as nb
from ..taylor.composites import _lu, _lu_solve
from ..taylor.interpreter import TapeWork, run_tape, tape_work
from ..taylor.tape import Tape
from .failure import Failure

POSITIVE_ORTHANT = DOMAINS["positive orthant"]
THETA_MAX = 0.5
ROUND_OFF_SHARE = 0.1
"""A sweep whose stages' measure is below this share of the tolerance has converged, contracting
or not (its changes are round-off)."""
"""Largest measured contraction of the implicit stages' sweeps that `_tail_factor` trusts."""


class SystemTapes(NamedTuple):
    """The tapes of a system over the 2n inputs (x, p): f = H o alpha, H, alpha, beta."""

    f: Tape
    h: Tape
    alpha: Tape
    beta: Tape


class StepBuffers(NamedTuple):
    """Every work array of the RKHP step loop (n: dimension, s: stages).

    work: the interpreter's; G (s, n, jet size): gradients of the stage functions; psi, Jpsi,
    alpha, Jalpha: the tower's results; x, delta, res (n): Newton's iterate, correction and
    residual; LU (n, n), perm (n,) int64, v (n): the linear solve's (`solve_small`); hist (3, n):
    psi of the three previous steps; memo (6,): how many of them there are, Newton's measured
    quadratic constant L, the implicit stages' weight rate and effect factor (`_stage_measure`),
    the measure of their last sweep and its tail factor (`implicit_tower`); y, y_next (n): the
    state before and after the step; Gx (n): the point where G is expanded (implicit stages); changes
    (jet degree + 1,): per degree k of G, the weighted change of its coefficients at their last
    sweep (`_stage`, `implicit_tower`).
    """

    work: TapeWork
    G: np.ndarray
    psi: np.ndarray
    Jpsi: np.ndarray
    alpha: np.ndarray
    Jalpha: np.ndarray
    x: np.ndarray
    delta: np.ndarray
    res: np.ndarray
    LU: np.ndarray
    perm: np.ndarray
    v: np.ndarray
    hist: np.ndarray
    memo: np.ndarray
    y: np.ndarray
    y_next: np.ndarray
    Gx: np.ndarray
    changes: np.ndarray


class StageSolve(NamedTuple):
    """How the towers compute the stages (passed to compiled code as it is for an implicit
    tableau; the compiled loop takes None for an explicit one, `rkhp_method.compiled_stage`).

    degree 0: an explicit tableau, each stage once at its exact degree (`tower`); degree D >= 1:
    an implicit tableau, every stage function a jet of degree D solved by sweeps
    (`implicit_tower`), at most `max_sweeps` in one tower.
    """

    degree: int
    max_sweeps: int


def step_buffers(tapes: SystemTapes, n: int, s: int, space) -> StepBuffers:
    """The work arrays of the step loop for dimension n, s stages and a jet space."""
    size = space.size

    def vec():
        return np.zeros(n)

    def mat():
        return np.zeros((n, n))

    return StepBuffers(tape_work(tapes, size), np.zeros((s, n, size)), vec(), mat(), vec(), mat(),
                       vec(), vec(), vec(), mat(), np.zeros(n, np.int64), vec(), np.zeros((3, n)),
                       np.zeros(6), vec(), vec(), vec(), np.zeros(space.degree + 1))


@nb.njit(inline="always", **NJIT_NORC)
def solve_small(J, r, out, LU, perm, v):
    """out = J^{-1} r by LU factorisation with partial pivoting (`rkhp.taylor.composites._lu`,
    `_lu_solve`) in the work arrays LU (n x n), perm (n) and v (n): no allocation in the step
    loop. A singular J gives out = NaN (a non-finite correction: NEWTON_NON_FINITE). Inlined: a
    compiled function of its own costs a unit of compile time (docs/engine.md "Compile time")."""
    n = r.shape[0]
    for i in range(n):
        out[i] = r[i]
        for j in range(n):
            LU[i, j] = J[i, j]
    if _lu(LU, perm):
        _lu_solve(LU, perm, out, v)
    else:
        for i in range(n):
            out[i] = np.nan


@nb.njit(**NJIT_NORC)
def _set_x(W, x0, n, D, M):
    """Input rows 0..n-1: the jets x0_k + dx_k (degree <= D, M coefficients)."""
    for k in range(n):
        for m in range(M):
            W[k, m] = 0.0
        W[k, 0] = x0[k]
        if D >= 1:
            W[k, 1 + k] = 1.0


@nb.njit(inline="always", **NJIT_NORC)
def _stage(i, x0, A, h, D, j_end, tapes, space, buf, rate):
    """Stage i at x0: g_i = f(x0 + dx, Z_i), Z_i = h sum_{j < j_end} a_ij G[j], in jets of degree
    D (G[j] read up to degree D); G[i] := grad g_i up to degree D - 1 (its higher coefficients
    are left as they are). buf.changes[k] (k < D) is raised to the largest w_k |change| among the
    degree-k coefficients of G[i], w_k = k! rate^k (the implicit tower's convergence measure,
    `_stage_measure`; unused by the explicit tower)."""
    W, G = buf.work.W, buf.G
    counts, up, expo = space.counts, space.up, space.expo
    n = x0.shape[0]
    M = counts[D]
    _set_x(W, x0, n, D, M)
    zero_row = True
    for j in range(j_end):
        if A[i, j] != 0.0:
            zero_row = False
    for k in range(n):
        for m in range(M):
            W[n + k, m] = 0.0
        for j in range(j_end):
            c = h * A[i, j]
            if c != 0.0:
                for m in range(M):
                    W[n + k, m] += c * G[j, k, m]
    tape = tapes.h if zero_row else tapes.f
    run_tape(tape, D, space, buf.work)
    g = tape.outputs[0]
    changes = buf.changes
    for k in range(n):
        lo = 0
        w = 1.0
        for d in range(D):
            for m in range(lo, counts[d]):
                new = (expo[m, k] + 1) * W[g, up[m, k]]
                c = w * abs(new - G[i, k, m])
                if not c <= changes[d]:  # also catches NaN
                    changes[d] = c
                G[i, k, m] = new
            lo = counts[d]
            w *= rate * (d + 1)


@nb.njit(inline="always", **NJIT_NORC)
def _psi_alpha(x0, b, h, tapes, space, buf, jacobian):
    """psi = h sum_i b_i G[i](0) and alpha(x0, psi) into buf.psi, buf.alpha; with `jacobian`,
    also Dpsi (degree-1 coefficients) and the Jacobian of x -> alpha(x, psi(x))."""
    W, G, psi, Jpsi = buf.work.W, buf.G, buf.psi, buf.Jpsi
    s = b.shape[0]
    n = x0.shape[0]
    extra = np.int64(1) if jacobian else np.int64(0)
    for k in range(n):
        psi[k] = 0.0
        for i in range(s):
            psi[k] += h * b[i] * G[i, k, 0]
        if jacobian:
            for l in range(n):
                acc = 0.0
                for i in range(s):
                    acc += h * b[i] * G[i, k, 1 + l]
                Jpsi[k, l] = acc
    _set_x(W, x0, n, extra, n + 1)
    for k in range(n):
        W[n + k, 0] = psi[k]
        for l in range(n):
            W[n + k, 1 + l] = Jpsi[k, l] if jacobian else 0.0
    run_tape(tapes.alpha, extra, space, buf.work)
    for k in range(n):
        a = tapes.alpha.outputs[k]
        buf.alpha[k] = W[a, 0]
        if jacobian:
            for l in range(n):
                buf.Jalpha[k, l] = W[a, 1 + l]


@nb.njit(inline="always", **NJIT_NORC)
def tower(x0, A, b, h, tapes, space, buf, jacobian):
    """The explicit tower: psi and alpha(x0, psi(x0)) at x0 into buf.psi, buf.alpha (see module);
    with `jacobian`, also Dpsi and the Jacobian of x -> alpha(x, psi(x)) (stage degrees
    s + 2 - i; without, s + 1 - i: each stage exact, computed once)."""
    s = b.shape[0]
    extra = np.int64(1) if jacobian else np.int64(0)
    for i in range(s):
        _stage(i, x0, A, h, s + extra - i, i, tapes, space, buf, 1.0)
    _psi_alpha(x0, b, h, tapes, space, buf, jacobian)


@nb.njit(inline="always", **NJIT_NORC)
def _shift(G, delta, top, space):
    """Re-expand the polynomials G[j, k] (degree `top` in dx) at dx = delta, in place: for each
    variable v, the univariate Taylor shift (Horner's synthetic division, `top` passes) along v.
    Exact for polynomials; costs s n^2 top counts[top - 1] multiply-adds."""
    counts, up, expo = space.counts, space.up, space.expo
    s, n = G.shape[0], G.shape[1]
    if top <= 0:
        return
    last = counts[top - 1]
    for v in range(n):
        d = delta[v]
        if d == 0.0:
            continue
        for p in range(top):
            for m in range(last - 1, -1, -1):
                if expo[m, v] >= p:
                    u = up[m, v]
                    for j in range(s):
                        for k in range(n):
                            G[j, k, m] += d * G[j, k, u]


@nb.njit(inline="always", **NJIT_NORC)
def _set_p(W, x0, n):
    """Input rows for derivatives in p at p = 0: x = x0 (constant), p_k = dp_k (degree 1)."""
    for k in range(n):
        for m in range(n + 1):
            W[k, m] = 0.0
            W[n + k, m] = 0.0
        W[k, 0] = x0[k]
        W[n + k, 1 + k] = 1.0


@nb.njit(inline="always", **NJIT_NORC)
def _stage_measure(x0, A, b, h, tapes, space, buf):
    """The scales of the implicit stages' convergence measure at x0 (docs/implicit.md), into
    buf.memo[2] (rate) and buf.memo[3] (effect factor), from J = d_p alpha(x0, 0) and
    c = d_p f(x0, 0) (the tapes at degree 1 in p, x fixed).

    A change dG of the stage gradients changes Z_i by h sum_j a_ij dG_j and g_i by about c . dZ_i,
    so its degree-(k+1) part reaches the degree-k coefficients of the next sweep with a factor at
    most (k + 1) rho, rate rho = h |c|_1 max_i sum_j |a_ij|: a change of the degree-k
    coefficients reaches psi's coefficients (degree 0) k sweeps later with a factor at most
    w_k = k! rho^k (the sweeps at the same degree shrink it further, by O(h)). A change of
    psi = h sum_i b_i G_i(0) by dpsi moves y_next = beta(x, psi) with x (alpha(x, psi) = y) by
    about (d_p beta - d_p alpha) dpsi = pi dpsi, pi = J^T - J: the effect factor is
    |pi|_inf h sum_i |b_i|.
    """
    W = buf.work.W
    n = x0.shape[0]
    _set_p(W, x0, n)
    run_tape(tapes.f, np.int64(1), space, buf.work)
    g = tapes.f.outputs[0]
    c = 0.0
    for k in range(n):
        c += abs(W[g, 1 + k])
    _set_p(W, x0, n)
    run_tape(tapes.alpha, np.int64(1), space, buf.work)
    pi = 0.0
    for k in range(n):
        row = 0.0
        for l in range(n):
            row += abs(W[tapes.alpha.outputs[l], 1 + k] - W[tapes.alpha.outputs[k], 1 + l])
        pi = max(pi, row)
    a = 0.0
    for i in range(A.shape[0]):
        row = 0.0
        for j in range(A.shape[1]):
            row += abs(A[i, j])
        a = max(a, row)
    bsum = 0.0
    for i in range(b.shape[0]):
        bsum += abs(b[i])
    buf.memo[2] = h * c * a
    buf.memo[3] = pi * h * bsum


@nb.njit(inline="always", **NJIT_NORC)
def _value_degree(changes, factor, D, bound):
    """Jet degree of a value-only sweep: 1 + the highest degree k of G whose weighted change at
    its last sweep, times the effect factor, exceeds bound / D (at least 1: psi needs the
    degree-0 coefficients); the degrees above keep their last change in the measure."""
    top = np.int64(1)
    for k in range(D):
        if not factor * changes[k] * D <= bound:  # also catches NaN
            top = k + 1
    return top


@nb.njit(inline="always", **NJIT_NORC)
def _tail_factor(effect, previous):
    """theta / (1 - theta), theta = effect / previous the measured contraction of the stages'
    measure over the last sweep of this step, when theta <= THETA_MAX; else 1 (no contraction
    measured: `previous` is inf at the first sweep of a step):
    the changes of the sweeps still to come are at most theta^j effect (j = 1, 2, ...), so their
    sum is the effect times this factor (the a-posteriori rule of simplified Newton iterations,
    Hairer & Wanner, Solving ODEs II, IV.8)."""
    if previous == np.inf:
        return 1.0
    theta = effect / previous
    if theta <= THETA_MAX:
        return theta / (1.0 - theta)
    if theta < 1.0:
        return max(1.0, theta / (1.0 - theta))
    return np.inf


@nb.njit(**NJIT_NORC)
def implicit_tower(x0, A, b, h, tapes, space, buf, jacobian, stage, first, tol, scale):
    """The implicit tower (docs/theory.md §10, docs/implicit.md): psi and alpha(x0, psi) (with
    `jacobian`, their Jacobians) as `tower`, the stage polynomials G (degree D - 1,
    D = stage.degree: every stage function a jet of degree D) from Gauss–Seidel Picard sweeps of
    the functional equation Z_i = h sum_j a_ij grad_x f(x, Z_j(x)), warm-started from the
    previous tower's G (previous Newton iterate or step) re-expanded at x0 (`_shift`), or from
    G = 0 at the first step of a run.

    One sweep per tower, or, at the first tower of a run, sweeps until the stages have converged.
    A tower with `jacobian` sweeps every degree; a value-only tower only the degrees of G whose
    last change still mattered (`_value_degree`): the others keep their values re-expanded at x0.
    The effect of the stages' remaining error on the step is estimated by
    e = factor sum_k w_k |change of the degree-k coefficients at their last sweep|
    (`_stage_measure`, computed at the first tower of each step): the changes that the next
    sweeps would still bring to psi. From the second sweep of a step on, e is multiplied by the
    tail factor theta / (1 - theta) of the measured contraction theta of e over the last sweep
    (`_tail_factor`; also in `_value_degree`'s choice), except while settling from G = 0 (the first
    changes are the polynomials themselves, not a contraction: measured, the tail factor then stops
    D = 10 too early). The stages have converged when that is at most Newton's tolerance `tol`
    times `scale`.

    Returns (Failure, sweeps, converged): STAGES_NO_CONVERGENCE for a non-finite sweep or more
    than stage.max_sweeps sweeps in one tower.

    Not inlined (unlike `tower`): numba's inlining copies a callee's whole inlined subtree at every
    site, and the loop of explicit tableaux, where this call sits in a pruned branch, would pay
    for it (docs/engine.md "Compile time").
    """
    s = b.shape[0]
    n = x0.shape[0]
    D = np.int64(stage.degree)
    G, changes, memo = buf.G, buf.changes, buf.memo
    if memo[0] > 0.0 or not first:
        for k in range(n):
            buf.delta[k] = x0[k] - buf.Gx[k]
            buf.Gx[k] = x0[k]
        _shift(G, buf.delta, D - 1, space)
    else:
        for k in range(n):
            buf.Gx[k] = x0[k]
        for j in range(s):
            for k in range(n):
                for m in range(G.shape[2]):
                    G[j, k, m] = 0.0
    if first:
        _stage_measure(x0, A, b, h, tapes, space, buf)
        memo[4] = np.inf
        memo[5] = 1.0
    rate, factor = memo[2], memo[3]
    bound = tol * scale
    top = D if jacobian else _value_degree(changes, factor * memo[5], D, bound)
    settle = first and memo[0] == 0.0
    sweeps = 0
    converged = False
    while True:
        sweeps += 1
        for k in range(top):
            changes[k] = 0.0
        for i in range(s):
            _stage(i, x0, A, h, top, s, tapes, space, buf, rate)
        effect = 0.0
        for k in range(D):
            effect += factor * changes[k]
        if not np.isfinite(effect):
            return Failure.STAGES_NO_CONVERGENCE, sweeps, False
        tail = _tail_factor(effect, memo[4])
        memo[5] = max(1.0, tail) if settle else tail
        memo[4] = effect
        # a sweep that did not contract proves nothing, unless its changes are already far below
        # the tolerance (round-off: the measure then no longer decreases)
        converged = effect * memo[5] <= bound or effect <= ROUND_OFF_SHARE * bound
        if converged or not settle:
            break
        if sweeps >= stage.max_sweeps:
            return Failure.STAGES_NO_CONVERGENCE, sweeps, False
    _psi_alpha(x0, b, h, tapes, space, buf, jacobian)
    return Failure.OK, sweeps, converged


@nb.njit(**NJIT_NORC)
def _max_abs(v):
    r = 0.0
    for q in range(v.shape[0]):
        a = abs(v[q])
        if not a <= r:  # also catches NaN
            r = a
    return r


@nb.njit(inline="always", **NJIT_NORC)
def rkhp_step(A, b, h, tapes, space, buf, tol, max_iter, stage):
    """One RKHP step from buf.y into buf.y_next; returns (Failure, Newton iterations, stage
    sweeps). `stage` says how the towers compute the stages: None, explicit (`tower`), or a
    StageSolve, implicit (`implicit_tower`: one sweep per tower, so the iterations go on after
    Newton's test holds until the stages have converged too, at most max_iter + stage.max_sweeps
    of them; STAGES_NO_CONVERGENCE when Newton's test held but the stages did not settle).

    buf.hist[0..2]: psi of the three previous steps, buf.memo[0]: how many of them there are,
    buf.memo[1]: Newton's quadratic constant L (|dx_{k+1}| ~ L |dx_k|^2) measured on an earlier
    step (0 when unknown). The start is predicted: psi extrapolated (quadratically) from the
    previous steps, x from alpha(x, psi_predicted) = y by a cheap Newton step (no tower). The first
    tower has the Jacobian; it is the last when max(2 L, 1/max(1, |y|)) |dx|^2 is below the
    tolerance. Later iterations are chord steps with value-only towers (one degree less, about
    half the cost), stopped when theta/(1 - theta) |dx_k| is (theta = |dx_k|/|dx_{k-1}|); the
    Jacobian is refreshed when theta > 1/4 (docs/theory.md §7 measured 2 full towers per step
    instead of 3).
    """
    y, x, res, delta, hist, memo = buf.y, buf.x, buf.res, buf.delta, buf.hist, buf.memo
    n = y.shape[0]
    scale = max(1.0, _max_abs(y))
    for k in range(n):
        x[k] = y[k]
    if memo[0] >= 1.0:
        for k in range(n):
            if memo[0] >= 3.0:
                res[k] = 3.0 * (hist[0, k] - hist[1, k]) + hist[2, k]
            elif memo[0] >= 2.0:
                res[k] = 2.0 * hist[0, k] - hist[1, k]
            else:
                res[k] = hist[0, k]
        _polish(res, tapes.alpha, space, buf, scale, np.int64(1), np.bool_(True))
        if not np.isfinite(_max_abs(x)):
            for k in range(n):
                x[k] = y[k]
    previous = np.inf
    converged = False
    full = np.bool_(True)
    it = 0
    # stage is None for an explicit tableau: numba prunes the implicit branches, so the loop of
    # explicit tableaux is compiled without them (`rkhp_method.compiled_stage`)
    limit = max_iter if stage is None else max_iter + stage.max_sweeps
    sweeps = 0
    stages_done = stage is None
    newton_done = False
    while it < limit:
        it += 1
        # a full tower (Jacobian) first; then value-only towers with that Jacobian (chord)
        if stage is None:
            tower(x, A, b, h, tapes, space, buf, full)
        else:
            cause, done, stages_done = implicit_tower(
                x, A, b, h, tapes, space, buf, full, stage, np.bool_(it == 1), tol, scale)
            sweeps += done
            if cause != Failure.OK:
                return cause, it, sweeps
        for k in range(n):
            res[k] = y[k] - buf.alpha[k]
        solve_small(buf.Jalpha, res, delta, buf.LU, buf.perm, buf.v)
        size = _max_abs(delta)
        if not np.isfinite(size):
            return Failure.NEWTON_NON_FINITE, it, sweeps
        for k in range(n):
            x[k] += delta[k]
        if previous < np.inf and previous > 1e3 * tol * scale and size < 0.5 * previous:
            memo[1] = size / (previous * previous)
        if previous < np.inf:
            # chord step: |dx_{k+1}| <~ theta |dx_k| with theta = |dx_k| / |dx_{k-1}|
            theta = size / previous
            predicted = theta / (1.0 - theta) * size if theta < 0.5 else np.inf
        else:
            # next correction ~ L |dx|^2; one measured L can be far too small (a correction
            # along a flat direction), hence the floor 1 / scale
            predicted = max(2.0 * memo[1], 1.0 / scale) * size * size
        newton_done = size <= tol * scale or predicted <= tol * scale
        if newton_done and stages_done:
            converged = True
            for k in range(n):
                acc = buf.psi[k]
                for l in range(n):
                    acc += buf.Jpsi[k, l] * delta[l]
                res[k] = acc
            break
        if size > 1e8 * scale:
            break
        # refresh the Jacobian when the chord iteration converges slowly
        full = np.bool_(previous < np.inf and size > 0.25 * previous)
        previous = size
    if not converged:
        if newton_done:
            return Failure.STAGES_NO_CONVERGENCE, it, sweeps
        return Failure.NEWTON_NO_CONVERGENCE, it, sweeps
    _polish(res, tapes.alpha, space, buf, scale, np.int64(1), np.bool_(False))
    for k in range(n):
        hist[2, k] = hist[1, k]
        hist[1, k] = hist[0, k]
        hist[0, k] = res[k]
    memo[0] = min(memo[0] + 1.0, 3.0)
    W = buf.work.W
    for k in range(n):
        W[k, 0] = x[k]
        W[n + k, 0] = res[k]
    run_tape(tapes.beta, np.int64(0), space, buf.work)
    for k in range(n):
        buf.y_next[k] = W[tapes.beta.outputs[k], 0]
    return Failure.OK, it, sweeps


@nb.njit(inline="always", **NJIT_NORC)
def _polish(p, atape, space, buf, scale, iterations, exact):
    """Solve alpha(x, p) = y for x = buf.x with p fixed by at most `iterations` cheap steps (no
    tower): with `exact`, Newton steps (J := d_x alpha(x, p) by degree-1 jets); otherwise steps
    with the given approximate J = buf.Jalpha (the last tower's), from values of alpha only.

    With p fixed, C(beta(x, p)) = C(alpha(x, p)) for every Casimir C, so the final such step keeps
    the Casimirs to round-off whatever the accuracy of psi (docs/theory.md §4): only alpha's
    residual matters. Its correction is below the Newton tolerance, so J's O(h) inexactness is
    harmless.
    """
    y, x, J, alpha, delta, W = buf.y, buf.x, buf.Jalpha, buf.alpha, buf.delta, buf.work.W
    n = y.shape[0]
    for _ in range(iterations):
        degree = np.int64(1) if exact else np.int64(0)
        for k in range(n):
            W[k, 0] = x[k]
            W[n + k, 0] = p[k]
            if exact:
                for l in range(n):
                    W[k, 1 + l] = 1.0 if k == l else 0.0
                    W[n + k, 1 + l] = 0.0
        run_tape(atape, degree, space, buf.work)
        for k in range(n):
            a = atape.outputs[k]
            alpha[k] = y[k] - W[a, 0]
            if exact:
                for l in range(n):
                    J[k, l] = W[a, 1 + l]
        solve_small(J, alpha, delta, buf.LU, buf.perm, buf.v)
        for k in range(n):
            x[k] += delta[k]
        if not _max_abs(delta) > 4e-16 * scale:
            break


@nb.njit(**NJIT_NORC)
def state_failure(y, domain):
    """The one step validator of every integrator: Failure.NON_FINITE if a component of y is not
    finite, Failure.LEFT_DOMAIN if y is outside the domain (code of `rkhp.systems.core.DOMAINS`),
    else Failure.OK."""
    for k in range(y.shape[0]):
        if not np.isfinite(y[k]):
            return Failure.NON_FINITE
    if domain == POSITIVE_ORTHANT:
        for k in range(y.shape[0]):
            if not y[k] > 0.0:
                return Failure.LEFT_DOMAIN
    return Failure.OK


@nb.njit(**NJIT_NORC)
def rkhp_run(y0, A, b, h, n_steps, tapes, space, buf, domain, tol, max_iter, stage, states,
             iterations, sweeps, keep_all):
    """Integrate n_steps from y0; states[k] = y_k (keep_all) or states[0] = the last state;
    iterations[k], sweeps[k]: Newton iterations and stage sweeps of step k.

    Returns (number of completed steps, Failure of the step after them or Failure.OK).
    """
    n = y0.shape[0]
    y = buf.y
    for k in range(n):
        y[k] = y0[k]
    buf.memo[0] = 0.0
    buf.memo[1] = 0.0
    for k in range(n):
        states[0, k] = y[k]
    for step in range(n_steps):
        cause, it, done = rkhp_step(A, b, h, tapes, space, buf, tol, max_iter, stage)
        iterations[step] = it
        sweeps[step] = done
        if cause == Failure.OK:
            cause = state_failure(buf.y_next, domain)
        if cause != Failure.OK:
            return step, cause
        row = step + 1 if keep_all else 0
        for k in range(n):
            y[k] = buf.y_next[k]
            states[row, k] = y[k]
    return n_steps, Failure.OK
