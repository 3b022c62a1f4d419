"""The explicit RKHP step as a compiled "Taylor tower" (paper §5.2, docs/theory.md §5 and §7).

At the Newton iterate x0, each stage function g_i(x) = f(x, Z_i(x)), f = H o alpha, is held as its
Taylor polynomial in dx = x - x0, truncated at degree s + 2 - i (1-based i); g_1 = H;
Z_i = h sum_{j<i} a_ij grad g_j is read off the coefficients. psi = h sum_i b_i grad g_i and its
Jacobian are the degree-0 and degree-1 coefficients. Newton solves alpha(x, psi(x)) = y (Jacobian
by the same jets) from a predicted start, then chord steps with value-only towers, stopping when
the predicted next correction is below the tolerance (then psi + Dpsi dx is reused at the new x,
docs/theory.md §7); a last cheap correction of x at fixed p makes alpha(x, p) = y hold to round-off (so
the Casimirs are kept); y_next = beta(x, p). Each stage is computed once: the cost is
polynomial in s (see `rkhp_step`).

The tableau, h and the states are data: one compilation serves every system and tableau.
Failure codes: 0 ok, 1 Newton did not converge, 2 non-finite values, 3 left the domain,
4 Newton reached non-finite values.
"""

from __future__ import annotations

import numpy as np

from .cache import numba as nb
from .jets import NJIT, NJIT_NORC, run_tape_into

OK, NO_CONVERGENCE, NON_FINITE, LEFT_DOMAIN, NEWTON_NON_FINITE = 0, 1, 2, 3, 4


@nb.njit(**NJIT_NORC)
def solve_small(J, r, out, M, v):
    """out = J^{-1} r by Gaussian elimination with partial pivoting (J, r copied into the work
    arrays M (n x n) and v (n): no allocation in the step loop)."""
    n = r.shape[0]
    for i in range(n):
        v[i] = r[i]
        for j in range(n):
            M[i, j] = J[i, j]
    for c in range(n):
        piv = c
        for i in range(c + 1, n):
            if abs(M[i, c]) > abs(M[piv, c]):
                piv = i
        if piv != c:
            for j in range(n):
                M[c, j], M[piv, j] = M[piv, j], M[c, j]
            v[c], v[piv] = v[piv], v[c]
        for i in range(c + 1, n):
            f = M[i, c] / M[c, c]
            for j in range(c, n):
                M[i, j] -= f * M[c, j]
            v[i] -= f * v[c]
    for i in range(n - 1, -1, -1):
        acc = v[i]
        for j in range(i + 1, n):
            acc -= M[i, j] * out[j]
        out[i] = acc / M[i, i]


@nb.njit(**NJIT_NORC)
def _set_x(W, x0, n, D, M):
    """Input rows 0..n-1: the jets x0_k + dx_k (degree <= D, M coefficients)."""
    for k in range(n):
        for m in range(M):
            W[k, m] = 0.0
        W[k, 0] = x0[k]
        if D >= 1:
            W[k, 1 + k] = 1.0


@nb.njit(**NJIT_NORC)
def tower(x0, A, b, h, tapes, space, W, G, scratch, deg, psi, Jpsi, alpha, Jalpha, jacobian):
    """psi and alpha(x0, psi(x0)) at x0 (see module); with `jacobian`, also Dpsi and the
    Jacobian of x -> alpha(x, psi(x)) (stage degrees s + 2 - i; without, s + 1 - i)."""
    ftape, htape, atape = tapes[0], tapes[1], tapes[2]
    counts, up, expo = space[0], space[5], space[6]
    s = b.shape[0]
    n = x0.shape[0]
    extra = np.int64(1) if jacobian else np.int64(0)
    for i in range(s):
        D = s + extra - i
        M = counts[D]
        _set_x(W, x0, n, D, M)
        zero_row = True
        for j in range(i):
            if A[i, j] != 0.0:
                zero_row = False
        for k in range(n):
            for m in range(M):
                W[n + k, m] = 0.0
            for j in range(i):
                c = h * A[i, j]
                if c != 0.0:
                    for m in range(M):
                        W[n + k, m] += c * G[j, k, m]
        tape = htape if zero_row else ftape
        run_tape_into(tape, W, D, space, scratch, deg)
        g = tape[3][0]
        for k in range(n):
            for m in range(counts[D - 1]):
                G[i, k, m] = (expo[m, k] + 1) * W[g, up[m, k]]
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
    run_tape_into(atape, W, extra, space, scratch, deg)
    for k in range(n):
        a = atape[3][k]
        alpha[k] = W[a, 0]
        if jacobian:
            for l in range(n):
                Jalpha[k, l] = W[a, 1 + l]


@nb.njit(**NJIT_NORC)
def _max_abs(v):
    r = 0.0
    for q in range(v.shape[0]):
        a = abs(v[q])
        if not a <= r:  # also catches NaN
            r = a
    return r


@nb.njit(**NJIT_NORC)
def rkhp_step(y, A, b, h, tapes, space, buf, tol, max_iter, y_next, hist, memo):
    """One RKHP step from y into y_next; returns (failure code, Newton iterations).

    hist[0..2]: psi of the three previous steps, memo[0]: how many of them there are,
    memo[1]: Newton's quadratic constant L (|dx_{k+1}| ~ L |dx_k|^2) measured on an earlier step
    (0 when unknown). The start is predicted: psi extrapolated (quadratically) from the previous
    steps, x from alpha(x, psi_predicted) = y by a cheap Newton step (no tower). The first tower has the
    Jacobian; it is the last when max(2 L, 1/max(1, |y|)) |dx|^2 is below the tolerance. Later
    iterations are chord steps with value-only towers (one degree less, about half the cost),
    stopped when theta/(1 - theta) |dx_k| is (theta = |dx_k|/|dx_{k-1}|); the Jacobian is
    refreshed when theta > 1/4 (docs/theory.md §7 measured 2 full towers per step instead of 3).
    """
    W, G, scratch, deg, psi, Jpsi, alpha, Jalpha, x, delta, res, LU, v = buf
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
        _polish(y, x, res, tapes[2], space, W, scratch, deg, Jalpha, alpha, delta, LU, v, scale,
                np.int64(1), np.bool_(True))
        if not np.isfinite(_max_abs(x)):
            for k in range(n):
                x[k] = y[k]
    previous = np.inf
    converged = False
    full = np.bool_(True)
    it = 0
    while it < max_iter:
        it += 1
        # a full tower (Jacobian) first; then value-only towers with that Jacobian (chord)
        tower(x, A, b, h, tapes, space, W, G, scratch, deg, psi, Jpsi, alpha, Jalpha, full)
        for k in range(n):
            res[k] = y[k] - alpha[k]
        solve_small(Jalpha, res, delta, LU, v)
        size = _max_abs(delta)
        if not np.isfinite(size):
            return NEWTON_NON_FINITE, it
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
        if size <= tol * scale or predicted <= tol * scale:
            converged = True
            for k in range(n):
                acc = psi[k]
                for l in range(n):
                    acc += Jpsi[k, l] * delta[l]
                res[k] = acc
            break
        if size > 1e8 * scale:
            break
        # refresh the Jacobian when the chord iteration converges slowly
        full = np.bool_(previous < np.inf and size > 0.25 * previous)
        previous = size
    if not converged:
        return NO_CONVERGENCE, it
    _polish(y, x, res, tapes[2], space, W, scratch, deg, Jalpha, alpha, delta, LU, v, scale,
            np.int64(1), np.bool_(False))
    for k in range(n):
        hist[2, k] = hist[1, k]
        hist[1, k] = hist[0, k]
        hist[0, k] = res[k]
    memo[0] = min(memo[0] + 1.0, 3.0)
    btape = tapes[3]
    for k in range(n):
        W[k, 0] = x[k]
        W[n + k, 0] = res[k]
    run_tape_into(btape, W, np.int64(0), space, scratch, deg)
    for k in range(n):
        y_next[k] = W[btape[3][k], 0]
    if not np.isfinite(_max_abs(y_next)):
        return NON_FINITE, it
    return OK, it


@nb.njit(**NJIT_NORC)
def _polish(y, x, p, atape, space, W, scratch, deg, J, alpha, delta, LU, v, scale, iterations,
            exact):
    """Solve alpha(x, p) = y for x with p fixed by at most `iterations` cheap steps (no tower):
    with `exact`, Newton steps (J := d_x alpha(x, p) by degree-1 jets); otherwise steps with the
    given approximate J (the last tower's), from values of alpha only.

    With p fixed, C(beta(x, p)) = C(alpha(x, p)) for every Casimir C, so the final such step keeps
    the Casimirs to round-off whatever the accuracy of psi (docs/theory.md §4): only alpha's residual
    matters. Its correction is below the Newton tolerance, so J's O(h) inexactness is harmless.
    """
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
        run_tape_into(atape, W, degree, space, scratch, deg)
        for k in range(n):
            a = atape[3][k]
            alpha[k] = y[k] - W[a, 0]
            if exact:
                for l in range(n):
                    J[k, l] = W[a, 1 + l]
        solve_small(J, alpha, delta, LU, v)
        for k in range(n):
            x[k] += delta[k]
        if not _max_abs(delta) > 4e-16 * scale:
            break


@nb.njit(**NJIT)
def make_buffers(n, s, n_slots, space):
    size = space[0][space[0].shape[0] - 1]
    return (np.zeros((n_slots, size)), np.zeros((s, n, size)),
            np.zeros((5 + 2 * n, size)), np.zeros(n_slots, dtype=np.int64), np.zeros(n),
            np.zeros((n, n)), np.zeros(n), np.zeros((n, n)), np.zeros(n), np.zeros(n),
            np.zeros(n), np.zeros((n, n)), np.zeros(n))


@nb.njit(**NJIT)
def in_domain(y, domain):
    if domain == 1:
        for k in range(y.shape[0]):
            if not y[k] > 0.0:
                return False
    return True


@nb.njit(**NJIT)
def rkhp_run(y0, A, b, h, n_steps, tapes, space, n_slots, domain, tol, max_iter, states,
             iterations, keep_all):
    """Integrate n_steps; states[k] = y_k (keep_all) or states[0] = the last state.

    Returns (number of completed steps, failure code of the step after them or 0).
    """
    n = y0.shape[0]
    buf = make_buffers(n, b.shape[0], n_slots, space)
    hist = np.zeros((3, n))
    memo = np.zeros(2)
    y = y0.copy()
    y_next = np.zeros(n)
    states[0, :] = y
    for step in range(n_steps):
        code, it = rkhp_step(y, A, b, h, tapes, space, buf, tol, max_iter, y_next, hist, memo)
        iterations[step] = it
        if code == OK and not in_domain(y_next, domain):
            code = LEFT_DOMAIN
        if code != OK:
            return step, code
        for k in range(n):
            y[k] = y_next[k]
        states[step + 1 if keep_all else 0, :] = y
    return n_steps, OK
