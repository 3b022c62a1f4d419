"""Kernels of the composite operations (kind COMPOSITE in `rkhp.taylor.ops`).

A kernel has the signature ``kernel(tape, r, W, D, space, S, deg)``: it reads its row
``tape.ops[r]`` = (code, out, a, b, k), its operand list ``tape.args[a : a + b]`` (references of
its sub-programs first, then operand slots; numbers were recorded as constant slots, read as
W[slot, 0]), writes its results to the slots out, out + 1, ... with their degree bounds in deg,
and uses the scratch rows from SCRATCH_BASE on (as many as its `Op.scratch(k)` declares; rows
below are the elementary rows' and may be overwritten by a sub-program evaluation).

A kernel evaluates a sub-program by setting its input slots (jets of degree D, and their deg
bounds) and calling `rkhp.taylor.rows.run_rows(tape, lo, hi, ...)` on its row range, then reading
its output slots; it may do so as often as it needs (a fixed-point iteration, several collocation
nodes). Registering one: a code and an `rkhp.taylor.ops.OPS` row (kind COMPOSITE, its scratch
need), the kernel here, and its entry in `rkhp.taylor.interpreter.COMPOSITE_KERNELS` (the one
dispatch, `rkhp.taylor.interpreter._dispatch`, reads it; docs/engine.md "Composite operations").
"""

from __future__ import annotations

import math
from typing import NamedTuple

import numpy as np

from .collocation import TABLE_A, TABLE_B, TABLE_E, TABLE_P, TABLE_W
from .compiler import NJIT_NORC, NJIT_NRT
from .compiler import numba as nb
from .elementary import PHI_COEF, TWO_PI
from .jets import jet_mul
from .linalg import lu_factor, lu_solve
from .ops import SCRATCH_BASE, SPRAY_MAX_NODES
from .rows import run_rows, subprogram_at
from .tape import Tape


@nb.njit(**NJIT_NORC)
def phimv(tape, r, W, D, space, S, deg):
    """phi(K) x by its power series sum_k PHI_COEF[k] K^k x, for ||K0||_F < 0.9 * 2 pi (NaN
    beyond); operands: K (k x k, row-major), then x (k); results: the k components.

    Scratch rows from SCRATCH_BASE: v = K^k x (n rows), K v (n rows), one product."""
    out, start, n = tape.ops[r, 1], tape.ops[r, 2], tape.ops[r, 4]
    args = tape.args
    M = space.counts[D]
    for i in range(n):
        deg[out + i] = D
    norm = 0.0
    for i in range(n * n):
        norm += W[args[start + i], 0] ** 2
    norm = math.sqrt(norm)
    ratio = norm / TWO_PI
    if not (ratio < 0.9):
        for i in range(n):
            for m in range(M):
                W[out + i, m] = np.nan
        return
    # K^k x has degree-m coefficients of size ~ binom(k, m) |K0|^(k-m): keep every k <= D, then
    # stop when the tail bound is below round-off
    terms = max(D, 1)
    while terms < PHI_COEF.shape[0] - 1:
        if 2.0 * (terms + 1.0) ** D * ratio ** (terms + 1 - D) < 1e-18:
            break
        terms += 1
    v = SCRATCH_BASE
    kv = SCRATCH_BASE + n
    acc = SCRATCH_BASE + 2 * n
    for i in range(n):
        xi = args[start + n * n + i]
        for m in range(M):
            S[v + i, m] = W[xi, m]
            W[out + i, m] = W[xi, m]
    for k in range(1, terms + 1):
        for i in range(n):
            for m in range(M):
                S[kv + i, m] = 0.0
            for j in range(n):
                jet_mul(W, args[start + i * n + j], S, v + j, S, acc, D, space)
                for m in range(M):
                    S[kv + i, m] += S[acc, m]
        c = PHI_COEF[k]
        for i in range(n):
            for m in range(M):
                S[v + i, m] = S[kv + i, m]
                W[out + i, m] += c * S[v + i, m]


#: Q nodes are used when the alpha of Q - 1 nodes agrees with theirs to this, relative to
#: max(1, |x|) (a few units of round-off: the solves themselves are accurate to about that)
SPRAY_AGREEMENT = 8.0 * 2.0**-52
#: X affine in y: the Bernoulli series of the spray (`_bernoulli_spray`) stops when the bound of
#: its tail is at most SPRAY_SERIES_BOUND max(1, |x|) (docs/theory.md §9.3, "X affine in y")
SPRAY_SERIES_BOUND = 2.0**-53
#: ... and is used when theta / (2 pi) <= SPRAY_SERIES_RATIO (theta >= |d_y X|_2; about 55 terms
#: at most); beyond, the collocation solve takes over
SPRAY_SERIES_RATIO = 0.5
#: |B_k / k!| <= SPRAY_BERNOULLI_MAJORANT (2 pi)^-k for k >= 2 (2 zeta(2) = pi^2 / 3 = 3.29; B_1
#: is summed exactly)
SPRAY_BERNOULLI_MAJORANT = 3.3
#: value-level Newton sweeps at most; one that does not reach the round-off level by then, or
#: that stops contracting above it, gives NaN results (a numerical failure, never a wrong value)
SPRAY_MAX_SWEEPS = 50
#: (A - w)_ij for q nodes at [q, :q, :q] (`rkhp.taylor.collocation`): the stage equations'
#: matrix
TABLE_AW = TABLE_A - TABLE_W[:, None, :]


class SprayOp(NamedTuple):
    """A spray row as its helpers read it (`spray`): the tape; its sub-program X(y, p) as
    sub = (lo, hi, in0, out0) (`rkhp.taylor.rows.subprogram_at`); where its x and p operand
    slots are listed in tape.args (x_slots, p_slots); the dimension n; its scratch rows: the
    stage values from Ys, their X from Xs."""

    tape: Tape
    sub: tuple
    x_slots: int
    p_slots: int
    n: int
    Ys: int
    Xs: int


class ValueStart(NamedTuple):
    """Where `_value_stages` starts: J = d_y X and X0 = X at y = x (the operand's values), theta
    an estimate of |J|_2, scale = max(1, |x|)."""

    J: np.ndarray
    X0: np.ndarray
    theta: float
    scale: float


class StageNewton(NamedTuple):
    """The Newton matrix of the stage values' solve for q nodes and its work arrays: Js (q, n, n)
    its Jacobians, LU (qn, qn) and perm (qn,) its factors and row order, rvec and tmp (at least
    qn) the linear solves' vectors, base (n) where `_jacobian` writes X."""

    Js: np.ndarray
    LU: np.ndarray
    perm: np.ndarray
    rvec: np.ndarray
    tmp: np.ndarray
    base: np.ndarray


@nb.njit(inline="always", **NJIT_NORC)
def _spray_field(op, W, D, space, S, deg, y_row):
    """X = pi(y) p by the sub-program at degree D: y from the scratch rows S[y_row + k] (with
    y_row < 0: already in the sub-program's input slots, degree 0), p from the slots listed at
    args[op.p_slots:]."""
    lo, hi, in0 = op.sub[0], op.sub[1], op.sub[2]
    tape, p_slots, n = op.tape, op.p_slots, op.n
    args = tape.args
    M = space.counts[D]
    for k in range(n):
        yk = args[in0 + k]
        if y_row >= 0:
            for m in range(M):
                W[yk, m] = S[y_row + k, m]
        deg[yk] = D
        pk = args[in0 + n + k]
        ps = args[p_slots + k]
        for m in range(M):
            W[pk, m] = W[ps, m]
        deg[pk] = min(D, deg[ps])
    run_rows(tape, lo, hi, W, D, space, S, deg)


@nb.njit(inline="always", **NJIT_NORC)
def spray(tape, r, W, D, space, S, deg):
    """alpha and beta of the Poisson-spray realisation (docs/theory.md §9.3) at degree D.

    Operands: the sub-program X(y, p) = pi(y) p (inputs y then p, outputs X), then x (k slots),
    then p (k slots); results alpha (k slots), then beta (k slots).

    X affine in y (the tape's flag, `rkhp.taylor.tape.degree_in`): by the Bernoulli series
    (`_bernoulli_spray`) where it converges fast. Otherwise Q-node Gauss collocation of
    y' = X(y) on [0, 1] with the average constraint: the stage values
    solve Y_i = x + sum_j (A_ij - w_j) X(Y_j), then alpha = x - sum_j w_j X(Y_j) and
    beta = x + sum_j (b_j - w_j) X(Y_j) (`rkhp.taylor.collocation`; `_spray_stages` solves for
    the stage values). NaN results when the stages cannot be solved (no Q <= SPRAY_MAX_NODES is
    accurate enough, or the iteration does not converge): a numerical failure, never a wrong value.

    Scratch rows from SCRATCH_BASE: the stage values Y (SPRAY_MAX_NODES * k rows), then their
    X (as many). Inlined into the interpreter (its one call site, `rkhp.taylor.interpreter`).
    """
    ops, args = tape.ops, tape.args
    out, start, n = ops[r, 1], ops[r, 2], ops[r, 4]
    lo, hi, in0, n_in, out0, n_out, pos = subprogram_at(args, start)
    x_slots = pos
    Xs = SCRATCH_BASE + SPRAY_MAX_NODES * n
    op = SprayOp(tape, (lo, hi, in0, out0), pos, pos + n, n, np.int64(SCRATCH_BASE), Xs)
    M = space.counts[D]
    if tape.fpar[r] == 1.0 and _bernoulli_spray(op, W, D, space, S, deg, out):
        return
    q = _spray_stages(op, W, D, space, S, deg)
    for k in range(n):
        xs = args[x_slots + k]
        for m in range(M):
            a = W[xs, m]
            b = W[xs, m]
            if q > 0:
                for j in range(q):
                    v = S[Xs + j * n + k, m]
                    a -= TABLE_W[q, j] * v
                    b += (TABLE_B[q, j] - TABLE_W[q, j]) * v
            else:
                a = np.nan
                b = np.nan
            W[out + k, m] = a
            W[out + n + k, m] = b
        deg[out + k] = D
        deg[out + n + k] = D


@nb.njit(**NJIT_NRT)
def _bernoulli_spray(op, W, D, space, S, deg, out):
    """alpha and beta of `spray` for X affine in y, X(y) = c + L y (c = X(0), L = d_y X: jets in
    p), by the Bernoulli series (docs/theory.md §9.3, "X affine in y"):
    alpha = x - v_1 / 2 + E, beta = x + v_1 / 2 + E, E = sum_{k even >= 2} B_k / k! v_k, with
    v_1 = X(x) and v_{k+1} = L v_k = X(v_k) - c: one evaluation of X per term, at degree D.

    The sum stops at the first k whose tail bound SPRAY_BERNOULLI_MAJORANT (2 pi)^-k |v_k|
    rho / (1 - rho) is at most SPRAY_SERIES_BOUND max(1, |x|), |v_k| <= sqrt(n) times its
    largest coefficient. At the values rho = theta / (2 pi), theta = `_norm_bound` of d_y X(x)
    >= |L|_2: a bound. On jets (D >= 1) also k >= D + 2 and rho >= |v_k| / |v_{k-1}| / (2 pi)
    (the degree-d coefficients of v_k grow like binom(k, d) theta^(k - d) until k > d, then
    shrink by ratios that decrease towards theta). Writes the results (slots out..) and returns
    True; False, nothing written, when theta > SPRAY_SERIES_RATIO 2 pi or the series does not
    meet the bound within PHI_COEF's terms. Scratch rows from op.Ys: v_k, c, E, v_1 (n each)."""
    args, x_slots, n = op.tape.args, op.x_slots, op.n
    out0 = op.sub[3]
    M = space.counts[D]
    rows = op.Ys
    V, C, E, V1 = rows, rows + n, rows + 2 * n, rows + 3 * n
    J = np.empty((n, n))
    X0 = np.empty(n)
    scale = 1.0
    for k in range(n):
        S[V + k, 0] = W[args[x_slots + k], 0]
        scale = max(scale, abs(S[V + k, 0]))
    _jacobian(op, W, space, S, deg, np.int64(V), J, X0, True)
    ratio = _norm_bound(J) / TWO_PI
    if not ratio <= SPRAY_SERIES_RATIO:
        return False
    tol = SPRAY_SERIES_BOUND * scale / (SPRAY_BERNOULLI_MAJORANT * math.sqrt(n))
    # X evaluated at y = 0 (k = 0: c), at x (k = 1: v_1), then at v_{k-1} (k >= 2: v_k + c)
    for i in range(n):
        for m in range(M):
            S[V + i, m] = 0.0
    power = TWO_PI  # (2 pi)^-k once divided in the loop
    previous = 0.0
    done = False
    for k in range(PHI_COEF.shape[0]):
        _spray_field(op, W, D, space, S, deg, np.int64(V))
        power /= TWO_PI
        b = PHI_COEF[k]  # B_k / k! for even k, 0 for odd k >= 3
        norm = 0.0
        for i in range(n):
            o, xs = args[out0 + i], args[x_slots + i]
            for m in range(M):
                if k == 0:
                    S[C + i, m] = W[o, m]
                    S[V + i, m] = W[xs, m]
                    continue
                v = W[o, m] if k == 1 else W[o, m] - S[C + i, m]
                S[V + i, m] = v
                if k == 1:
                    S[V1 + i, m] = v
                    S[E + i, m] = 0.0
                else:
                    S[E + i, m] += b * v
                if not abs(v) <= norm:  # also catches NaN
                    norm = abs(v)
        if not norm < np.inf:
            return False
        if k >= 2 and norm == 0.0:
            done = True
            break
        if k < 2 or (D >= 1 and k < D + 2):
            previous = norm
            continue
        rho = ratio if D == 0 else max(ratio, norm / previous / TWO_PI)
        if rho < 1.0 and power * norm * rho / (1.0 - rho) <= tol:
            done = True
            break
        previous = norm
    if not done:
        return False
    for k in range(n):
        xs = args[x_slots + k]
        for m in range(M):
            half = 0.5 * S[V1 + k, m]
            W[out + k, m] = W[xs, m] - half + S[E + k, m]
            W[out + n + k, m] = W[xs, m] + half + S[E + k, m]
        deg[out + k] = D
        deg[out + n + k] = D
    return True


@nb.njit(inline="always", **NJIT_NORC)
def _jacobian(op, W, space, S, deg, y_row, J, base, affine):
    """J := d_y X(y, p) and base := X(y, p) at the values y = S[y_row + k, 0] and p's values:
    by forward mode (one evaluation at degree 1) when the jet space has n variables, else by
    finite differences (for X affine in y, `affine`, with steps max(1, |y_k|): exact but for
    round-off)."""
    tape, sub, p_slots, n = op.tape, op.sub, op.p_slots, op.n
    args = tape.args
    in0, out0 = sub[2], sub[3]
    if space.n_vars >= n and space.degree >= 1:
        M1 = space.counts[1]
        for k in range(n):
            yk = args[in0 + k]
            pk = args[in0 + n + k]
            for m in range(M1):
                W[yk, m] = 0.0
                W[pk, m] = 0.0
            W[yk, 0] = S[y_row + k, 0]
            W[yk, 1 + k] = 1.0
            W[pk, 0] = W[args[p_slots + k], 0]
            deg[yk] = 1
            deg[pk] = 0
        run_rows(tape, sub[0], sub[1], W, np.int64(1), space, S, deg)
        for i in range(n):
            base[i] = W[args[out0 + i], 0]
            for k in range(n):
                J[i, k] = W[args[out0 + i], 1 + k]
        return
    # finite differences: X at y (k = -1), then at y + step e_k
    zero = np.int64(0)
    step = 0.0
    for k in range(-1, n):
        for j in range(n):
            W[args[in0 + j], 0] = S[y_row + j, 0]
        if k >= 0:
            step = (1.0 if affine else 1.4901161193847656e-08) * max(1.0, abs(S[y_row + k, 0]))
            W[args[in0 + k], 0] = S[y_row + k, 0] + step
        _spray_field(op, W, zero, space, S, deg, np.int64(-1))
        for i in range(n):
            if k < 0:
                base[i] = W[args[out0 + i], 0]
            else:
                J[i, k] = (W[args[out0 + i], 0] - base[i]) / step


@nb.njit(**NJIT_NRT)
def _spray_stages(op, W, D, space, S, deg):
    """The stage values of `spray` (rows op.Ys) and their X (rows op.Xs) up to degree D; returns Q,
    or 0 when they cannot be solved. Allocates the Jacobians and the Newton matrices.
    docs/theory.md §9.3, "Choice of Q" and "Solving for the stages".

    1. Q and the stages at the values, by Newton (`_value_stages`): Q0 is the smallest with
       E_Q0 theta^(2 Q0) <= 8 SPRAY_AGREEMENT, theta an estimate of |J|_2, J = d_y X(x),
       pessimistic so that the first check usually passes; Q is the first Q > Q0 whose alpha
       agrees with that of Q - 1 nodes to SPRAY_AGREEMENT max(1, |x|) (the truncation error of
       Q nodes is then smaller by about theta^2 / (16 Q^2)): theta alone misses the
       non-linearity of X (where J is small but d^2 X is not).
    2. Degrees 1..D, one at a time (D >= 1): with the exact value-level matrix
       N = I - [(A - w)_ij J(Y_j)] (J at each stage value), the degree-d coefficients solve one
       linear system once the lower ones are known: evaluate X on the stages at degree d, solve
       N dY_d = (x + (A - w) X(Y) - Y)_d, and correct X's degree-d coefficients by J(Y_j) dY_d
       (exact at degree d). One evaluation per stage and degree, at that degree (two with
       finite-difference Jacobians).
    """
    args, x_slots, n, Ys, Xs = op.tape.args, op.x_slots, op.n, op.Ys, op.Xs
    out0 = op.sub[3]
    counts = space.counts
    work = np.empty(n)
    J = np.empty((n, n))
    X0 = np.empty(n)
    # the linear solves' work vectors, long enough for every number of nodes
    rvec = np.empty(SPRAY_MAX_NODES * n)
    tmp = np.empty(SPRAY_MAX_NODES * n)
    for k in range(n):
        S[Ys + k, 0] = W[args[x_slots + k], 0]
    _jacobian(op, W, space, S, deg, np.int64(Ys), J, X0, False)
    scale = 1.0
    for k in range(n):
        scale = max(scale, abs(W[args[x_slots + k], 0]))
    alpha = np.empty(n)
    theta = _spectral_norm(J, rvec, tmp)
    q = 1
    while q < SPRAY_MAX_NODES - 1 and not (TABLE_E[q] * theta ** (2 * q)
                                           <= 8.0 * SPRAY_AGREEMENT):
        q += 1
    # Q0 nodes, then Q0 + 1, ... warm-started from the previous solve, until two agree; the
    # Newton matrix of the last value-level solve (its Jacobians, factors, row order)
    previous = np.empty(n)
    warm = False
    while True:
        if q > SPRAY_MAX_NODES:
            return 0
        newton = StageNewton(np.empty((q, n, n)), np.empty((q * n, q * n)),
                             np.empty(q * n, dtype=np.int64), rvec, tmp, work)
        if not _value_stages(op, W, space, S, deg, q, ValueStart(J, X0, theta, scale), alpha, warm,
                             newton):
            return 0
        if warm:
            gap = 0.0
            for k in range(n):
                gap = max(gap, abs(alpha[k] - previous[k]))
            if gap <= SPRAY_AGREEMENT * scale:
                break
        for k in range(n):  # a loop: numpy's slice assignment compiles its shape-error message
            previous[k] = alpha[k]
        warm = True
        q += 1
    if D == 0:
        return q
    # 2. degrees 1..D with the exact value-level matrix
    AW = TABLE_AW[q]
    # the last value-level matrix is the exact one when its Jacobians are the stages': then
    # its factors serve, else factorise
    Js = np.empty((q, n, n))
    for j in range(q):
        _jacobian(op, W, space, S, deg, np.int64(Ys + j * n), Js[j], work, False)
    if not _same_matrices(Js, newton.Js):
        if not _newton_matrix(AW, Js, q, n, newton.LU, newton.perm):
            return 0
    for i in range(q):
        for k in range(n):
            xs = args[x_slots + k]
            for m in range(1, counts[D]):
                S[Ys + i * n + k, m] = W[xs, m]
    # with finite-difference Jacobians (a jet space of fewer than n variables) each degree
    # takes a second pass, which removes their O(1e-8) error
    passes = 1 if space.n_vars >= n else 2
    for step in range(passes * D):
        d = 1 + step // passes
        for j in range(q):
            _spray_field(op, W, np.int64(d), space, S, deg, np.int64(Ys + j * n))
            for k in range(n):
                o = args[out0 + k]
                for m in range(counts[d]):
                    S[Xs + j * n + k, m] = W[o, m]
        for m in range(counts[d - 1], counts[d]):
            _newton_step(op, W, S, AW, q, np.int64(m), newton)
            for j in range(q):
                for i in range(n):
                    acc = 0.0
                    for k in range(n):
                        acc += Js[j, i, k] * rvec[j * n + k]
                    S[Xs + j * n + i, m] += acc
    return q


@nb.njit(inline="always", **NJIT_NORC)
def _same_matrices(A, B):
    """Whether two stacks of matrices are equal entry by entry (as np.array_equal: NaN differs
    from itself), without numpy's comparison of arrays, which compiles its shape-error message
    (seconds of a cold start)."""
    if A.shape != B.shape:
        return False
    for j in range(A.shape[0]):
        for i in range(A.shape[1]):
            for k in range(A.shape[2]):
                if not A[j, i, k] == B[j, i, k]:
                    return False
    return True


@nb.njit(**NJIT_NORC)
def _value_stages(op, W, space, S, deg, q, start, alpha, warm, newton):
    """The stage values with q nodes at the values (rows Ys, column 0; their X in Xs) by Newton
    with the matrix I - (A - w) (x) J (J at the stage values when the first corrections contract
    slowly: far from x it matters) until the update is at the round-off level; alpha := the
    resulting alpha's values. The start is the spray series to degree 2 at the nodes,
    Y(s) = x + (s - 1/2) X(x) + (s^2/2 - s/2 + 1/12) J X(x) (docs/theory.md §9.1), or with
    `warm` the (q - 1)-node solution's collocation polynomial at the q nodes (its X in the rows
    Xs). alpha comes from X at the last stage values but one, so the last update need only be
    below 4 eps max(1, |x|) / theta (alpha moves by about theta |dY| / 2). False if it does not
    converge (or q nodes exceed SPRAY_MAX_NODES). start: J, X0, theta and scale at x
    (`ValueStart`); newton: the Newton matrix and its work arrays (`StageNewton`), its Jacobians,
    factors and row order left as last used."""
    if q > SPRAY_MAX_NODES:
        return False
    args, x_slots, n, Ys, Xs = op.tape.args, op.x_slots, op.n, op.Ys, op.Xs
    J, X0, theta, scale = start.J, start.X0, start.theta, start.scale
    Js, LU, perm = newton.Js, newton.LU, newton.perm
    out0 = op.sub[3]
    zero = np.int64(0)
    AW = TABLE_AW[q]
    for j in range(q):  # J frozen at every node
        for i in range(n):
            for k in range(n):
                Js[j, i, k] = J[i, k]
    if not _newton_matrix(AW, Js, q, n, LU, perm):
        return False
    eps = 2.220446049250313e-16
    tol = min(4.0 * eps * scale / max(theta, 1e-3), 1e-13 * scale)
    for i in range(q):
        c = 0.0
        for j in range(q):
            c += TABLE_A[q, i, j]
        for k in range(n):
            acc = W[args[x_slots + k], 0]
            if warm:
                for j in range(q - 1):
                    acc += (TABLE_P[q - 1, i, j] - TABLE_W[q - 1, j]) * S[Xs + j * n + k, 0]
            else:
                jx = 0.0
                for l in range(n):
                    jx += J[k, l] * X0[l]
                acc += (c - 0.5) * X0[k] + (0.5 * c * c - 0.5 * c + 1.0 / 12.0) * jx
            S[Ys + i * n + k, 0] = acc
    previous = np.inf
    for sweep in range(SPRAY_MAX_SWEEPS):
        for j in range(q):
            _spray_field(op, W, zero, space, S, deg, np.int64(Ys + j * n))
            for k in range(n):
                S[Xs + j * n + k, 0] = W[args[out0 + k], 0]
        update = _newton_step(op, W, S, AW, q, zero, newton)
        if not update < np.inf:
            return False
        converged = update <= tol
        # stagnation at the round-off level is convergence; above it, divergence
        if not converged and sweep >= 3 and update > 0.5 * previous:
            if not update <= 64.0 * 4.0 * eps * scale:
                return False
            converged = True
        if converged:
            for k in range(n):
                acc = W[args[x_slots + k], 0]
                for j in range(q):
                    acc -= TABLE_W[q, j] * S[Xs + j * n + k, 0]
                alpha[k] = acc
            return True
        if sweep == 1 and update > 0.05 * previous:
            for j in range(q):
                _jacobian(op, W, space, S, deg, np.int64(Ys + j * n), Js[j], newton.base, False)
            if not _newton_matrix(AW, Js, q, n, LU, perm):
                return False
        previous = update
    return False


@nb.njit(**NJIT_NORC)
def _newton_matrix(AW, Js, q, n, LU, perm):
    """LU := I - [(A - w)_ij J_j] (blocks i, j of size n), factorised; False if singular."""
    for i in range(q):
        for k in range(n):
            for j in range(q):
                for l in range(n):
                    LU[i * n + k, j * n + l] = (1.0 if (i == j and k == l) else 0.0) \
                        - AW[i, j] * Js[j, k, l]
    return lu_factor(LU, perm)


@nb.njit(inline="always", **NJIT_NORC)
def _newton_step(op, W, S, AW, q, m, newton):
    """One Newton correction of the stage values' coefficient m: rvec := N^-1 (x + (A - w) X
    - Y)_m (N factorised in newton.LU, newton.perm), added to the rows Ys; returns its largest
    magnitude (NaN-safe)."""
    args, x_slots, n, Ys, Xs = op.tape.args, op.x_slots, op.n, op.Ys, op.Xs
    rvec = newton.rvec
    for i in range(q):
        for k in range(n):
            acc = W[args[x_slots + k], m] - S[Ys + i * n + k, m]
            for j in range(q):
                acc += AW[i, j] * S[Xs + j * n + k, m]
            rvec[i * n + k] = acc
    lu_solve(newton.LU, newton.perm, rvec, newton.tmp)
    update = 0.0
    for a in range(q * n):
        S[Ys + a, m] += rvec[a]
        d = abs(rvec[a])
        if not d <= update:  # also catches NaN
            update = d
    return update


@nb.njit(**NJIT_NORC)
def _spectral_norm(J, v, u):
    """An estimate of the largest singular value of J (power iteration on J^T J from the
    all-ones vector, 8 steps, 5% added), inf for a non-finite J; v, u: work vectors (at least
    as long as J's side)."""
    n = J.shape[0]
    for i in range(n):
        for k in range(n):
            if not abs(J[i, k]) < np.inf:
                return np.inf
    for k in range(n):
        v[k] = 1.0 / math.sqrt(n)
    sigma = 0.0
    for _ in range(8):
        for i in range(n):
            acc = 0.0
            for k in range(n):
                acc += J[i, k] * v[k]
            u[i] = acc
        norm = 0.0
        for k in range(n):
            acc = 0.0
            for i in range(n):
                acc += J[i, k] * u[i]
            v[k] = acc
            norm += acc * acc
        norm = math.sqrt(norm)
        if norm == 0.0:
            return 0.0
        sigma = math.sqrt(norm)
        for k in range(n):
            v[k] /= norm
    return 1.05 * sigma


@nb.njit(**NJIT_NORC)
def _norm_bound(J):
    """A bound of |J|_2 (so |J^k|_2 <= bound^k): the smaller of |J|_F and
    (|J|_1 |J|_inf)^(1/2); inf or NaN if J is not finite."""
    frobenius = 0.0
    rows = 0.0
    for i in range(J.shape[0]):
        row = 0.0
        for k in range(J.shape[1]):
            frobenius += J[i, k] * J[i, k]
            row += abs(J[i, k])
        rows = max(rows, row)
    columns = 0.0
    for k in range(J.shape[1]):
        column = 0.0
        for i in range(J.shape[0]):
            column += abs(J[i, k])
        columns = max(columns, column)
    return min(math.sqrt(frobenius), math.sqrt(rows * columns))
