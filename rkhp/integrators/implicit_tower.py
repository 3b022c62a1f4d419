"""The implicit tower (docs/theory.md §10, docs/implicit.md): for an implicit tableau every stage
function g_i is truncated at one degree D and the stage polynomials are solved by Gauss–Seidel
Picard sweeps of Z_i = h sum_j a_ij grad g_j, warm-started from the previous iterate re-expanded at
the new one (`implicit_tower`); the stages' remaining error is measured by its effect on the step
(`_stage_measure`, `_stage_weights`), and where the sweeps stall the stage equations are solved by
Newton's method (`_stage_newton`, docs/implicit.md "When the sweeps stall").
"""

from __future__ import annotations

import numpy as np

from ..taylor.compiler import NJIT_NORC
from ..taylor.compiler import numba as nb
from ..taylor.interpreter import run_from
from ..taylor.linalg import lu_factor, lu_solve, max_abs
from ..taylor.ops import COMPOSE_ARG
from .engine_state import (
    MEMO_EFFECT,
    MEMO_FACTOR,
    MEMO_HISTORY,
    MEMO_JACOBIAN_KEPT,
    MEMO_RATE,
    MEMO_SHIFT_BEFORE,
    MEMO_SHIFT_SINCE,
    MEMO_STAGE_NEWTON_FAILS,
    MEMO_STALLED,
    MEMO_SWEEPS,
)
from .failure import Failure
from .tower import alpha_at_psi, psi_alpha, stage_jet

THETA_MAX = 0.5
"""Largest measured contraction of the implicit stages' sweeps that `_tail_factor` trusts."""
ROUND_OFF_SHARE = 0.1
"""A sweep whose stages' measure is below this share of the tolerance has converged, contracting
or not (its changes are round-off)."""
TRUST_SWEEPS = 2
"""A step starts from the defect predicted by the previous step when that step made at most this
many sweeps (`implicit_tower`)."""
STALE_SHARE = 0.5
"""Share of the tolerance that the degrees a value-only sweep leaves out may keep (`_value_degree`)."""
SHIFT_MARGIN = 10.0
"""Safety factor on the linear estimate of how a Taylor shift moves the degrees of G that
value-only sweeps leave out (`_stale_factor`)."""


STAGE_NEWTON_ITERATIONS = 30
"""Most iterations of one `_stage_newton` solve of the stage equations."""


STAGE_NEWTON_DONE = 1e-14
"""`_stage_newton` has converged when a full correction is at most this times the coefficients'
size (max(1, max-norm)): 45 eps, the round-off of a sweep of the stage polynomials."""
STAGE_NEWTON_ROUND_OFF = 1e-12
"""A correction of `_stage_newton` that no halving makes decrease the residual is round-off (the
iteration has converged) when at most this times the coefficients' size: the forward-difference
Jacobian (step sqrt(eps)) is accurate to about sqrt(eps), so the residual's noise of a few eps
times the coefficients, divided by that accuracy, is below it."""
STAGE_NEWTON_HALVINGS = 30
"""Most halvings of a correction of `_stage_newton` before it gives up (no decrease of the
residual along the correction: no solution near the iterate)."""
STAGE_NEWTON_FAILS_PER_STEP = 2
"""Most `_stage_newton` solves that may fail in one step: after them the step's towers only sweep,
so a step whose stages have no solution near its iterates ends after its Newton iterations
(NEWTON_NO_CONVERGENCE or STAGES_NO_CONVERGENCE) at the cost of sweeps, not of a solve (each a
forward-difference Jacobian of up to STAGE_NEWTON_MAX_UNKNOWNS columns) per iteration."""
STAGE_NEWTON_CONTRACTION = 0.5
"""A correction of `_stage_newton` with a kept (earlier) Jacobian larger than this times the
previous one refreshes the Jacobian (the chord iteration converges too slowly)."""


@nb.njit(inline="always", **NJIT_NORC)
def _stage(i, x0, A, h, D, j_end, tapes, space, buf, rate):
    """Stage i at x0 (`stage_jet`): G[i] := grad g_i up to degree D - 1 (its higher coefficients
    are left as they are). buf.changes[k] (k < D) is increased by rate^k times the largest
    w |change| among the degree-k coefficients of G[i], w = buf.weights[i] of the coefficient (the
    implicit tower's convergence measure, `_stage_weights`)."""
    W, G = buf.work.W, buf.G
    g = stage_jet(i, x0, A, h, D, j_end, tapes, space, buf)
    counts, up, expo = space.counts, space.up, space.expo
    n = x0.shape[0]
    changes, weights = buf.changes, buf.weights
    lo = 0
    power = 1.0
    for d in range(D):
        largest = 0.0
        for k in range(n):
            for m in range(lo, counts[d]):
                new = (expo[m, k] + 1) * W[g, up[m, k]]
                c = weights[i, m] * abs(new - G[i, k, m])
                if not c <= largest:  # also catches NaN
                    largest = c
                G[i, k, m] = new
        changes[d] += power * largest
        lo = counts[d]
        power *= rate


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
    """The scales of the implicit stages' convergence measure at x0 (docs/implicit.md): the rate
    h |c|_1 of `_stage_weights` into buf.memo[MEMO_RATE] and the effect factor into
    buf.memo[MEMO_FACTOR], from J = d_p alpha(x0, 0) and c = d_p f(x0, 0) (the tapes at degree 1
    in p, x fixed).

    A change of psi = h sum_i b_i G_i(0) by dpsi moves y_next = beta(x, psi) with x
    (alpha(x, psi) = y) by about (d_p beta - d_p alpha) dpsi = pi dpsi, pi = J^T - J: the effect
    factor is |pi|_inf h sum_i |b_i|.
    """
    W = buf.work.W
    n = x0.shape[0]
    _set_p(W, x0, n)
    run_from(tapes.run, tapes.f_at, np.int64(1), tapes.space_at, tapes.work_at)
    g = tapes.f.outputs[0]
    c = 0.0
    for k in range(n):
        c += abs(W[g, 1 + k])
    _set_p(W, x0, n)
    run_from(tapes.run, tapes.alpha_at, np.int64(1), tapes.space_at, tapes.work_at)
    pi = 0.0
    for k in range(n):
        row = 0.0
        for l in range(n):
            row += abs(W[tapes.alpha.outputs[l], 1 + k] - W[tapes.alpha.outputs[k], 1 + l])
        pi = max(pi, row)
    bsum = 0.0
    for i in range(b.shape[0]):
        bsum += abs(b[i])
    buf.memo[MEMO_RATE] = h * c
    buf.memo[MEMO_FACTOR] = pi * h * bsum


@nb.njit(inline="always", **NJIT_NORC)
def _stage_weights(A, b, space, weights):
    """weights[j, m] = m! (|b|^T |A|^|m|)_j / sum_i |b_i| for the coefficients m of G[j]
    (m! = prod_v m_v!, |A| and |b| entrywise; docs/implicit.md): with the effect factor (which
    has the sum) and rate^|m|, rate = h |c|_1 (`_stage_measure`, each step), the weight of a
    change of that coefficient in the stages' measure (`_stage`).

    A change dG of the stage gradients changes Z_i by h sum_j a_ij dG_j and g_i by about c . dZ_i
    (c = d_p f(x0, 0)). Counted in derivatives (a coefficient times m!), the order-|m| derivatives
    of grad g_i are order-(|m| + 1) derivatives of g_i, so a change of the order-(k + 1)
    derivatives of G_j moves the order-k derivatives of G_i (at a later sweep, or later in the
    same Gauss-Seidel sweep) by at most h |c|_1 |a_ij| times its size, and reaches psi's
    coefficients (order 0) after k such passes, times h |b_i| at the end: a change of coefficient
    m of G[j] moves psi by at most h m! (h |c|_1)^|m| (|b|^T |A|^|m|)_j times it (the sweeps at
    the same degree shrink it further, by O(h)). This is at most |m|! rho^|m| sum_i |b_i|,
    rho = h |c|_1 max_i sum_j |a_ij|, the cruder bound that keeps only the largest row of A and
    the worst monomial of the degree.
    """
    s = b.shape[0]
    counts, expo = space.counts, space.expo
    top = counts.shape[0] - 1
    bsum = 0.0
    for j in range(s):
        bsum += abs(b[j])
    # (|b|^T |A|^d)_j / bsum at the first monomial of each degree d ...
    for j in range(s):
        weights[j, 0] = abs(b[j]) / bsum
    for d in range(1, top + 1):
        here, below = counts[d - 1], counts[d - 2] if d >= 2 else 0
        for j in range(s):
            acc = 0.0
            for i in range(s):
                acc += weights[i, below] * abs(A[i, j])
            weights[j, here] = acc
    # ... then times m! on every monomial of the degree (the first one last)
    for d in range(top, -1, -1):
        lo = counts[d - 1] if d >= 1 else 0
        for j in range(s):
            base = weights[j, lo]
            for m in range(counts[d] - 1, lo - 1, -1):
                f = 1.0
                for v in range(expo.shape[1]):
                    for q in range(2, expo[m, v] + 1):
                        f *= q
                weights[j, m] = base * f


@nb.njit(inline="always", **NJIT_NORC)
def _kept(changes, defects, factor, stale, top, D):
    """The measure of the degrees top..D - 1 of G that a value-only sweep leaves out: their last
    changes, plus (stale - 1) times those and the step's predicted defect (`_stale_factor`),
    times the effect factor."""
    kept = 0.0
    for k in range(top, D):
        kept += factor * (changes[k] + (stale - 1.0) * (changes[k] + defects[k]))
    return kept


@nb.njit(inline="always", **NJIT_NORC)
def _value_degree(changes, defects, factor, stale, D, bound):
    """Jet degree of a value-only sweep: the lowest t >= 0 such that the degrees t..D - 1 of G,
    not swept, keep a measure (`_kept`) of at most STALE_SHARE * bound (0: no sweep, psi from the
    polynomials re-expanded at x0)."""
    top = np.int64(D)
    while top > 0 and _kept(changes, defects, factor, stale, top - 1, D) <= STALE_SHARE * bound:
        top -= 1
    return top


@nb.njit(inline="always", **NJIT_NORC)
def _stale_factor(since, before):
    """1 + SHIFT_MARGIN since / before: by how much the degrees of G that value-only sweeps have
    left out may have moved off their fixed point, relative to their last changes and the step's
    predicted defect (`_kept`), after Taylor shifts by `since` in all (max-norm) since their last
    sweep, which followed shifts by `before`. Truncating the shift moves the stage polynomials'
    fixed point off the shifted polynomials linearly in the shift, and that last sweep (with the
    defect predicted for it) measured the move of the shifts before it; inf when they had none
    to measure (the first tower of a run, from G = 0)."""
    if since == 0.0:
        return 1.0
    if before == 0.0:
        return np.inf
    return 1.0 + SHIFT_MARGIN * since / before


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


@nb.njit(inline="always", **NJIT_NORC)
def _predict(G, defect, top, space, before, keep):
    """Before the first sweep of a step, on the coefficients of degree < top: with `before`,
    G += defect (G still expanded at the previous step's point: the Taylor shift follows);
    otherwise defect := (defect if `keep` else 0) - G (G now shifted: the sweep's changes are
    added back by `_learn`)."""
    M = space.counts[top - 1]
    for j in range(G.shape[0]):
        for k in range(G.shape[1]):
            for m in range(M):
                if before:
                    G[j, k, m] += defect[j, k, m]
                elif keep:
                    defect[j, k, m] -= G[j, k, m]
                else:
                    defect[j, k, m] = -G[j, k, m]


@nb.njit(inline="always", **NJIT_NORC)
def _learn(G, defect, weights, rate, top, space, defects):
    """After the first sweep of a step: defect += G, so that it becomes the prediction (if the
    step used one) plus what the sweep still changed: the predicted defect of the next step (the
    stage polynomials move smoothly along the solution, and so does what their Taylor shift
    misses); defects[k] := its measure at degree k (as `_stage`'s changes)."""
    counts = space.counts
    for d in range(top):
        defects[d] = 0.0
    for j in range(G.shape[0]):
        lo = 0
        power = 1.0
        for d in range(top):
            largest = 0.0
            for k in range(G.shape[1]):
                for m in range(lo, counts[d]):
                    defect[j, k, m] += G[j, k, m]
                    c = weights[j, m] * abs(defect[j, k, m])
                    if not c <= largest:  # also catches NaN
                        largest = c
            defects[d] += power * largest
            lo = counts[d]
            power *= rate


@nb.njit(inline="always", **NJIT_NORC)
def _psi_at(b, h, space, buf, top):
    """psi = h sum_i b_i G[i](delta), delta = buf.delta, into buf.psi: the degree-0 coefficients
    of the polynomials G (degree < top) re-expanded at dx = delta, without re-expanding them
    (the monomials' values at delta in the scratch row COMPOSE_ARG of the interpreter's S)."""
    G, psi, delta, up, S = buf.G, buf.psi, buf.delta, space.up, buf.work.S
    M = space.counts[top - 1]
    S[COMPOSE_ARG, 0] = 1.0
    for m in range(space.counts[top - 2] if top >= 2 else 0):
        for v in range(delta.shape[0]):
            S[COMPOSE_ARG, up[m, v]] = S[COMPOSE_ARG, m] * delta[v]
    for k in range(G.shape[1]):
        acc = 0.0
        for i in range(G.shape[0]):
            part = 0.0
            for m in range(M):
                part += G[i, k, m] * S[COMPOSE_ARG, m]
            acc += h * b[i] * part
        psi[k] = acc


@nb.njit(**NJIT_NORC)
def _sweep_residual(u, r, x0, A, h, D, tapes, space, buf, M):
    """r = P(u) - u, P one Gauss-Seidel sweep of every stage at degree D (`_stage`) of the
    coefficients u of the stage polynomials G (degree < D, M = counts[D - 1] each, flattened over
    (stage, component, coefficient)); G := P(u). Returns the max-norm of r (inf if non-finite).
    P and the Picard sweeps of `implicit_tower` have the same fixed points: the stage equations.
    A compiled unit of its own, called at three sites of `_stage_newton` (with `_sweep_jacobian`,
    inlined there): inlined, each site would compile the stages' sweep again (docs/engine.md
    "Compile time"); a call costs nothing beside a sweep's interpreter calls."""
    G = buf.G
    s, n = G.shape[0], G.shape[1]
    q = 0
    for j in range(s):
        for k in range(n):
            for m in range(M):
                G[j, k, m] = u[q]
                q += 1
    for i in range(s):
        _stage(i, x0, A, h, D, s, tapes, space, buf, 1.0)
    size = 0.0
    q = 0
    for j in range(s):
        for k in range(n):
            for m in range(M):
                r[q] = G[j, k, m] - u[q]
                a = abs(r[q])
                if not a <= size:  # also catches NaN
                    size = a
                q += 1
    return size


@nb.njit(inline="always", **NJIT_NORC)
def _sweep_jacobian(x0, A, h, D, tapes, space, buf, M):
    """work.J := the Jacobian of `_sweep_residual` at work.u (whose residual is work.r) by forward
    differences, step sqrt(eps) times max(1, |u_c|), factorised in place; False if singular."""
    work = buf.stage_newton
    u, r, rt, J = work.u, work.r, work.rt, work.J
    N = u.shape[0]
    for c in range(N):
        e = 1.4901161193847656e-08 * max(1.0, abs(u[c]))
        keep = u[c]
        u[c] = keep + e
        _sweep_residual(u, rt, x0, A, h, D, tapes, space, buf, M)
        u[c] = keep
        for q in range(N):
            J[q, c] = (rt[q] - r[q]) / e
    return lu_factor(J, work.perm)


@nb.njit(**NJIT_NORC)
def _stage_newton(x0, A, h, D, tapes, space, buf):
    """Solve the stage equations (the fixed point of the sweeps) for the coefficients of the stage
    polynomials G by Newton's method, when the Picard sweeps stall (h beyond their contraction
    radius, where a solution may still exist; docs/implicit.md "When the sweeps stall").

    Simplified Newton: the forward-difference Jacobian (`_sweep_jacobian`) is kept between calls
    (the stage equations change little from one Newton iterate or step to the next) and refreshed
    when a correction is not below STAGE_NEWTON_CONTRACTION times the previous one, or when it
    does not decrease the residual; each correction is halved until the residual decreases. From
    the polynomials in G (G = 0 if they are not finite). Converged when a correction is at
    round-off of the coefficients (`STAGE_NEWTON_DONE`, `STAGE_NEWTON_ROUND_OFF`); returns whether
    it did, G holding the solution (buf.changes reset), or the polynomials it started from when
    it did not. False at once when the work arrays hold fewer than the unknowns
    (`STAGE_NEWTON_MAX_UNKNOWNS`).
    """
    G, memo, work = buf.G, buf.memo, buf.stage_newton
    s, n = G.shape[0], G.shape[1]
    M = space.counts[D - 1]
    N = s * n * M
    if work.u.shape[0] != N:
        return False
    u, r, trial, rt, tmp = work.u, work.r, work.trial, work.rt, work.tmp
    q = 0
    finite = True
    for j in range(s):
        for k in range(n):
            for m in range(M):
                u[q] = G[j, k, m]
                work.start[q] = u[q]
                if not np.isfinite(u[q]):
                    finite = False
                q += 1
    if not finite:
        for q in range(N):
            u[q] = 0.0
    size = _sweep_residual(u, r, x0, A, h, D, tapes, space, buf, M)
    fresh = memo[MEMO_JACOBIAN_KEPT] == 0.0
    previous = np.inf
    converged = False
    for _ in range(STAGE_NEWTON_ITERATIONS):
        if not np.isfinite(size):
            break
        if fresh:
            if not _sweep_jacobian(x0, A, h, D, tapes, space, buf, M):
                memo[MEMO_JACOBIAN_KEPT] = 0.0
                break
            memo[MEMO_JACOBIAN_KEPT] = 1.0
        for q in range(N):
            trial[q] = -r[q]
        lu_solve(work.J, work.perm, trial, tmp)
        correction = max_abs(trial)
        scale = max(1.0, max_abs(u))
        if not fresh and not correction < STAGE_NEWTON_CONTRACTION * previous:
            fresh = True  # the kept Jacobian no longer serves: refresh it
            continue
        step = 1.0
        accepted = False
        for _h in range(STAGE_NEWTON_HALVINGS):
            for q in range(N):
                rt[q] = u[q] + step * trial[q]
            new = _sweep_residual(rt, tmp, x0, A, h, D, tapes, space, buf, M)
            if new < size:
                accepted = True
                break
            step *= 0.5
        if not accepted:
            if correction <= STAGE_NEWTON_ROUND_OFF * scale:
                converged = True  # the residual's own noise
                break
            if fresh:
                break
            fresh = True
            continue
        for q in range(N):
            u[q] = rt[q]
            r[q] = tmp[q]
        size = new
        previous = step * correction
        fresh = False
        if step * correction <= STAGE_NEWTON_DONE * scale:
            converged = True
            break
    q = 0
    for j in range(s):
        for k in range(n):
            for m in range(M):
                G[j, k, m] = u[q] if converged else work.start[q]
                q += 1
    if converged:
        for k in range(D + 1):
            buf.changes[k] = 0.0
    return converged


@nb.njit(**NJIT_NORC)
def implicit_tower(x0, method, tapes, space, buf, jacobian, stage, first, bound):
    """The implicit tower (docs/theory.md §10, docs/implicit.md): psi and alpha(x0, psi) (with
    `jacobian`, their Jacobians) as `tower`, the stage polynomials G (degree D - 1,
    D = stage.degree: every stage function a jet of degree D) from Gauss–Seidel Picard sweeps of
    the functional equation Z_i = h sum_j a_ij grad_x f(x, Z_j(x)), warm-started from the
    previous tower's G (previous Newton iterate or step) re-expanded at x0 (`_shift`), or from
    G = 0 at the first step of a run.

    One sweep per tower, or, at the first tower of a run, sweeps until the stages have converged.
    The first tower of a later step starts from the polynomials plus the defect that the first
    sweep of the previous step added to them (`_predict`, `_learn`: what the Taylor shift misses
    moves smoothly along the solution). A tower with `jacobian` sweeps every degree; a value-only
    tower only the degrees of G below `_value_degree`: the others keep their values re-expanded
    at x0; if it is 0, no sweep and no re-expansion (`_psi_at`). The effect of the stages'
    remaining error on the step is estimated by e = factor sum_{k, i} w |change of a degree-k
    coefficient of G[i] at its last sweep| (largest over the coefficients; `_stage_measure` and
    `_stage_weights`, computed at the first tower of each step): the changes that the next sweeps
    would still bring to psi. The part of the degrees swept now is multiplied by the tail factor
    theta / (1 - theta) of its measured contraction theta over their previous sweep in this step
    (`_tail_factor`; none at the first sweep of a step, at least 1 while settling from G = 0: the
    first changes are the polynomials themselves, not a contraction, and measured, the tail factor
    then stops D = 10 too early); the part of the degrees left out counts once, times
    `_stale_factor` for the Taylor shifts since their last sweep. The stages have converged when
    that is at most `bound` (Newton's tolerance times the state's scale, `rkhp_step`).

    When the sweeps stall (a non-finite one, stage.max_sweeps of them while settling, or half as
    many in one step without converging), the stages are solved by `_stage_newton`, and from
    then on in the run every tower solves them so (MEMO_STALLED; docs/implicit.md "When the
    sweeps stall") until it finds no solution, where the sweeps take over again; at most
    STAGE_NEWTON_FAILS_PER_STEP such solves may find nothing in one step, after which its towers
    only sweep.

    Returns (Failure, sweeps, converged): STAGES_NO_CONVERGENCE when the sweeps stalled while
    settling (or went non-finite) and `_stage_newton` found no solution; a step whose sweeps
    stalled goes on sweeping when it found none.

    Not inlined (unlike `tower`): numba's inlining copies a callee's whole inlined subtree at every
    site, and the loop of explicit tableaux, where this call sits in a pruned branch, would pay
    for it (docs/engine.md "Compile time").
    """
    A, b, h = method.A, method.b, method.h
    s = b.shape[0]
    n = x0.shape[0]
    D = np.int64(stage.degree)
    G, changes, memo = buf.G, buf.changes, buf.memo
    settle = first and memo[MEMO_HISTORY] == 0.0
    # the first tower of a later step learns the defect, and starts from the shifted polynomials
    # plus the one learnt at the previous step if that step converged in at most TRUST_SWEEPS
    # sweeps (the defect it learnt was most of what it needed)
    learn = first and not settle
    predict = learn and memo[MEMO_SWEEPS] <= TRUST_SWEEPS
    if first:
        _stage_measure(x0, A, b, h, tapes, space, buf)
        memo[MEMO_EFFECT] = np.inf
        memo[MEMO_STAGE_NEWTON_FAILS] = 0.0
    factor = memo[MEMO_FACTOR]
    for k in range(n):
        buf.delta[k] = x0[k] - buf.Gx[k]
    shift = 0.0 if settle else max_abs(buf.delta)
    since = memo[MEMO_SHIFT_SINCE] + shift
    stale = _stale_factor(since, memo[MEMO_SHIFT_BEFORE])
    # once the sweeps have stalled in a run, every tower solves its stages by Newton (`_stage_newton`)
    newton = memo[MEMO_STALLED] > 0.0 and not settle
    top = D if jacobian or newton else _value_degree(changes, buf.defects, factor, stale, D, bound)
    memo[MEMO_SHIFT_BEFORE], memo[MEMO_SHIFT_SINCE] = (since, 0.0) if top == D else (memo[MEMO_SHIFT_BEFORE], since)
    if settle:
        for k in range(n):
            buf.Gx[k] = x0[k]
        for j in range(s):
            for k in range(n):
                for m in range(G.shape[2]):
                    G[j, k, m] = 0.0
                    buf.defect[j, k, m] = 0.0
        for k in range(D + 1):
            buf.defects[k] = 0.0
        memo[MEMO_SWEEPS] = 0.0
        memo[MEMO_STALLED] = 0.0
        memo[MEMO_JACOBIAN_KEPT] = 0.0
        _stage_weights(A, b, space, buf.weights)
    elif top > 0:
        if predict:
            _predict(G, buf.defect, D, space, np.bool_(True), predict)
        for k in range(n):
            buf.Gx[k] = x0[k]
        _shift(G, buf.delta, D - 1, space)
        if learn:
            _predict(G, buf.defect, D, space, np.bool_(False), predict)
    if newton:
        if _stage_newton(x0, A, h, D, tapes, space, buf):
            psi_alpha(x0, b, h, tapes, space, buf, jacobian)
            return Failure.OK, 0, True
        memo[MEMO_STALLED] = 0.0  # no solution found by Newton here: back to the sweeps
        memo[MEMO_STAGE_NEWTON_FAILS] += 1.0
    sweeps = 0
    converged = False
    if top == 0:
        # no sweep: G stays expanded at buf.Gx, psi is its value at x0
        converged = _kept(changes, buf.defects, factor, stale, top, D) <= bound
        _psi_at(b, h, space, buf, D)
        alpha_at_psi(x0, tapes, space, buf, jacobian)
        return Failure.OK, sweeps, converged
    while top > 0:
        sweeps += 1
        # the measure of the degrees swept now at their last sweep (inf: none yet in this step)
        previous = memo[MEMO_EFFECT]
        if previous < np.inf:
            previous = 0.0
            for k in range(top):
                previous += factor * changes[k]
        for k in range(top):
            changes[k] = 0.0
        for i in range(s):
            _stage(i, x0, A, h, top, s, tapes, space, buf, memo[MEMO_RATE])
        swept = 0.0
        for k in range(top):
            swept += factor * changes[k]
        if learn:
            _learn(G, buf.defect, buf.weights, memo[MEMO_RATE], D, space, buf.defects)
            memo[MEMO_SWEEPS] = 1.0
        else:
            memo[MEMO_SWEEPS] += 1.0
        kept = _kept(changes, buf.defects, factor, stale, top, D)
        effect = swept + kept
        tail = _tail_factor(swept, previous)
        if settle:
            tail = max(1.0, tail)
        memo[MEMO_EFFECT] = effect
        # a sweep that did not contract proves nothing, unless its changes are already far below
        # the tolerance (round-off: the measure then no longer decreases)
        converged = swept * tail + kept <= bound or effect <= ROUND_OFF_SHARE * bound
        if converged:
            break
        # the sweeps stall: not finite, stage.max_sweeps of them while settling, or half as many
        # in one step without converging; Newton on the stage equations instead (`_stage_newton`).
        # (A sweep larger than the previous one is no stall by itself: after a Taylor shift it
        # also measures what the shift moved.)
        stalled = not np.isfinite(effect) or (
            sweeps >= stage.max_sweeps if settle else memo[MEMO_SWEEPS] >= stage.max_sweeps // 2)
        if stalled:
            # at most STAGE_NEWTON_FAILS_PER_STEP solves that find nothing in one step
            if settle or memo[MEMO_STAGE_NEWTON_FAILS] < STAGE_NEWTON_FAILS_PER_STEP:
                if _stage_newton(x0, A, h, D, tapes, space, buf):
                    memo[MEMO_STALLED] = 1.0
                    converged = True
                    break
                memo[MEMO_STAGE_NEWTON_FAILS] += 1.0
            if settle or not np.isfinite(effect):
                return Failure.STAGES_NO_CONVERGENCE, sweeps, False
            # no solution found by Newton here: the sweeps go on from where they were
        if not settle:
            break
    psi_alpha(x0, b, h, tapes, space, buf, jacobian)
    return Failure.OK, sweeps, converged
