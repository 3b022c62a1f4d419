"""The RKHP Euler step on the Poisson-spray realisation in its direct form, and compositions of it
(docs/theory.md §9, docs/general-poisson.md "The Euler step in direct form").

With the spray realisation, alpha(x, p) solves int_0^1 Phi_s^p(alpha) ds = x and
beta(x, p) = Phi_1^p(alpha), Phi_s^p the flow of the frozen field X_p(y) = pi(y) p. The RKHP Euler
step solves alpha(x, h grad H(x)) = y0 and returns beta(x, h grad H(x)); since alpha(x, p) = y0
means x = int_0^1 Phi_s^p(y0) ds, the step is

    y1 = Phi_1^p(y0),   p = h grad H(xbar(p)),   xbar(p) = int_0^1 Phi_s^p(y0) ds,

one small system in p whose every evaluation integrates one short flow from the known start y0
(|p| = O(h)): no solve for alpha, no jets: values and first derivatives of the tapes only
(`rkhp.taylor.scalar`), Hess H for the chord matrix by differences of the gradient. The flow and
its average are computed by Q-node Gauss collocation on [0, 1] (`rkhp.taylor.collocation`):
stage increments Z_j with Y_j = y0 + Z_j, Z_i = sum_j A_ij X_p(Y_j), then y1 = y0 + sum_j b_j X_p(Y_j) and
xbar = y0 + sum_j w_j X_p(Y_j) (w_j = b_j (1 - c_j): the average is the end value of the
augmented equation z' = y, exact for the collocation polynomial). The unknowns (Z, p), (Q + 1) n
numbers, solve first by fixed-point sweeps (`_sweeps`)

    X_j := X_p(y0 + Z_j),   Z := A X,   p := h grad H(y0 + sum_j w_j X_j),

which contract the error by O(h) a sweep (X_p = pi p is O(h): |A (x) d_y X_p| and
|h Hess H pi / 2| are O(h)), about as fast as the chord iterations below with a kept matrix at
the compositions' step sizes, without their linear solve; while a sweep contracts the changes
by at most the square root of the kept matrix's last contraction, from `PICARD_RATE` to
`SLOW_SWEEPS` (`rkhp.integrators.direct_form.sweep_verdict`; a substep without
previous solutions, whose start is off by O(h^2) in p, first takes one sweep that is not judged:
it carries the error of p into Z, and its change measures the start, not the contraction), else
by chord iterations with the frozen Jacobian

    [ I - A (x) J      -c (x) P         ]     J = d_y X_p(y0), P = pi(y0) = d_p X_p(y0),
    [ -h H w^T (x) J   I - (h/2) H P    ]     H = Hess H(y0), c_i = sum_j A_ij, sum_j w_j = 1/2,

which contracts the error by O(h^2) an iteration (by O(h) the first iteration of a step, when the
matrix was built at an earlier step: `SLOW_CONTRACTION`), inverted once (an iteration's correction is
then one product of the inverse with the residual, `rkhp.taylor.linalg.transposed_product`) and
kept across steps for each substep of a composition (refreshed when the iterations contract
slowly, when the number of nodes changes, and before iterating when the iterations a fresh matrix
would save pay for it, `_worth_rebuilding`: the contraction of a kept matrix grows from 1e-3 just
after its build to 0.02 to 0.2 as the state moves).
Where even a fresh matrix contracts slowly, and in any substep past half its iterations, the
matrix is the exact Jacobian at the current iterate (`_newton_matrix_p`: d_y X and pi at each
stage, Hess H at xbar; Newton's method), taken again at each iteration until the correction nears
the tolerance: the substeps near the largest steps the iterations converge at (|h| about 0.6 to
0.9 on the charged particle), where a matrix built at y0 contracts by 0.1 to 0.25. Each
substep starts from its own previous solutions: the average's increment xbar - y0 and Z
extrapolated (a polynomial in the step index) from the same substep of up to eight previous
steps (`HISTORY`; of the number the last start used, one fewer and one more, the number that
would have predicted the last increment best: `_best_order`), and p = h grad H(y0 + that
increment), whose error is then O(h) times the extrapolation's (`_predict_p`). On a constant pi,
J = 0 and the step is the implicit midpoint rule.

Number of nodes: Q is the smallest (at least 2) with E_Q theta^(2Q) <= NODE_BOUND, E_Q the
average's error constant for y' = lambda y (`rkhp.taylor.collocation.average_error_constant`) and
theta = `_norm_bound` of J >= |J|_2, computed at each substep from the derivatives of X at
(y0, predicted p) by forward mode (`rkhp.taylor.scalar`). A substep needing more nodes than its
previous stages had, or two fewer, starts its stages afresh with that Q (one fewer keeps them:
more nodes than needed only cost, and Q would otherwise toggle along an orbit), and its chord
matrix, where it needs one, is rebuilt for it.

The size of a change (a sweep's or a chord iteration's, what the stop tests compare) is the
largest of |dp| and min(1, theta) |dZ|: Z enters the step only through X_p(y0 + Z_j), whose
derivative in y is J, |J|_2 <= theta, so an error of Z moves the stages' field, the average,
hence p, and y1 by at most theta times itself (at the compositions' steps theta is 0.03 to 0.4,
and Z's changes, carried from p's by P, are the larger); p counts in full.

Compiled data: `SprayTapes` (X and H as plain tapes),
`EulerWork` (work arrays of one substep), `SubstepMemory` (what each substep keeps across steps).
`SpraySubstep` (the three, and the state); `begin` and `substep` make the direct form a substep
provider of the driver (`rkhp.integrators.substeps`); `rkhp.integrators.driver.integrate_spray_euler`
is the Python entry. What every substep runs is inlined into the driver's loop: a call of a
compiled function passes the tapes, the work arrays and the memory field by field (hundreds of
arguments, costlier than `_theta`'s own work). What builds a chord or Newton matrix, the
tapes' forward mode (a system without compiled code) and the start of a substep without previous
stages (`_taylor_start`) stay functions of their own, so that the loop's compiled code holds
what runs at every substep (`benchmarks/substeps.py` measures it).
"""

from __future__ import annotations

import math
from typing import NamedTuple

import numpy as np

from ..base.errors import InputError
from ..systems.families import GENERAL
from ..systems.field_code import POINTS
from ..taylor.collocation import TABLE_A, TABLE_B, TABLE_E, TABLE_W
from ..taylor.compiler import NJIT_NORC
from ..taylor.compiler import numba as nb
from ..taylor.composites import _norm_bound
from ..taylor.generated import call_at
from ..taylor.linalg import aligned_zeros, inverse_transposed, max_abs, padded, transposed_product
from ..taylor.ops import SCRATCH_BASE, SPRAY
from ..taylor.rows import subprogram_at
from ..taylor.scalar import SCALAR_CODES, gradients, shared, values
from ..taylor.tape import Tape
from .derivatives import derivatives_at, spray_at
from .direct_form import (
    MAX_PICARD,
    PICARD_RATE,
    RATE_MARGIN,
    REFRESH_FLOOR,
    SLOW_CONTRACTION,
    STAGNATION,
    SWEEP_CONVERGED,
    SWEEP_ON,
    SWEEP_UNDO,
    add_increment,
    gradient,
    hessian,
    sweep_verdict,
    weight,
)
from .failure import Failure

HISTORY = 8
"""Previous solutions of a substep kept for its extrapolated start (a polynomial in the step
index of degree at most 7; the closed form keeps `rkhp.integrators.direct_form.HISTORY`): the
start's error falls as (h omega)^k with k solutions along an orbit of frequency omega, and at the
contraction of a matrix kept across steps each decade less saves about one chord iteration. Where
h omega is not small the higher differences grow instead: each substep extrapolates from as many
as would have predicted its last solution best, among those its last start used and one fewer or
more (`_best_order`)."""
AMORTISE = 2.0
"""A substep rebuilds its chord matrix before iterating when AMORTISE times the iterations that
would save at this step exceeds the matrix's cost in iterations (`_worth_rebuilding`): a fresh
matrix serves the steps that follow too."""
SLOW_SWEEPS = 0.5
"""The sweeps of a substep give way to its chord iterations when one contracts by more than the
square root of the kept matrix's last measured contraction (a chord iteration costs about two
sweeps: a sweep and the product with the inverse), at least
`rkhp.integrators.direct_form.PICARD_RATE` and at most this (a substep whose matrix is unbuilt or
contracts slowly: a sweep then gains 0.3 decades or more)."""
SPARE = 2
"""Iterations a substep keeps for Newton's method after its chord iterations fall behind their
measured contraction (`_out_of_reach`): from a correction at 1e-10 or below, two Newton steps
reach round-off."""
MAX_NODES = 12
"""Collocation nodes of the direct form at most (E_12 theta^24 <= NODE_BOUND for theta up to
about 3.1, beyond the steps at which the chord iterations converge); a substep needing more
fails with STAGES_NO_CONVERGENCE."""
UNROLLED_NODES = 8
"""The sweeps run with Q a constant up to this many nodes (`_picard_unrolled`; the race's settings
take 4 and 5, `benchmarks/substeps.py`)."""
NODE_BOUND = 2.0**-66
"""The bound on E_Q theta^(2 Q), the relative error of the average for y' = lambda y,
|lambda| <= theta (`rkhp.taylor.collocation.average_error_constant`), that sets the number of
nodes: 2^-13 below a unit of round-off, since the flows of a non-linear field are less accurate
than that linear estimate (kahan-li8 on the charged particle from (0.5, 0.1), 100 steps of h = 0.1
forward and back: 6e-12 from the start with 2^-53 or 2^-60, 3e-14 with 2^-66, at 16% more time
a substep)."""


class SprayTapes(NamedTuple):
    """The plain tapes of the direct form, each over the 2n inputs (y, p): `field` X(y, p) =
    pi(y) p (the spray operation's sub-program, outputs X), `hamiltonian` H(y) (p unused); and the
    addresses of their functions compiled for the system (`rkhp.integrators.derivatives`; 0: the
    tape is interpreted): `derivatives_at` H's gradient, `field_at` X with d_y X and pi;
    rebuild_cost (MAX_NODES + 1,): a chord matrix's flops over a chord iteration's with Q nodes
    (`spray_flops`), what a rebuild must save."""

    field: Tape
    hamiltonian: Tape
    derivatives_at: int
    field_at: int
    rebuild_cost: np.ndarray


class EulerWork(NamedTuple):
    """Work arrays of one substep (n: dimension, m = (MAX_NODES + 1) n; res, tmp and inverting
    start on cache lines, inverting's rows padded to whole lines: `rkhp.taylor.linalg.aligned_zeros`).

    W (slots, 2 n + 1): the tapes' slots, values and first derivatives (`rkhp.taylor.scalar`);
    Z, X (MAX_NODES, n): stage increments and their field values; p, g, xbar, y, y_low, dy (n):
    the momentum, grad H(xbar), the average, the state as the double-double y + y_low (`begin`), a
    substep's increment; hess (n, n): Hess H at the refresh point; res, tmp (m): the residual (then
    the correction) and a work vector; u ((MAX_NODES + 2) n), out (n + 2 n^2): the arguments of
    the compiled field, (y, p) or (unused, p, the stages' points), and its results at one point
    (X, d_y X, pi; at the stages X goes to X); perm (m) int64, inverting (m, padded m): the work
    space of a chord matrix's inverse (`rkhp.taylor.linalg.inverse_transposed`)."""

    W: np.ndarray
    Z: np.ndarray
    X: np.ndarray
    p: np.ndarray
    g: np.ndarray
    xbar: np.ndarray
    y: np.ndarray
    y_low: np.ndarray
    dy: np.ndarray
    hess: np.ndarray
    res: np.ndarray
    tmp: np.ndarray
    u: np.ndarray
    out: np.ndarray
    perm: np.ndarray
    inverting: np.ndarray


class SubstepMemory(NamedTuple):
    """What substep i of a composition keeps from one step to the next (index i first).

    x_hist (s, HISTORY, n), z_hist (s, HISTORY, MAX_NODES, n): its last solutions, the average's
    increments xbar - y0 and the stage increments Z, a ring: the r-th newest in slot
    (newest + r) mod HISTORY (`_slot`), so that a new solution moves none; newest (s,) int64:
    the slot of the newest; counts (s, 2) int64: how many
    of them are valid for xbar - y0 and for Z (Z's only with the same
    number of nodes, z_nodes (s,)); nodes (s,) int64: Q of the inverted chord matrix (0: none
    yet); inverse (s, m, padded m): its inverse, transposed (`transposed_product`), m = (Q + 1) n
    used; J, P (s, n, n): d_y X and pi at the refresh point; rate (s,): the contraction of the
    first two iterations, last measured (1: none yet); refreshes (s,) int64: how many times the
    matrix was built in this run; order (s,) int64: how many previous solutions the next start
    extrapolates from at most (`_remember`); built_rate (s,): the contraction measured at the first substep of the
    matrix's last build (1: none yet); iterations (s,) int64: the chord iterations of the last
    substep (0 where the fixed-point sweeps converged)."""

    x_hist: np.ndarray
    z_hist: np.ndarray
    newest: np.ndarray
    counts: np.ndarray
    z_nodes: np.ndarray
    nodes: np.ndarray
    inverse: np.ndarray
    J: np.ndarray
    P: np.ndarray
    rate: np.ndarray
    refreshes: np.ndarray
    order: np.ndarray
    built_rate: np.ndarray
    iterations: np.ndarray


def euler_work(tapes: SprayTapes, n: int) -> EulerWork:
    """The work arrays of one substep for dimension n."""
    m = (MAX_NODES + 1) * n

    def euler_vector():
        return np.zeros(n)

    slots = max(tapes.field.n_slots, tapes.hamiltonian.n_slots)
    return EulerWork(np.zeros((slots, 2 * n + 1)), np.zeros((MAX_NODES, n)), np.zeros((MAX_NODES, n)),
                     euler_vector(), euler_vector(), euler_vector(), euler_vector(), euler_vector(), euler_vector(),
                     np.zeros((n, n)), aligned_zeros(m), aligned_zeros(m), np.zeros((MAX_NODES + 2) * n),
                     np.zeros(n + 2 * n * n),
                     np.zeros(m, np.int64), aligned_zeros((m, padded(m))))


def substep_memory(s: int, n: int) -> SubstepMemory:
    """The memory of s substeps in dimension n (empty: every substep starts cold); the inverses'
    rows start on cache lines (`rkhp.taylor.linalg.aligned_zeros`, rows padded to whole lines)."""
    m = (MAX_NODES + 1) * n
    return SubstepMemory(np.zeros((s, HISTORY, n)), np.zeros((s, HISTORY, MAX_NODES, n)),
                         np.zeros(s, np.int64), np.zeros((s, 2), np.int64), np.zeros(s, np.int64),
                         np.zeros(s, np.int64),
                         aligned_zeros((s, m, padded(m))), np.zeros((s, n, n)),
                         np.zeros((s, n, n)), np.ones(s), np.zeros(s, np.int64), np.full(s, HISTORY, np.int64),
                         np.ones(s), np.zeros(s, np.int64))


# ----------------------------------------------------------------------------------------------
# compiled


@nb.njit(**NJIT_NORC)
def nodes_for(theta):
    """The smallest Q >= 2 with E_Q theta^(2 Q) <= NODE_BOUND (see the module); MAX_NODES + 1
    when none up to MAX_NODES qualifies (or theta is not finite)."""
    if not theta < np.inf:
        return MAX_NODES + 1
    q = 2
    while q <= MAX_NODES and not TABLE_E[q] * theta ** (2 * q) <= NODE_BOUND:
        q += 1
    return q


@nb.njit(inline="always", **NJIT_NORC)
def _fields_at(tapes, work, y0, q, n):
    """work.X[j] := X(y0 + work.Z[j], work.p) for the q stages: one call of the field compiled
    for the system for all of them (``what`` = POINTS - q, the points after p in work.u:
    `rkhp.systems.field_code.spray_code`), else the tape at each."""
    if tapes.field_at != 0:
        for k in range(n):
            work.u[n + k] = work.p[k]
        for j in range(q):
            for k in range(n):
                work.u[2 * n + n * j + k] = y0[k] + work.Z[j, k]
        call_at(tapes.field_at, work.u, work.X, np.int64(POINTS - q))
        return
    W = work.W
    for j in range(q):
        for k in range(n):
            W[k, 0] = y0[k] + work.Z[j, k]
            W[n + k, 0] = work.p[k]
        values(tapes.field, W)
        for k in range(n):
            work.X[j, k] = W[tapes.field.outputs[k], 0]


@nb.njit(**NJIT_NORC)
def _refresh_chord_p(i, y0, hs, tapes, work, memory, n, current):
    """Substep i's chord matrix with step hs at (y0, work.p) (see the module): J, P, Q and the
    inverse of the matrix into the memory; the stages restarted by `_start_stages` when Q differs
    from `current`, the number of nodes work.Z holds (0 for none). Returns Failure.OK,
    STAGES_NO_CONVERGENCE when no Q <= MAX_NODES suffices (the step is too large for the flow),
    or SINGULAR."""
    memory.refreshes[i] += 1
    J, P = memory.J[i], memory.P[i]
    _field_jacobians(y0, tapes, work, n, J, P, True)
    q = nodes_for(_norm_bound(J))
    if q > MAX_NODES:
        return Failure.STAGES_NO_CONVERGENCE
    memory.nodes[i] = q
    if q != current:
        _start_stages(i, q, memory, work, n)
    hessian(tapes, work, y0, n)
    M, H = memory.inverse[i], work.hess
    m = (q + 1) * n
    _set_identity(M, m)
    for a in range(q):
        c = 0.0
        for b in range(q):
            c += TABLE_A[q, a, b]
        for k in range(n):
            for b in range(q):
                for l in range(n):
                    M[a * n + k, b * n + l] -= TABLE_A[q, a, b] * J[k, l]
            for l in range(n):
                M[a * n + k, q * n + l] = -c * P[k, l]
    for k in range(n):
        for l in range(n):
            hj, hp = _hessian_times(H, J, P, k, l, n)
            for b in range(q):
                M[q * n + k, b * n + l] = -hs * TABLE_W[q, b] * hj
            M[q * n + k, q * n + l] -= 0.5 * hs * hp
    return _invert(i, m, work, memory)


@nb.njit(**NJIT_NORC)
def _newton_matrix_p(i, q, y0, hs, tapes, work, memory, n):
    """Substep i's matrix as the exact Jacobian of its equations at the current (Z, p): the chord
    matrix of the module with d_y X and pi taken at each stage, J_b = d_y X(Y_b, p), P_b =
    pi(Y_b), and Hess H at xbar, not all at y0: blocks I - A_ab J_b, -sum_b A_ab P_b,
    -h w_b H J_b and I - h H sum_b w_b P_b (Newton's method; `euler_substep` says when). Q
    kept; memory.J[i], memory.P[i] and work.tmp[:n] (xbar, then the stage) serve as work space.
    Returns Failure.OK or SINGULAR."""
    memory.refreshes[i] += 1
    _fields_at(tapes, work, y0, q, n)
    M, H, J, P, Y = memory.inverse[i], work.hess, memory.J[i], memory.P[i], work.tmp
    for k in range(n):
        acc = y0[k]
        for j in range(q):
            acc += TABLE_W[q, j] * work.X[j, k]
        Y[k] = acc
    hessian(tapes, work, Y[:n], n)
    m = (q + 1) * n
    _set_identity(M, m)
    for b in range(q):
        for k in range(n):
            Y[k] = y0[k] + work.Z[b, k]
        _field_jacobians(Y[:n], tapes, work, n, J, P, True)
        for a in range(q):
            for k in range(n):
                for l in range(n):
                    M[a * n + k, b * n + l] -= TABLE_A[q, a, b] * J[k, l]
                    M[a * n + k, q * n + l] -= TABLE_A[q, a, b] * P[k, l]
        for k in range(n):
            for l in range(n):
                hj, hp = _hessian_times(H, J, P, k, l, n)
                M[q * n + k, b * n + l] = -hs * TABLE_W[q, b] * hj
                M[q * n + k, q * n + l] -= hs * TABLE_W[q, b] * hp
    return _invert(i, m, work, memory)


@nb.njit(inline="always", **NJIT_NORC)
def _set_identity(M, m):
    """M[:m, :m] := the identity (the chord and Newton matrices are I minus their blocks)."""
    for r in range(m):
        for col in range(m):
            M[r, col] = 1.0 if r == col else 0.0


@nb.njit(inline="always", **NJIT_NORC)
def _hessian_times(H, J, P, k, l, n):
    """((H J)_kl, (H P)_kl), the products of the matrices' last block row."""
    hj = 0.0
    hp = 0.0
    for r in range(n):
        hj += H[k, r] * J[r, l]
        hp += H[k, r] * P[r, l]
    return hj, hp


@nb.njit(inline="always", **NJIT_NORC)
def _invert(i, m, work, memory):
    """memory.inverse[i, :m, :m] (the matrix just assembled) replaced by its inverse, transposed
    (`rkhp.taylor.linalg.inverse_transposed`, `transposed_product`); Failure.OK or SINGULAR."""
    if not inverse_transposed(memory.inverse[i, :m, :m], work.perm[:m], work.inverting[:m, :m]):
        return Failure.SINGULAR
    return Failure.OK


@nb.njit(**NJIT_NORC)
def _field_derivatives(y0, j, tapes, work, n, first, nd):
    """X(y, p) with its first derivatives in nd directions by forward mode
    (`rkhp.taylor.scalar.gradients`), y = y0 + work.Z[j] (y0 for j < 0), p = work.p: input k
    (y then p) moves along direction k - first when that is in 0..nd-1. So first = 0, nd = n:
    W[output a, 1 + b] = (d_y X)_ab; first = 0, nd = 2 n: also W[a, 1 + n + b] = pi_ab(y);
    first = n, nd = n: W[a, 1 + b] = pi_ab(y)."""
    W = work.W
    for k in range(2 * n):
        for m in range(1, nd + 1):
            W[k, m] = 1.0 if m == 1 + k - first else 0.0
    for k in range(n):
        W[k, 0] = y0[k] + (work.Z[j, k] if j >= 0 else 0.0)
        W[n + k, 0] = work.p[k]
    gradients(tapes.field, W, nd)


@nb.njit(inline="always", **NJIT_NORC)
def _field_jacobians(y0, tapes, work, n, J, P, both):
    """J := d_y X(y0, work.p) and, with `both`, P := pi(y0) = d_p X: compiled for the system where
    it is, else by forward mode on the field's tape (`_field_derivatives`)."""
    if tapes.field_at != 0:
        for k in range(n):
            work.u[k] = y0[k]
            work.u[n + k] = work.p[k]
        call_at(tapes.field_at, work.u, work.out, np.int64(2) if both else np.int64(1))
        for a in range(n):
            for b in range(n):
                J[a, b] = work.out[n + n * a + b]
                if both:
                    P[a, b] = work.out[n + n * n + n * a + b]
        return
    W = work.W
    _field_derivatives(y0, np.int64(-1), tapes, work, n, np.int64(0), np.int64(2 * n if both else n))
    for a in range(n):
        o = tapes.field.outputs[a]
        for b in range(n):
            J[a, b] = W[o, 1 + b]
            if both:
                P[a, b] = W[o, 1 + n + b]


@nb.njit(inline="always", **NJIT_NORC)
def _theta(y0, tapes, work, n):
    """`_norm_bound` of J = d_y X(y0, work.p) (>= |J|_2): what sets the number of nodes."""
    _field_jacobians(y0, tapes, work, n, work.hess, work.hess, False)
    return _norm_bound(work.hess)


@nb.njit(inline="always", **NJIT_NORC)
def _slot(memory, i, r):
    """The slot of substep i's r-th newest solution in its history (`SubstepMemory`), r < HISTORY;
    r = HISTORY - 1 gives the oldest's, where `_remember` writes the next newest."""
    slot = memory.newest[i] + r
    return slot - HISTORY if slot >= HISTORY else slot


@nb.njit(inline="always", **NJIT_NORC)
def _predict_p(i, y0, hs, tapes, work, memory, n):
    """work.p := hs grad H(y0 + d), d the average's increment xbar - y0 extrapolated from substep
    i's previous solutions (their polynomial in the step index, `weight`; d = 0 without any)."""
    count = min(memory.counts[i, 0], memory.order[i])
    hist = memory.x_hist[i]
    for k in range(n):
        acc = 0.0
        for r in range(count):
            acc += weight(count, r) * hist[_slot(memory, i, r), k]
        work.xbar[k] = y0[k] + acc
    gradient(tapes, work, work.xbar, n)
    for k in range(n):
        work.p[k] = hs * work.g[k]


@nb.njit(**NJIT_NORC)
def _taylor_start(q, J, P, p, Z, n):
    """Z for q nodes as the flow's Taylor polynomial Z(c) = c X0 + (c^2 / 2) J X0, X0 = P p (a
    substep without previous stages: compiled apart from the loop, as it runs rarely)."""
    for j in range(q):
        c = 0.0
        for b in range(q):
            c += TABLE_A[q, j, b]
        for k in range(n):
            x0 = 0.0
            jx = 0.0
            for l in range(n):
                pl = 0.0
                for r in range(n):
                    pl += P[l, r] * p[r]
                x0 += P[k, l] * p[l]
                jx += J[k, l] * pl
            Z[j, k] = c * x0 + 0.5 * c * c * jx


@nb.njit(inline="always", **NJIT_NORC)
def _start_stages(i, q, memory, work, n):
    """work.Z for q nodes: extrapolated from substep i's previous stages when they had q nodes,
    else the flow's Taylor polynomial (`_taylor_start`, memory's J and P)."""
    count = min(memory.counts[i, 1], memory.order[i]) if memory.z_nodes[i] == q else 0
    hist = memory.z_hist[i]
    if count > 0:
        for j in range(q):
            for k in range(n):
                work.Z[j, k] = 0.0
        for r in range(count):
            w = weight(count, r)
            row = hist[_slot(memory, i, r)]
            for j in range(q):
                for k in range(n):
                    work.Z[j, k] += w * row[j, k]
    else:
        _taylor_start(q, memory.J[i], memory.P[i], work.p, work.Z, n)
        memory.counts[i, 1] = 0
        memory.z_nodes[i] = q


@nb.njit(inline="always", **NJIT_NORC)
def _average_gradient(q, y0, tapes, work, n):
    """work.xbar := y0 + sum_j w_j X_j, the flow's average from the stages' field work.X, and
    work.g := grad H(xbar)."""
    for k in range(n):
        acc = y0[k]
        for j in range(q):
            acc += TABLE_W[q, j] * work.X[j, k]
        work.xbar[k] = acc
    gradient(tapes, work, work.xbar, n)


@nb.njit(inline="always", **NJIT_NORC)
def _picard(q, y0, hs, tapes, work, n, zw):
    """One fixed-point sweep of the equations: X_b := X(y0 + Z_b, p), Z_a := sum_b A_ab X_b,
    p := hs grad H(y0 + sum_b w_b X_b); (Z, p) first saved in work.tmp. Returns the size of the
    change, the largest of |dp| and zw |dZ| (see the module; NaN-safe)."""
    _fields_at(tapes, work, y0, q, n)
    size = 0.0
    for a in range(q):
        for k in range(n):
            acc = 0.0
            for b in range(q):
                acc += TABLE_A[q, a, b] * work.X[b, k]
            work.tmp[a * n + k] = work.Z[a, k]
            d = zw * abs(acc - work.Z[a, k])
            if not d <= size:
                size = d
            work.Z[a, k] = acc
    _average_gradient(q, y0, tapes, work, n)
    for k in range(n):
        work.tmp[q * n + k] = work.p[k]
        new = hs * work.g[k]
        d = abs(new - work.p[k])
        if not d <= size:
            size = d
        work.p[k] = new
    return size


@nb.njit(inline="always", **NJIT_NORC)
def _picard_unrolled(q, y0, hs, tapes, work, n, zw):
    """`_picard` with q a constant from 2 to UNROLLED_NODES (a branch per value), else as it is:
    with q constant the loops over the stages unroll and the collocation tables' entries are
    constants (the branch costs less than the loops' overhead on the few stages of a sweep)."""
    if q == 2:
        return _picard(2, y0, hs, tapes, work, n, zw)
    if q == 3:
        return _picard(3, y0, hs, tapes, work, n, zw)
    if q == 4:
        return _picard(4, y0, hs, tapes, work, n, zw)
    if q == 5:
        return _picard(5, y0, hs, tapes, work, n, zw)
    if q == 6:
        return _picard(6, y0, hs, tapes, work, n, zw)
    if q == 7:
        return _picard(7, y0, hs, tapes, work, n, zw)
    if q == UNROLLED_NODES:
        return _picard(UNROLLED_NODES, y0, hs, tapes, work, n, zw)
    return _picard(q, y0, hs, tapes, work, n, zw)


@nb.njit(inline="always", **NJIT_NORC)
def _undo_picard(q, work, n):
    """(Z, p) as before the last `_picard` sweep."""
    for a in range(q):
        for k in range(n):
            work.Z[a, k] = work.tmp[a * n + k]
    for k in range(n):
        work.p[k] = work.tmp[q * n + k]


@nb.njit(inline="always", **NJIT_NORC)
def _sweeps(q, y0, hs, tapes, work, n, tol, stagnation, zw, slow):
    """Fixed-point sweeps (`_picard`) from the current (Z, p) while `sweep_verdict` lets them
    go on: returns (sweeps, whether they converged; a sweep it undoes is not counted)."""
    previous = np.inf
    sweeps = 0
    while sweeps < MAX_PICARD:
        size = _picard_unrolled(q, y0, hs, tapes, work, n, zw)
        sweeps += 1
        verdict = sweep_verdict(sweeps, size, previous, tol, stagnation, slow)
        if verdict == SWEEP_UNDO:
            _undo_picard(q, work, n)
            return sweeps - 1, False
        if verdict != SWEEP_ON:
            return sweeps, verdict == SWEEP_CONVERGED
        previous = size
    return sweeps, False


@nb.njit(inline="always", **NJIT_NORC)
def _best_order(i, memory, y0, work, n):
    """The number of substep i's previous solutions whose extrapolation comes closest to its
    converged xbar - y0 (largest component of the difference), among the number its start used
    (`_predict_p`) and one fewer or more: the order moves by one a step, as the best does along
    an orbit, at three extrapolations' cost rather than HISTORY's; HISTORY, to let the order
    grow, when the best is all there were."""
    count = memory.counts[i, 0]
    best = np.inf
    chosen = count
    used = min(count, memory.order[i])
    for c in range(max(1, used - 1), min(count, used + 1) + 1):
        err = 0.0
        for k in range(n):
            acc = 0.0
            for r in range(c):
                acc += weight(c, r) * memory.x_hist[i, _slot(memory, i, r), k]
            err = max(err, abs(acc - (work.xbar[k] - y0[k])))
        if err < best:
            best = err
            chosen = c
    return HISTORY if chosen == count else chosen


@nb.njit(inline="always", **NJIT_NORC)
def _worth_rebuilding(i, q, tapes, memory):
    """Whether substep i rebuilds its chord matrix before iterating: its last two contractions
    measured, stale (memory.rate, at its last step) and fresh (memory.built_rate, at the first
    substep after the last build), put the iterations it needs at about
    memory.iterations log(fresh) / log(stale) with a fresh matrix; a rebuild when AMORTISE times
    the saving exceeds the matrix's cost in iterations (tapes.rebuild_cost[q])."""
    stale, fresh = memory.rate[i], memory.built_rate[i]
    if not (0.0 < fresh < stale < 1.0):
        return False
    saved = memory.iterations[i] * (1.0 - np.log(stale) / np.log(fresh))
    return AMORTISE * saved > tapes.rebuild_cost[q]


@nb.njit(inline="always", **NJIT_NORC)
def _remember(i, q, memory, y0, work, n):
    """Push the converged xbar - y0 and Z of substep i into its history (in place of the oldest:
    `SubstepMemory`), after choosing how many previous solutions its next start extrapolates from
    (`_best_order`)."""
    memory.order[i] = _best_order(i, memory, y0, work, n)
    newest = _slot(memory, i, HISTORY - 1)
    memory.newest[i] = newest
    for k in range(n):
        memory.x_hist[i, newest, k] = work.xbar[k] - y0[k]
    for j in range(q):
        for k in range(n):
            memory.z_hist[i, newest, j, k] = work.Z[j, k]
    memory.counts[i, 0] = min(memory.counts[i, 0] + 1, HISTORY)
    memory.counts[i, 1] = min(memory.counts[i, 1] + 1, HISTORY)


@nb.njit(inline="always", **NJIT_NORC)
def _chord_iteration(i, q, y0, hs, tapes, work, memory, n, zw):
    """One chord iteration of substep i: X at the stages, the residual of (Z, p), the correction
    by the stored inverse (into work.res), applied to work.Z and work.p; returns its size, the
    largest of |dp| and zw |dZ| (see the module; NaN-safe)."""
    _fields_at(tapes, work, y0, q, n)
    _average_gradient(q, y0, tapes, work, n)
    res = work.res
    for a in range(q):
        for k in range(n):
            acc = -work.Z[a, k]
            for b in range(q):
                acc += TABLE_A[q, a, b] * work.X[b, k]
            res[a * n + k] = acc
    for k in range(n):
        res[q * n + k] = hs * work.g[k] - work.p[k]
    transposed_product(memory.inverse[i], res, work.tmp, (q + 1) * n)
    for r in range((q + 1) * n):
        res[r] = work.tmp[r]
    size = 0.0
    for a in range(q):
        for k in range(n):
            d = res[a * n + k]
            work.Z[a, k] += d
            if not zw * abs(d) <= size:
                size = zw * abs(d)
    for k in range(n):
        d = res[q * n + k]
        work.p[k] += d
        if not abs(d) <= size:
            size = abs(d)
    return size


@nb.njit(**NJIT_NORC)
def _out_of_reach(it, since, size, theta, max_iter, floor):
    """Whether iteration `it` of a substep, from the (max_iter // 2)-th, takes the exact Jacobian:
    unless its corrections, contracting by the measured theta (since >= 2), would meet the stop
    test (their predicted successor theta / (1 - theta) |d| at most `floor`, the tolerance) in
    the iterations left but SPARE, as a kept matrix contracting by 0.1 at large steps does in a
    few more iterations, each far cheaper than a Jacobian (docs/general-poisson.md "The Euler
    step in direct form"). The test is made again at each iteration: a substep that falls behind
    takes the Jacobian with SPARE iterations left for Newton's. A unit of its own, called only
    past half the iterations, and powers by products: inlined, or with a call of pow, it changes
    how the compiler lays out the whole loop, sweeps included."""
    if since < 2 or not theta < 1.0:
        return True
    reach = size
    for _ in range(max_iter - it - 1 - SPARE):
        reach *= theta
    return theta / (1.0 - theta) * reach > floor


@nb.njit(inline="always", **NJIT_NORC)
def euler_substep(i, y0, hs, tapes, work, memory, tol, max_iter):
    """One Euler substep of step hs in direct form (see the module) from y0: its increment
    y1 - y0 into work.dy, substep i of the composition (its memory); returns (Failure, chord
    iterations, fixed-point sweeps).

    Starts from the predicted (p, Z) (`_predict_p`, `_start_stages`) and sweeps
    (`_sweeps`, after one sweep not judged where the substep has no previous solutions: see the
    module); where the sweeps did not converge, iterates with the chord matrix from
    where they left. Q is that of the previous stages (`SubstepMemory.z_nodes`) unless theta asks
    for more or for two fewer (`nodes_for`). The chord matrix is built only for the iterations:
    before them where it has another Q than the stages or a fresh one is worth its cost
    (`_worth_rebuilding`), and when an iteration
    contracts by more than SLOW_CONTRACTION (once per substep); takes the exact Jacobian at the
    current iterate (`_newton_matrix_p`) when a fresh matrix contracts by more than that, and at
    each iteration from the (max_iter // 2)-th whose contraction would not meet the stop test in
    time (`_out_of_reach`) while the correction exceeds max(1e3 tol, REFRESH_FLOOR) max(1, |y0|).
    Stops (sweeps and iterations alike) when the correction (its size as the module says: Z's
    part times min(1, theta), theta `_theta`), or its predicted successor
    theta / (1 - theta) |d| (theta the
    measured contraction; after the first iteration, twice the substep's last measured first
    contraction), is at most tol max(1, |y0|); then X is evaluated at the final (Z, p) and
    y1 = y0 + sum_j b_j X_j."""
    n = y0.shape[0]
    scale = max(1.0, max_abs(y0))
    _predict_p(i, y0, hs, tapes, work, memory, n)
    theta = _theta(y0, tapes, work, n)
    needed = nodes_for(theta)
    zw = min(1.0, theta)
    if needed > MAX_NODES:
        return Failure.STAGES_NO_CONVERGENCE, 0, 0
    q = memory.z_nodes[i]
    if q == 0 or needed > q or needed < q - 1:
        q = needed
    if memory.z_nodes[i] != q or memory.counts[i, 1] == 0:
        _field_jacobians(y0, tapes, work, n, memory.J[i], memory.P[i], True)
    _start_stages(i, q, memory, work, n)
    aligned = 0
    if memory.counts[i, 0] == 0:
        if _picard(q, y0, hs, tapes, work, n, zw) < np.inf:
            aligned = 1
        else:
            _undo_picard(q, work, n)
    slow = min(SLOW_SWEEPS, max(PICARD_RATE, math.sqrt(memory.rate[i])))
    sweeps, converged = _sweeps(q, y0, hs, tapes, work, n, tol * scale, STAGNATION * scale, zw, slow)
    sweeps += aligned
    fresh = False
    if not converged and (memory.nodes[i] != q or _worth_rebuilding(i, q, tapes, memory)):
        cause = _refresh_chord_p(i, y0, hs, tapes, work, memory, n, q)
        if cause != Failure.OK:
            return cause, 0, sweeps
        fresh = True
        q = memory.nodes[i]
    previous = np.inf
    since = 0
    it = 0
    size = 0.0
    while not converged and it < max_iter:
        it += 1
        since += 1
        size = _chord_iteration(i, q, y0, hs, tapes, work, memory, n, zw)
        if not size < np.inf:
            return Failure.NEWTON_NON_FINITE, it, sweeps
        if size > 1e8 * scale:
            return Failure.NEWTON_DIVERGED, it, sweeps
        if since == 1:
            theta = RATE_MARGIN * memory.rate[i]
        else:
            theta = size / previous
            if since == 2:
                memory.rate[i] = theta
                if fresh:
                    memory.built_rate[i] = theta
        predicted = theta / (1.0 - theta) * size if theta < 0.5 else np.inf
        if size <= tol * scale or predicted <= tol * scale:
            converged = True
            break
        if since >= 2 and size >= 0.5 * previous and size <= STAGNATION * scale:
            converged = True  # the corrections stagnate at round-off
            break
        rescue = it >= max_iter // 2 and _out_of_reach(it, since, size, theta, max_iter, tol * scale)
        if size > max(1e3 * tol, REFRESH_FLOOR) * scale and ((since >= 2 and theta > SLOW_CONTRACTION) or rescue):
            if fresh or rescue:
                cause = _newton_matrix_p(i, q, y0, hs, tapes, work, memory, n)
            else:
                fresh = True
                cause = _refresh_chord_p(i, y0, hs, tapes, work, memory, n, q)
            if cause != Failure.OK:
                return cause, it, sweeps
            q = memory.nodes[i]
            since = 0
        previous = size
    if not converged:
        return Failure.NEWTON_NO_CONVERGENCE, it, sweeps
    _fields_at(tapes, work, y0, q, n)
    for k in range(n):
        acc = 0.0
        for j in range(q):
            acc += TABLE_B[q, j] * work.X[j, k]
        work.dy[k] = acc
    _remember(i, q, memory, y0, work, n)
    memory.iterations[i] = it
    return Failure.OK, it, sweeps


@nb.njit(inline="always", **NJIT_NORC)
def resume(data, y0):
    """The state set to y0 (work.y, carried as the double-double y + y_low: each substep adds its
    increment without rounding the state to doubles, so the rounding of the states does not
    accumulate; what remains of a non-quadratic Casimir's error is each substep's systematic
    part, far below a unit of round-off, docs/compositions.md "Long runs"), every substep's memory
    kept."""
    work = data.work
    for k in range(y0.shape[0]):
        work.y[k] = y0[k]
        work.y_low[k] = 0.0


@nb.njit(inline="always", **NJIT_NORC)
def begin(data, y0):
    """Start a run at y0 (`resume`), every substep's memory emptied."""
    resume(data, y0)
    memory = data.memory
    for i in range(memory.nodes.shape[0]):
        memory.counts[i, 0] = 0
        memory.counts[i, 1] = 0
        memory.newest[i] = 0
        memory.z_nodes[i] = 0
        memory.nodes[i] = 0
        memory.rate[i] = 1.0
        memory.refreshes[i] = 0
        memory.order[i] = HISTORY
        memory.built_rate[i] = 1.0
        memory.iterations[i] = 0
    return 0


@nb.njit(inline="always", **NJIT_NORC)
def substep(data, context, i, hs, solver):
    """Substep i of size hs in direct form (`euler_substep`: solver.tol relative to max(1, |y|),
    at most solver.max_iter chord iterations), its increment added to the state without rounding
    it (`add_increment`); returns (Failure, chord iterations, fixed-point sweeps: the stage
    sweeps the run reports)."""
    work = data.work
    cause, it, sweeps = euler_substep(i, work.y, hs, data.tapes, work, data.memory, solver.tol, solver.max_iter)
    if cause == Failure.OK:
        add_increment(work.y, work.y_low, work.dy, work.y.shape[0])
    return cause, it, sweeps


# ----------------------------------------------------------------------------------------------
# Python


def field_tape(alpha_tape: Tape, n: int) -> Tape:
    """X(y, p) = pi(y) p as a plain tape over (y, p): the sub-program of the spray operation that
    the full spray realisation's alpha tape consists of (its operands the inputs x, p; its
    first n results alpha). InputError when the tape is not that (another realisation)."""
    ops, args = alpha_tape.ops, alpha_tape.args
    main = [r for r in range(alpha_tape.main, len(ops)) if ops[r, 0] == SPRAY]
    not_spray = InputError("the direct Euler step needs the full Poisson-spray realisation "
                           "(family general, realisation symmetric)")
    if len(main) != 1:
        raise not_spray
    r = main[0]
    out, start = int(ops[r, 1]), int(ops[r, 2])
    lo, hi, in0, n_in, out0, n_out, pos = subprogram_at(args, start)
    operands = [int(v) for v in args[pos: pos + 2 * n]]
    if (n_in != 2 * n or n_out != n or operands != list(range(2 * n))
            or [int(v) for v in alpha_tape.outputs] != list(range(out, out + n))):
        raise not_spray
    first = int(args[in0])
    inputs = [int(v) for v in args[in0: in0 + n_in]]
    if inputs != list(range(first, first + 2 * n)):
        raise not_spray
    rows = np.array(ops[lo:hi], dtype=np.int64)
    for col in (1, 2, 3):  # out, a, b: slots of the sub-program (or -1), shifted to start at 0
        rows[:, col] = np.where(rows[:, col] >= 0, rows[:, col] - first, rows[:, col])
    outputs = np.array([int(args[out0 + k]) - first for k in range(n)], dtype=np.int64)
    n_slots = int(max(rows[:, 1].max(initial=-1), outputs.max(), 2 * n - 1)) + 1
    return Tape(rows, np.array(alpha_tape.fpar[lo:hi], dtype=np.float64), np.zeros(1, np.int64),
                outputs, 2 * n, n_slots, 0, SCRATCH_BASE)


def plain_tapes(system) -> tuple[Tape, Tape]:
    """The field's and H's plain tapes of the direct form (`SprayTapes`) for a system of the
    general family with the symmetric (full spray) realisation; InputError otherwise."""
    if system.family != GENERAL or system.realisation != "symmetric":
        raise InputError(f"{system.name}: the direct Euler step is that of the Poisson-spray "
                         f"realisation (family general, realisation symmetric); this system is "
                         f"{system.family}, realisation {system.realisation}")
    field, h = field_tape(system.alpha_tape, system.dim), system.h_tape
    for what, tape in (("Poisson matrix", field), ("Hamiltonian", h)):
        if tape.main != 0 or any(int(code) not in SCALAR_CODES for code in tape.ops[:, 0]):
            raise InputError(f"{system.name}: the direct Euler step evaluates + - * / and the "
                             f"functions of mathematical text; the {what}'s tape holds another "
                             f"operation")
    return shared(field), shared(Tape(*h))


class SprayFlops(NamedTuple):
    """Floating-point operations of the direct form's parts with Q nodes (`spray_flops`).
    iteration: X at the stages, xbar, the gradient, the residual, the solve and the corrections;
    sweep: a fixed-point sweep (X at the stages, Z, xbar, the gradient, the changes);
    substep: the start extrapolated from HISTORY steps with its gradient, J for the node count,
    X at the final stages and y1; matrix: a chord matrix built at y0 (X with its derivatives, the Hessian by
    central differences of the gradient, the assembly, the inversion: LU factors, then the columns of the inverse)."""

    iteration: float
    sweep: float
    substep: float
    matrix: float


class OperationCounts(NamedTuple):
    """Operations of one evaluation: X (`field`), X with d_y X (`jacobian`), X with d_y X and pi
    (`both`), and H's gradient (`gradient`)."""

    field: float
    jacobian: float
    both: float
    gradient: float


def spray_flops(n: int, q: float, counts: OperationCounts) -> SprayFlops:
    """The operations of `SprayFlops` in dimension n with q nodes (m = (q + 1) n unknowns), from
    those of one evaluation of each function (`counts`)."""
    m = (q + 1) * n
    iteration = q * counts.field + 2 * q * n + counts.gradient + 2 * q * q * n + 2 * m * m + 2 * m
    sweep = q * counts.field + 2 * q * n + counts.gradient + 2 * q * q * n + 2 * m
    substep = (2 * HISTORY * (q + 1) * n + counts.gradient + counts.jacobian + 2 * n * n + q * counts.field
               + 2 * q * n)
    assembly = 2 * q * q * n * n + 4 * n**3 + 2 * q * n * n
    matrix = counts.both + 2 * n * counts.gradient + assembly + 8 * m**3 / 3
    return SprayFlops(iteration, sweep, substep, matrix)


def tape_counts(field: Tape, hamiltonian: Tape, n: int) -> OperationCounts:
    """`OperationCounts` by forward mode on the tapes (an upper bound of those of the code compiled
    per system): X with no, n and 2 n directions, and H's gradient."""
    ops, h_ops = field.ops.shape[0], hamiltonian.ops.shape[0]
    return OperationCounts(2 * ops, 2 * ops * (n + 1), 2 * ops * (2 * n + 1), 2 * h_ops * (n + 1) + 2 * n)


def rebuild_costs(field: Tape, hamiltonian: Tape, n: int) -> np.ndarray:
    """`SprayTapes.rebuild_cost`: for each Q up to MAX_NODES (at least 2), a chord matrix's
    operations over a chord iteration's (`spray_flops` on `tape_counts`)."""
    counts = tape_counts(field, hamiltonian, n)
    costs = [spray_flops(n, max(q, 2), counts) for q in range(MAX_NODES + 1)]
    return np.array([c.matrix / c.iteration for c in costs])


def spray_tapes(system) -> SprayTapes:
    """The tapes of the direct form (`plain_tapes`; InputError where it refuses the system), with
    the addresses of the field and of H's gradient compiled for the system and the cost of a
    chord matrix (`rebuild_costs`)."""
    field, h = plain_tapes(system)
    return SprayTapes(field, h, derivatives_at(system, hessian=False), spray_at(system, field),
                      rebuild_costs(field, h, system.dim))


def direct_form_available(system) -> bool:
    """Whether `plain_tapes` accepts `system` (the full spray realisation, tapes of plain
    operations)."""
    try:
        plain_tapes(system)
    except InputError:
        return False
    return True


class SpraySubstep(NamedTuple):
    """What the direct form's substeps of one run use: the tapes (`spray_tapes`), the work arrays
    and the memory of the composition's substeps; the state the substeps advance, y (work.y, the
    high part of the double-double y + y_low)."""

    tapes: SprayTapes
    work: EulerWork
    memory: SubstepMemory
    y: np.ndarray


def spray_substep_data(system, substeps: int) -> SpraySubstep:
    """The data of `substeps` direct-form substeps on `system` (InputError for a system that
    `spray_tapes` refuses)."""
    tapes = spray_tapes(system)
    work = euler_work(tapes, system.dim)
    return SpraySubstep(tapes, work, substep_memory(substeps, system.dim), work.y)


def spray_extra(data: SpraySubstep) -> dict:
    """What a run reports of its direct-form substeps: the collocation nodes of each (of its last
    stages) and how often each built its chord matrix."""
    return {"nodes": data.memory.z_nodes.tolist(), "refreshes": data.memory.refreshes.tolist()}
