"""The RKHP step as a compiled "Taylor tower" (paper §5.2, docs/theory.md §5, §7 and §10).

At the Newton iterate x0 a tower gives psi(x0), alpha(x0, psi(x0)) and their Jacobians: the
explicit tower (`rkhp.integrators.tower`: each stage function a Taylor polynomial in dx = x - x0,
each stage computed once) or the implicit tower (`rkhp.integrators.implicit_tower`: the stage
polynomials solved by Picard sweeps warm-started from the previous iterate). Newton solves
alpha(x, psi(x)) = y (Jacobian by the same jets) from a predicted start, then chord steps with
value-only towers, stopping when the predicted next correction is below the tolerance (then
psi + Dpsi dx is reused at the new x, docs/theory.md §7); a last cheap correction of x at fixed
p makes alpha(x, p) = y hold to round-off (so the Casimirs are kept); y_next = beta(x, p). The
cost is polynomial in s (see `rkhp_step`).

The tableau, h and the states are data: one compilation serves every system and tableau. The
compiled data are small named groups (`rkhp.integrators.engine_state`, docs/engine.md "The state
of the step loop").
"""

from __future__ import annotations

import numpy as np

from ..taylor.compiler import NJIT_NORC
from ..taylor.compiler import numba as nb
from ..taylor.interpreter import run_from
from ..taylor.linalg import lu_factor, lu_solve, max_abs
from .engine_state import MEMO_FACTORED, MEMO_HISTORY, MEMO_NEWTON_L
from .failure import Failure
from .implicit_tower import implicit_tower
from .tower import tower


@nb.njit(inline="always", **NJIT_NORC)
def newton_solve(r, out, buf):
    """out = Jalpha^{-1} r, Jalpha = buf.Jalpha, by LU factorisation with partial pivoting
    (`rkhp.taylor.linalg.lu_factor`, `lu_solve`) in the work arrays buf.LU, buf.perm and buf.v:
    no allocation in the step loop. The factors are kept while Jalpha is (memo slot
    MEMO_FACTORED), so that the chord steps and the closing polish of `rkhp_step`, which reuse
    the last tower's Jalpha, factorise it once. A singular Jalpha gives out = NaN (a non-finite
    correction: NEWTON_NON_FINITE). Inlined: a compiled function of its own costs a unit of
    compile time (docs/engine.md "Compile time")."""
    J, LU, memo = buf.Jalpha, buf.LU, buf.memo
    n = r.shape[0]
    if memo[MEMO_FACTORED] == 0.0:
        for i in range(n):
            for j in range(n):
                LU[i, j] = J[i, j]
        memo[MEMO_FACTORED] = 1.0 if lu_factor(LU, buf.perm) else -1.0
    if memo[MEMO_FACTORED] > 0.0:
        for i in range(n):
            out[i] = r[i]
        lu_solve(LU, buf.perm, out, buf.v)
    else:
        for i in range(n):
            out[i] = np.nan


@nb.njit(inline="always", **NJIT_NORC)
def rkhp_step(method, tapes, space, buf, solver, stage):
    """One RKHP step from buf.y into buf.y_next; returns (Failure, Newton iterations, stage
    sweeps). `stage` says how the towers compute the stages: None, explicit (`tower`), or a
    StageSolve, implicit (`implicit_tower`: one sweep per tower, so the iterations go on after
    Newton's test holds until the stages have converged too, at most max_iter + stage.max_sweeps
    of them; STAGES_NO_CONVERGENCE when Newton's test held but the stages did not settle).

    buf.hist[0..2]: psi of the three previous steps, buf.memo[MEMO_HISTORY]: how many of them
    there are, buf.memo[MEMO_NEWTON_L]: Newton's quadratic constant L (|dx_{k+1}| ~ L |dx_k|^2)
    measured on an earlier step (0 when unknown). The start is predicted: psi extrapolated (quadratically) from the
    previous steps, x from alpha(x, psi_predicted) = y by a cheap Newton step (no tower). The first
    tower has the Jacobian; it is the last when max(2 L, 1/max(1, |y|)) |dx|^2 is below the
    tolerance. Later iterations are chord steps with value-only towers (one degree less, about
    half the cost), stopped when theta/(1 - theta) |dx_k| is (theta = |dx_k|/|dx_{k-1}|); the
    Jacobian is refreshed when theta > 1/4 (docs/theory.md §7 measured 2 full towers per step
    instead of 3).
    """
    A, b, h, tol, max_iter = method.A, method.b, method.h, solver.tol, solver.max_iter
    y, x, res, delta, hist, memo = buf.y, buf.x, buf.res, buf.delta, buf.hist, buf.memo
    n = y.shape[0]
    scale = max(1.0, max_abs(y))
    for k in range(n):
        x[k] = y[k]
    if memo[MEMO_HISTORY] >= 1.0:
        for k in range(n):
            if memo[MEMO_HISTORY] >= 3.0:
                res[k] = 3.0 * (hist[0, k] - hist[1, k]) + hist[2, k]
            elif memo[MEMO_HISTORY] >= 2.0:
                res[k] = 2.0 * hist[0, k] - hist[1, k]
            else:
                res[k] = hist[0, k]
        _polish(res, tapes, space, buf, scale, np.int64(1), np.bool_(True))
        if not np.isfinite(max_abs(x)):
            for k in range(n):
                x[k] = y[k]
    previous = np.inf
    converged = False
    full = np.bool_(True)
    it = 0
    # stage is None for an explicit tableau: numba prunes the implicit branches, so the loop of
    # explicit tableaux is compiled without them (`tower_substep.compiled_stage`)
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
                x, method, tapes, space, buf, full, stage, np.bool_(it == 1), tol * scale)
            sweeps += done
            if cause != Failure.OK:
                return cause, it, sweeps
        for k in range(n):
            res[k] = y[k] - buf.alpha[k]
        newton_solve(res, delta, buf)
        size = max_abs(delta)
        if not np.isfinite(size):
            return Failure.NEWTON_NON_FINITE, it, sweeps
        for k in range(n):
            x[k] += delta[k]
        if previous < np.inf and previous > 1e3 * tol * scale and size < 0.5 * previous:
            memo[MEMO_NEWTON_L] = size / (previous * previous)
        if previous < np.inf:
            # chord step: |dx_{k+1}| <~ theta |dx_k| with theta = |dx_k| / |dx_{k-1}|
            theta = size / previous
            predicted = theta / (1.0 - theta) * size if theta < 0.5 else np.inf
        else:
            # next correction ~ L |dx|^2; one measured L can be far too small (a correction
            # along a flat direction), hence the floor 1 / scale
            predicted = max(2.0 * memo[MEMO_NEWTON_L], 1.0 / scale) * size * size
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
    _polish(res, tapes, space, buf, scale, np.int64(1), np.bool_(False))
    for k in range(n):
        hist[2, k] = hist[1, k]
        hist[1, k] = hist[0, k]
        hist[0, k] = res[k]
    memo[MEMO_HISTORY] = min(memo[MEMO_HISTORY] + 1.0, 3.0)
    W = buf.work.W
    for k in range(n):
        W[k, 0] = x[k]
        W[n + k, 0] = res[k]
    run_from(tapes.run, tapes.beta_at, np.int64(0), tapes.space_at, tapes.work_at)
    for k in range(n):
        buf.y_next[k] = W[tapes.beta.outputs[k], 0]
    return Failure.OK, it, sweeps


@nb.njit(inline="always", **NJIT_NORC)
def _polish(p, tapes, space, buf, scale, iterations, exact):
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
        run_from(tapes.run, tapes.alpha_at, degree, tapes.space_at, tapes.work_at)
        for k in range(n):
            a = tapes.alpha.outputs[k]
            alpha[k] = y[k] - W[a, 0]
            if exact:
                for l in range(n):
                    J[k, l] = W[a, 1 + l]
        if exact:
            buf.memo[MEMO_FACTORED] = 0.0
        newton_solve(alpha, delta, buf)
        for k in range(n):
            x[k] += delta[k]
        if not max_abs(delta) > 4e-16 * scale:
            break
