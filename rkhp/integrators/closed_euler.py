"""The RKHP Euler step in direct form on the families whose symmetric birealisation is in closed
form (constant, lie-poisson, log-canonical; docs/theory.md §4, §5, §12), and compositions of it.

The RKHP Euler step of size h solves alpha(x, p) = y0 with p = h grad H(x) and returns
y1 = beta(x, p) = alpha(x, -p). On these families alpha(x, p) = y0 solves for x in closed form,
so the step is one system of n equations in an unknown z, with x and y1 explicit in z:

- constant pi (alpha = x - pi p / 2): z = p, x = y0 + pi z / 2, y1 = y0 + pi z (the implicit
  midpoint rule);
- lie-poisson (alpha = phi(K) x, phi(z) = z / (1 - e^-z), K(p) x = -pi(x) p, K_ik =
  -sum_j C_ijk p_j): z = p, x = psi(K) y0 with psi(z) = (1 - e^-z) / z, and y1 = phi(-K) psi(K) y0
  = e^-K y0 (a coadjoint orbit is kept whatever z is);
- log-canonical (alpha_i = x_i exp(-(1/2) sum_j lambda_ij x_j p_j)): z = x o p (componentwise),
  u = lambda z, x_i = y0_i e^(u_i / 2), y1_i = y0_i e^(u_i), p = z / x (the Casimirs
  sum_i k_i log x_i, k lambda = 0, are kept whatever z is).

The equation is z = G(x(z)) with G(x) = h grad H(x) (constant, lie-poisson) or x o h grad H(x)
(log-canonical): values and first derivatives of H only (`rkhp.taylor.scalar`), no jets. It is
solved by quasi-Newton iterations z += B (G(x(z)) - z) from B = M^-1, M = I - G'(y0) x'(0)
(x'(0) = pi(y0) / 2 for the first two families, diag(y0) lambda / 2 for log-canonical; Hess H by
differences of the gradient, `rkhp.integrators.direct_form.hessian`), a chord matrix that
contracts by O(h^2) an iteration, improved in up to BROYDEN_DIMENSION dimensions by Broyden's
update of B from each correction and the change of the residual it brought (measured on RKHP
Euler: 4.3 iterations a step against 6.6 for the plain chord iterations on the rigid body at
h = 0.1, 5.8 against 8.1 on Lotka–Volterra, 4.5 against 8.5 on the ax + b algebra).
B is stored transposed, its columns contiguous: its inversion and, beyond BROYDEN_DIMENSION, its
product with a vector are loops over rows the compiler vectorises (`_chord_correction`).
B is built once per substep of a composition and kept, with its updates, across steps (rebuilt
when its contraction grows, `REFRESH_CONTRACTION`, `rkhp.integrators.direct_form.SLOW_CONTRACTION`).
A substep without previous solutions (the first step's, a processor's: it runs once a call) first
sweeps z := G(x(z)), which contracts by O(h) (|h Hess H x'| is O(h)) without a matrix, and builds
B only where the sweeps slow (`rkhp.integrators.direct_form.sweep_verdict`): a matrix costs 2n
gradients and an n x n inverse, more than the sweeps a single substep takes; a substep that
recurs iterates with its B, whose iterations cost an n x n product but contract by O(h^2).
Each substep starts from z extrapolated over the same substep of the previous steps (`HISTORY`,
as the spray's direct form, docs/general-poisson.md "The Euler step in direct form"), plus the
errors that extrapolation made on the two substeps just before, per unit of step, on their line
in time (`_predict_z`, docs/compositions.md "The cost of a substep").

e^-K y0 and psi(K) y0 are power series, or closed forms on so(3)* (Rodrigues'), se(3)* (the heavy
top: Rodrigues' and their derivative) and the diagonal algebras (K(p) = [[D, 0], [E, 0]]: n
exponentials, the Toda lattice), under the guard of the family's phi
(`rkhp.integrators.lie_poisson_point`).

Compiled data: `ClosedForm` (the family's structure and H's tape), `ClosedWork` (work arrays),
`ChordMemory` (what each substep keeps across steps, B included), `ClosedSubstep` (the three, and
the state); `begin` and `substep` make the direct form a substep provider of the driver
(`rkhp.integrators.substeps`), inlined into its loop with their helpers (a unit of their own would
be optimised again there: docs/engine.md "Compile time"); `rkhp.integrators.driver.integrate_closed_euler`
is the Python entry.
"""

from __future__ import annotations

import math
import weakref
from typing import NamedTuple

import numpy as np

from ..base.errors import InputError
from ..systems import families
from ..taylor.compiler import NJIT_NORC
from ..taylor.compiler import numba as nb
from ..taylor.generated import call_at
from ..taylor.linalg import inverse_transposed, lu_factor, lu_solve, max_abs, transposed_product
from ..taylor.scalar import SCALAR_CODES, polynomial_degree, shared
from ..taylor.tape import Tape
from .derivatives import derivatives_at
from .direct_form import (
    HISTORY,
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
from .lie_poisson_point import (
    POINT_CONSTANTS,
    diagonal_point,
    diagonal_point_at,
    exp_series,
    generated_diagonal_point,
    rotation_jacobian,
    rotation_point,
    se3_point,
)

CONSTANT, LIE_POISSON, LOG_CANONICAL = 0, 1, 2
"""The families of `ClosedForm.kind`."""
KINDS = {families.CONSTANT: CONSTANT, families.LIE_POISSON: LIE_POISSON, families.LOG_CANONICAL: LOG_CANONICAL}
REFRESH_CONTRACTION = 0.05
"""A substep whose first two iterations contracted by more than this at its previous step
rebuilds B before iterating: the chord matrix built at y0 contracts by O(h^2) (measured 0.004
on the rigid body, 0.0004 on toda:12, 0.02 on Lotka–Volterra, tj4 at h = 0.1, 0.05, 0.1), and
goes stale as the state moves along its orbit (without Broyden's update 0.1 to 0.2 on
Lotka–Volterra after a few steps, where each iteration then gains a decade only); a rebuild
costs 2 n gradients of H."""
BROYDEN_DIMENSION = 8
"""Broyden's update of B in systems of at most this dimension: it costs three products with B
(3 n^2 multiply-adds an iteration), which beyond it cost more than the iterations they save
(measured: the heavy top, n = 6, runs faster with it; the Toda lattices of 12 and 24 variables,
whose closed-form point costs O(n), without)."""
DEFECT_REACH = 4.0
"""A substep's start takes the line through the last two substeps' defects (`_predict_z`) only
within this many times their distance in time from the last: further, or with the two at one
time, the last defect alone."""
BROYDEN_FLOOR = 2.0**-30
"""Broyden's update uses a correction only above this (relative to max(1, |y0|)): below, the
change of the residual is dominated by its rounding."""
EXACT_DIMENSION = 12
"""Systems whose Hess H is constant (a quadratic H) or compiled (`ClosedForm.derivatives_at`)
solve each substep by Newton's method (`newton_substep`) on so(3)*, and on the constant and
log-canonical families up to this dimension; the others keep a chord matrix across steps with
Broyden's updates (`closed_substep`): where Hess H is interpreted (central differences of the
gradient, 2 n gradients), more but cheaper chord iterations take less time
(`benchmarks/substeps.py`); on other Lie–Poisson algebras x'(z) is not written (se(3)*, the
series), or (the diagonal algebras) the chord iterations on their closed-form point cost less than
Newton's factorisations; and in more dimensions the Hessian's n^2 entries and its factorisation
cost more than the iterations they save."""
NEWTON_REFRESH = 1e-4
"""`newton_substep` takes the exact Jacobian again after a correction above this (relative to
max(1, |y0|)); below it the last one serves: its chord step contracts by about L |d| (L the
quadratic constant, d the correction since the Jacobian was taken), so from an extrapolated start
(`_predict_z`) the first Newton step leaves an error of about L |d|^2 that one or two chord
steps take to round-off, and a second factorisation pays only after a large correction (a cold
start; `benchmarks/substeps.py` shows the iterations and factorisations a substep)."""


class ClosedForm(NamedTuple):
    """The structure of a system of a closed-form family, and H's plain tape (`hamiltonian`,
    over the 2n inputs (x, p), p unused).

    kind: CONSTANT, LIE_POISSON or LOG_CANONICAL; matrix (n, n): pi (constant), lambda
    (log-canonical), zeros (lie-poisson); lie-poisson's K(p) by its entries that are not
    identically zero: pairs (e, 2) the (i, k) of entry e, K_ik = sum over r in
    starts[e]..starts[e+1]-1 of coefs[r] p[cols[r]] (coefs = -C_ijk, cols = j); rotation: the
    scalar s with K(z) = hat(s z) when the algebra is so(3) (C = -s epsilon; e^-K and psi(K) are
    then Rodrigues' closed forms, `rotation_point`) and K(z) = [[hat(q), hat(r)], [0, hat(q)]],
    (q, r) = s z, when it is se(3) (`se3_point`), else 0; diagonal (n,) int64: on a diagonal
    algebra (K(p) = [[D, 0], [E, 0]], `rkhp.integrators.lie_poisson_point`) the entry of K_kk
    for each k (-1 where it vanishes; e^-K and psi(K) are then closed forms, `diagonal_point`),
    else empty; exact: whether each substep's matrix is the exact Jacobian at its iterates
    (`EXACT_DIMENSION`, `newton_substep`);
    hessian_constant: whether H is a polynomial of degree at most 2 (`rkhp.taylor.scalar.
    polynomial_degree`), and then hessian (n, n) its Hessian (else zeros); derivatives_at: the
    address of H's gradient and Hessian compiled for this system (`rkhp.integrators.derivatives`;
    the Hessian where the substeps take Newton's method on a non-quadratic H), 0 where the tape is
    interpreted; point_at: on a diagonal algebra the address of its generated point
    (`rkhp.integrators.lie_poisson_point.diagonal_point_at`), else 0 (`diagonal_point` then)."""

    kind: int
    matrix: np.ndarray
    pairs: np.ndarray
    starts: np.ndarray
    cols: np.ndarray
    coefs: np.ndarray
    hamiltonian: Tape
    rotation: float
    diagonal: np.ndarray
    exact: bool
    hessian_constant: bool
    hessian: np.ndarray
    derivatives_at: int
    point_at: int


class ClosedWork(NamedTuple):
    """Work arrays (n: dimension, e: entries of K).

    W (slots, n + 1): H's tape slots, values and first derivatives (`rkhp.taylor.scalar`);
    z (n): the unknown; xbar (n): the point x of the step (alpha(x, p) = y0); g (n): grad H(xbar);
    dy (n): the substep's increment y1 - y0; v, kv (n): a term of the series and its product by
    K; kval (e): the entries of K; hess, jac (n, n): Hess H and x'(z) at the refresh point (then
    the chord matrix's inverse, before it is copied into the memory); xz (n): x at the refresh
    point; res, tmp (n): the residual
    (then the correction) and lu_solve's work vector; last, step, by (n): the previous residual,
    the previous correction and a product, for Broyden's update; perm (n) int64: the row order
    of the chord matrix's factors; y, y_low (n): the state as the double-double y + y_low
    (`begin`); derivs (n + n^2): grad H and Hess H by the compiled derivatives; zy (2n + constants)
    and pt (2n + 1): the generated point's input (z, y0, `lie_poisson_point.POINT_CONSTANTS`) and
    output (`generated_diagonal_point`)."""

    W: np.ndarray
    z: np.ndarray
    xbar: np.ndarray
    g: np.ndarray
    dy: np.ndarray
    v: np.ndarray
    kv: np.ndarray
    kval: np.ndarray
    hess: np.ndarray
    jac: np.ndarray
    xz: np.ndarray
    res: np.ndarray
    tmp: np.ndarray
    last: np.ndarray
    step: np.ndarray
    by: np.ndarray
    perm: np.ndarray
    y: np.ndarray
    y_low: np.ndarray
    derivs: np.ndarray
    zy: np.ndarray
    pt: np.ndarray


class ChordMemory(NamedTuple):
    """What substep i of a composition keeps from one step to the next (index i first).

    z_hist (s, HISTORY, n): its last solutions, newest first; count (s,) int64: how many;
    inverse (s, n, n): the inverse of its chord matrix, transposed (inverse[i, c] is column c of
    the inverse, `_chord_correction`), with Broyden's updates (with Newton's method,
    `newton_substep`: the LU factors of its last Jacobian); ready (s,) int64:
    1 once it exists; rate (s,): the contraction of its first two iterations, last measured (1: none yet);
    refreshes (s,) int64: how many times the matrix was built in this run; z_pred (n): the
    extrapolation of the substep running (`_predict_z`); defect (2, n), defect_order (2,) int64,
    defect_time (2,): for the last substep and the one before it, the converged z less its
    extrapolation, divided by its step, the number of solutions that extrapolation used (0:
    none, after `resume`) and the substep's midpoint time; clock (1,): the time at the end of
    the last substep (from the run's start)."""

    z_hist: np.ndarray
    count: np.ndarray
    inverse: np.ndarray
    ready: np.ndarray
    rate: np.ndarray
    refreshes: np.ndarray
    z_pred: np.ndarray
    defect: np.ndarray
    defect_order: np.ndarray
    defect_time: np.ndarray
    clock: np.ndarray


def closed_work(form: ClosedForm, n: int) -> ClosedWork:
    """The work arrays for dimension n."""
    def vector():
        return np.zeros(n)

    return ClosedWork(np.zeros((form.hamiltonian.n_slots, n + 1)), vector(), vector(), vector(), vector(), vector(),
                      vector(), np.zeros(form.pairs.shape[0]), np.zeros((n, n)), np.zeros((n, n)),
                      vector(), vector(), vector(), vector(), vector(), vector(),
                      np.zeros(n, np.int64), vector(), vector(), np.zeros(n + n * n),
                      np.concatenate([np.zeros(2 * n), POINT_CONSTANTS]), np.zeros(2 * n + 1))


def chord_memory(s: int, n: int) -> ChordMemory:
    """The memory of s substeps in dimension n (empty: every substep starts cold)."""
    return ChordMemory(np.zeros((s, HISTORY, n)), np.zeros(s, np.int64), np.zeros((s, n, n)),
                       np.zeros(s, np.int64), np.ones(s), np.zeros(s, np.int64), np.zeros(n), np.zeros((2, n)),
                       np.zeros(2, np.int64), np.zeros(2), np.zeros(1))


# ----------------------------------------------------------------------------------------------
# compiled


@nb.njit(inline="always", **NJIT_NORC)
def _point(y0, form, work, n):
    """work.xbar (x with alpha(x, p) = y0) and work.dy (y1 - y0) from work.z (see the module);
    returns Failure.OK or the series' failure."""
    if form.kind == LIE_POISSON and form.rotation != 0.0 and n == 6:
        return se3_point(y0, form, work)
    if form.kind == LIE_POISSON and form.rotation != 0.0:
        return rotation_point(y0, form, work)
    if form.kind == LIE_POISSON and form.diagonal.shape[0] > 0 and form.point_at != 0:
        return generated_diagonal_point(y0, form, work, n)
    if form.kind == LIE_POISSON and form.diagonal.shape[0] > 0:
        return diagonal_point(y0, form, work, n)
    if form.kind == LIE_POISSON:
        return exp_series(y0, form, work, n)
    M = form.matrix
    for i in range(n):
        u = 0.0
        for j in range(n):
            u += M[i, j] * work.z[j]
        if form.kind == CONSTANT:
            work.xbar[i] = y0[i] + 0.5 * u
            work.dy[i] = u
        else:
            work.xbar[i] = y0[i] * math.exp(0.5 * u)
            work.dy[i] = y0[i] * math.expm1(u)
    return Failure.OK


@nb.njit(inline="always", **NJIT_NORC)
def _target(hs, form, work, n):
    """work.res := G(work.xbar) (see the module) with step hs."""
    gradient(form, work, work.xbar, n)
    for k in range(n):
        gk = hs * work.g[k]
        work.res[k] = work.xbar[k] * gk if form.kind == LOG_CANONICAL else gk


@nb.njit(**NJIT_NORC)
def _refresh_chord_z(i, y0, hs, form, work, memory, n):
    """Substep i's chord matrix M = I - G'(y0) x'(0) with step hs (x'(0) = pi(y0) / 2, or
    diag(y0) lambda / 2 for log-canonical), its inverse into the memory (its contraction, until
    measured, taken as REFRESH_CONTRACTION); Failure.OK or SINGULAR."""
    memory.rate[i] = REFRESH_CONTRACTION  # until measured: a bound that triggers no rebuild
    D, x = work.jac, work.xz
    for k in range(n):
        x[k] = y0[k]
    for a in range(n):
        for b in range(n):
            D[a, b] = 0.0
    if form.kind == LIE_POISSON:
        # x'(0) = pi(y0) / 2, pi(y0)_ij = sum_k C_ijk y0_k = -sum_k coefs y0_k
        for e in range(form.pairs.shape[0]):
            row, k = form.pairs[e, 0], form.pairs[e, 1]
            for r in range(form.starts[e], form.starts[e + 1]):
                D[row, form.cols[r]] -= 0.5 * form.coefs[r] * y0[k]
    else:
        for a in range(n):
            for b in range(n):
                D[a, b] = 0.5 * form.matrix[a, b] * (x[a] if form.kind == LOG_CANONICAL else 1.0)
    return _store_inverse(i, hs, form, work, memory, n)


@nb.njit(inline="always", **NJIT_NORC)
def _exact_factors(i, y0, hs, form, work, memory, n):
    """The LU factors (in memory.inverse[i], row order work.perm) of substep i's exact Jacobian of
    z - G(x(z)) at z = work.z, I - G'(x) x'(z): called right after `_point` at that z (x =
    work.xbar, kept), with x'(z) = pi / 2 (constant), diag(x) lambda / 2 (log-canonical) or
    `rotation_jacobian` (so(3)*). Failure.OK or SINGULAR."""
    memory.refreshes[i] += 1
    D, x = work.jac, work.xz
    for k in range(n):
        x[k] = work.xbar[k]
    if form.kind == LIE_POISSON:
        rotation_jacobian(y0, form, work, D)
    else:
        for a in range(n):
            for b in range(n):
                D[a, b] = 0.5 * form.matrix[a, b] * (x[a] if form.kind == LOG_CANONICAL else 1.0)
    _jacobian_matrix(i, hs, form, work, memory, n)
    for k in range(n):
        work.xbar[k] = x[k]
    if not lu_factor(memory.inverse[i], work.perm):
        return Failure.SINGULAR
    return Failure.OK


@nb.njit(inline="always", **NJIT_NORC)
def _jacobian_matrix(i, hs, form, work, memory, n):
    """memory.inverse[i] := I - hs G'(x) D with G'(x) = Hess H(x) (constant, lie-poisson) or
    diag(grad H(x)) + diag(x) Hess H(x) (log-canonical), x = work.xz, D = work.jac (x'). Hess H is
    the constant one of the form for a quadratic H, else the compiled one (`ClosedForm.
    derivatives_at`) or, without it, by differences of the gradient
    (`rkhp.integrators.direct_form.hessian`)."""
    D, H, x = work.jac, work.hess, work.xz
    if form.hessian_constant:
        for a in range(n):
            for b in range(n):
                H[a, b] = form.hessian[a, b]
        if form.kind == LOG_CANONICAL:
            gradient(form, work, x, n)
    elif form.derivatives_at != 0 and form.exact:
        call_at(form.derivatives_at, x, work.derivs, 1)
        for a in range(n):
            work.g[a] = work.derivs[a]
            for b in range(n):
                H[a, b] = work.derivs[n + n * a + b]
    else:
        hessian(form, work, x, n)
        if form.kind == LOG_CANONICAL:
            gradient(form, work, x, n)
    if form.kind == LOG_CANONICAL:
        # G'(x) = h (diag(grad H) + diag(x) Hess H)
        for a in range(n):
            for b in range(n):
                H[a, b] *= x[a]
            H[a, a] += work.g[a]
    M = memory.inverse[i]
    for a in range(n):  # row a of M: e_a - sum_r hs H[a, r] D[r], rows of D contiguous
        for b in range(n):
            M[a, b] = 1.0 if a == b else 0.0
        for r in range(n):
            c = hs * H[a, r]
            if c != 0.0:
                for b in range(n):
                    M[a, b] -= c * D[r, b]


@nb.njit(**NJIT_NORC)
def _store_inverse(i, hs, form, work, memory, n):
    """Substep i's chord matrix (`_jacobian_matrix`) inverted in place (memory.inverse[i],
    transposed: `rkhp.taylor.linalg.inverse_transposed`, work.jac its work space), marked ready.
    Failure.OK or SINGULAR."""
    memory.refreshes[i] += 1
    _jacobian_matrix(i, hs, form, work, memory, n)
    if not inverse_transposed(memory.inverse[i], work.perm, work.jac):
        return Failure.SINGULAR
    memory.ready[i] = 1
    return Failure.OK


@nb.njit(inline="always", **NJIT_NORC)
def _predict_z(i, y0, hs, form, work, memory, n):
    """work.z from substep i's previous solutions, or G(y0) without any: their polynomial
    extrapolation in the step index (`rkhp.integrators.direct_form.weight`, kept in memory.z_pred)
    plus hs times the defect the two substeps before give at this substep's time (`_remember_z`):
    extrapolated linearly in the time where both extrapolated from as many solutions and this
    substep lies within DEFECT_REACH times their distance in time from the last, else the last
    one's defect alone where that one did. A substep's solution is hs times a smooth function of
    the time, z = hs g(t + c h) (z = hs grad H(x), or x o hs grad H(x), x at a time c h into the
    step), so the error of its extrapolation per unit of step is one smooth function of the
    time, E(t + c h), for every substep: the last defect leaves an error O(h) times the
    extrapolation's, the line through the last two O(h^2) (docs/compositions.md "The cost of a
    substep")."""
    count = memory.count[i]
    if count == 0:
        for k in range(n):
            work.xbar[k] = y0[k]
        _target(hs, form, work, n)
        for k in range(n):
            work.z[k] = work.res[k]
        return
    shift = hs if memory.defect_order[0] == count else 0.0
    slope = 0.0
    if shift != 0.0 and memory.defect_order[1] == count:
        span = memory.defect_time[0] - memory.defect_time[1]
        ahead = memory.clock[0] + 0.5 * hs - memory.defect_time[0]
        if abs(ahead) < DEFECT_REACH * abs(span):  # never with span 0 (a step and its inverse)
            slope = ahead / span
    for k in range(n):
        acc = 0.0
        for r in range(count):
            acc += weight(count, r) * memory.z_hist[i, r, k]
        memory.z_pred[k] = acc
        last = memory.defect[0, k]
        work.z[k] = acc + shift * (last + slope * (last - memory.defect[1, k]))


@nb.njit(inline="always", **NJIT_NORC)
def _remember_z(i, hs, memory, work, n):
    """Push the converged z of substep i (step hs) into its history, after keeping its
    extrapolation's defect (z - memory.z_pred) / hs and its midpoint time for the next substeps'
    starts (`_predict_z`, the defect before it kept as the second); the clock advances by hs."""
    count = memory.count[i]
    memory.defect_order[1] = memory.defect_order[0]
    memory.defect_time[1] = memory.defect_time[0]
    memory.defect_order[0] = count if hs != 0.0 else 0
    memory.defect_time[0] = memory.clock[0] + 0.5 * hs
    memory.clock[0] += hs
    for k in range(n):
        memory.defect[1, k] = memory.defect[0, k]
    if count > 0 and hs != 0.0:
        for k in range(n):
            memory.defect[0, k] = (work.z[k] - memory.z_pred[k]) / hs
    for r in range(HISTORY - 1, 0, -1):
        for k in range(n):
            memory.z_hist[i, r, k] = memory.z_hist[i, r - 1, k]
    for k in range(n):
        memory.z_hist[i, 0, k] = work.z[k]
    memory.count[i] = min(memory.count[i] + 1, HISTORY)


@nb.njit(inline="always", **NJIT_NORC)
def _chord_correction(B, work, n):
    """work.step := B work.res, B stored transposed (B[c] is column c of the inverse): beyond
    BROYDEN_DIMENSION the sum of the columns times the residual (`transposed_product`); up to it
    n dot products, independent sums of a few terms (measured faster there, where a vector is
    shorter than the loops' overhead)."""
    if n <= BROYDEN_DIMENSION:
        for k in range(n):
            acc = 0.0
            for c in range(n):
                acc += B[c, k] * work.res[c]
            work.step[k] = acc
        return
    transposed_product(B, work.res, work.step, n)


@nb.njit(inline="always", **NJIT_NORC)
def _broyden(B, work, n):
    """Broyden's update of the inverse ~ F'(z)^-1 (F(z) = z - G(x(z)), residual r = -F), stored
    transposed in B (`_chord_correction`), from the last correction s = work.step and the change
    of F, q = work.last - work.res: B^-1 += u (s^T B^-1), u = (s - B^-1 q) / (s^T B^-1 q),
    skipped when s^T B^-1 q vanishes; in the transposed store, row c gains (column c of B^-1 . s)
    u."""
    for k in range(n):
        acc = 0.0
        for c in range(n):
            acc += B[c, k] * (work.last[c] - work.res[c])
        work.by[k] = acc
    den = 0.0
    for a in range(n):
        den += work.step[a] * work.by[a]
    if not abs(den) > 0.0:
        return
    for a in range(n):
        work.by[a] = (work.step[a] - work.by[a]) / den
    for c in range(n):
        v = 0.0
        for a in range(n):
            v += B[c, a] * work.step[a]
        for a in range(n):
            B[c, a] += v * work.by[a]


@nb.njit(inline="always", **NJIT_NORC)
def _sweeps_z(y0, hs, form, work, n, tol, stagnation):
    """Fixed-point sweeps z := G(x(z)) from work.z while `rkhp.integrators.direct_form.
    sweep_verdict` lets them go on: returns (sweeps, whether they converged; a sweep it undoes is
    not counted). Where x(z) fails they stop, z unchanged: the chord iteration that follows meets
    the failure at the same z and reports it."""
    previous = np.inf
    sweeps = 0
    while sweeps < MAX_PICARD:
        if _point(y0, form, work, n) != Failure.OK:
            return sweeps, False
        _target(hs, form, work, n)
        size = 0.0
        for k in range(n):
            d = abs(work.res[k] - work.z[k])
            work.last[k] = work.z[k]
            work.z[k] = work.res[k]
            if not d <= size:
                size = d
        sweeps += 1
        verdict = sweep_verdict(sweeps, size, previous, tol, stagnation, PICARD_RATE)
        if verdict == SWEEP_UNDO:
            for k in range(n):
                work.z[k] = work.last[k]
            return sweeps - 1, False
        if verdict != SWEEP_ON:
            return sweeps, verdict == SWEEP_CONVERGED
        previous = size
    return sweeps, False


@nb.njit(inline="always", **NJIT_NORC)
def closed_substep(i, y0, hs, form, work, memory, solver):
    """One Euler substep of step hs in direct form from y0 (substep i of the composition, its
    memory): its increment y1 - y0 into work.dy.

    Starts from the extrapolated z; iterates z += B r, r = G(x(z)) - z, B updated by `_broyden`
    from the second iteration on (n <= BROYDEN_DIMENSION); builds B afresh at the substep's first
    call, when its last measured contraction exceeds REFRESH_CONTRACTION, and when an iteration
    contracts by more than SLOW_CONTRACTION (once per substep). Stops when the correction, or
    from the second iteration on its predicted successor t / (1 - t) |d| (t = RATE_MARGIN theta,
    theta the measured contraction: Broyden's iterations contract unevenly; without the margin, a
    constant pi's step stopped 4e-15 off the midpoint equation), is at most solver.tol
    max(1, |y0|), or when corrections at round-off stop halving
    (`rkhp.integrators.direct_form.STAGNATION`); then x and y1 are taken at the final z. The
    first iteration predicts nothing: the previous step's first contraction, which the spray's
    direct form uses there, is no bound once Broyden's update has improved B (measured below 1e-4
    on the rigid body). A substep without previous solutions first sweeps (`_sweeps_z`), B built
    and iterated only where the sweeps did not converge. Returns (Failure, iterations, sweeps)."""
    n = y0.shape[0]
    scale = max(1.0, max_abs(y0))
    _predict_z(i, y0, hs, form, work, memory, n)
    sweeps, converged = 0, False
    if memory.count[i] == 0:
        sweeps, converged = _sweeps_z(y0, hs, form, work, n, solver.tol * scale, STAGNATION * scale)
    fresh = False
    if not converged and (memory.ready[i] == 0 or memory.rate[i] > REFRESH_CONTRACTION):
        cause = _refresh_chord_z(i, y0, hs, form, work, memory, n)
        if cause != Failure.OK:
            return cause, 0, sweeps
        fresh = True
    previous = np.inf
    since = 0
    it = 0
    while not converged and it < solver.max_iter:
        it += 1
        since += 1
        cause = _point(y0, form, work, n)
        if cause != Failure.OK:
            return cause, it, sweeps
        _target(hs, form, work, n)
        for k in range(n):
            work.res[k] -= work.z[k]
        if n <= BROYDEN_DIMENSION and since >= 2 and previous > BROYDEN_FLOOR * scale:
            _broyden(memory.inverse[i], work, n)
        _chord_correction(memory.inverse[i], work, n)
        size = 0.0
        for k in range(n):
            acc = work.step[k]
            work.last[k] = work.res[k]
            work.z[k] += acc
            if not abs(acc) <= size:
                size = abs(acc)
        if not size < np.inf:
            return Failure.NEWTON_NON_FINITE, it, sweeps
        if size > 1e8 * scale:
            return Failure.NEWTON_DIVERGED, it, sweeps
        theta = size / previous if since >= 2 else np.inf  # no prediction from one correction
        if since == 2:
            memory.rate[i] = theta
        bound = RATE_MARGIN * theta
        predicted = bound / (1.0 - bound) * size if bound < 0.5 else np.inf
        if size <= solver.tol * scale or predicted <= solver.tol * scale:
            converged = True
            break
        if since >= 2 and size >= 0.5 * previous and size <= STAGNATION * scale:
            converged = True
            break
        floor = max(1e3 * solver.tol, REFRESH_FLOOR) * scale
        if since >= 2 and not fresh and theta > SLOW_CONTRACTION and size > floor:
            fresh = True
            cause = _refresh_chord_z(i, y0, hs, form, work, memory, n)
            if cause != Failure.OK:
                return cause, it, sweeps
            since = 0
        previous = size
    if not converged:
        return Failure.NEWTON_NO_CONVERGENCE, it, sweeps
    cause = _point(y0, form, work, n)
    if cause != Failure.OK:
        return cause, it, sweeps
    _remember_z(i, hs, memory, work, n)
    return Failure.OK, it, sweeps


@nb.njit(inline="always", **NJIT_NORC)
def newton_substep(i, y0, hs, form, work, memory, solver):
    """One Euler substep of step hs in direct form from y0 by Newton's method (form.exact): its
    increment y1 - y0 into work.dy; returns (Failure, iterations).

    Starts from the extrapolated z (`_predict_z`); each iteration evaluates x(z), factorises the
    exact Jacobian there (`_exact_factors`) when the last correction exceeded NEWTON_REFRESH max(1, |y0|)
    (always at the first: a Newton step; below it a chord step with the last Jacobian, which
    already contracts by about L |d|), and corrects z by the Jacobian's inverse times G(x(z)) - z.
    Stops when the correction is at most solver.tol max(1, |y0|), or when the next one is
    predicted to be: 2 L |d|^2 after two Newton steps (L = |d_k| / |d_(k-1)|^2, the quadratic
    constant just measured), theta / (1 - theta) |d| (theta = RATE_MARGIN |d_k| / |d_(k-1)|)
    after a chord step; or when corrections at round-off stop halving (STAGNATION). Then x and
    y1 are taken at the final z."""
    n = y0.shape[0]
    scale = max(1.0, max_abs(y0))
    _predict_z(i, y0, hs, form, work, memory, n)
    previous = np.inf
    newton = False  # whether the last correction was a Newton step
    refresh = True
    it = 0
    converged = False
    while it < solver.max_iter:
        it += 1
        cause = _point(y0, form, work, n)
        if cause != Failure.OK:
            return cause, it
        was_newton = newton
        newton = refresh
        if refresh:
            cause = _exact_factors(i, y0, hs, form, work, memory, n)
            if cause != Failure.OK:
                return cause, it
        _target(hs, form, work, n)
        for k in range(n):
            work.res[k] -= work.z[k]
        lu_solve(memory.inverse[i], work.perm, work.res, work.tmp)
        size = 0.0
        for k in range(n):
            work.z[k] += work.res[k]
            if not abs(work.res[k]) <= size:
                size = abs(work.res[k])
        if not size < np.inf:
            return Failure.NEWTON_NON_FINITE, it
        if size > 1e8 * scale:
            return Failure.NEWTON_DIVERGED, it
        if newton and was_newton:
            predicted = 2.0 * size / (previous * previous) * size * size
        elif it >= 2:
            bound = RATE_MARGIN * size / previous
            predicted = bound / (1.0 - bound) * size if bound < 0.5 else np.inf
        else:
            predicted = np.inf
        if size <= solver.tol * scale or predicted <= solver.tol * scale:
            converged = True
            break
        if it >= 2 and size >= 0.5 * previous and size <= STAGNATION * scale:
            converged = True
            break
        refresh = size > NEWTON_REFRESH * scale
        previous = size
    if not converged:
        return Failure.NEWTON_NO_CONVERGENCE, it
    cause = _point(y0, form, work, n)
    if cause != Failure.OK:
        return cause, it
    _remember_z(i, hs, memory, work, n)
    return Failure.OK, it


@nb.njit(inline="always", **NJIT_NORC)
def resume(data, y0):
    """The state set to y0 (work.y, carried as the double-double y + y_low,
    `rkhp.integrators.direct_form.add_increment`), every substep's memory kept but the last
    substeps' defects (`_predict_z`: the next substep does not follow them in time) and the
    clock, from 0 again (so that a run on memory used before rounds its times as on new)."""
    work = data.work
    for k in range(y0.shape[0]):
        work.y[k] = y0[k]
        work.y_low[k] = 0.0
    data.memory.defect_order[0] = 0
    data.memory.defect_order[1] = 0
    data.memory.clock[0] = 0.0


@nb.njit(inline="always", **NJIT_NORC)
def begin(data, y0):
    """Start a run at y0 (`resume`), every substep's memory emptied."""
    resume(data, y0)
    memory = data.memory
    for i in range(memory.count.shape[0]):
        memory.count[i] = 0
        memory.ready[i] = 0
        memory.rate[i] = 1.0
        memory.refreshes[i] = 0
    return 0


@nb.njit(inline="always", **NJIT_NORC)
def substep(data, context, i, hs, solver):
    """Substep i of size hs in direct form (`newton_substep` where the form is exact, else
    `closed_substep`), its increment added to the state
    without rounding it (`add_increment`); returns (Failure, iterations, sweeps)."""
    work, form = data.work, data.form
    sweeps = 0
    if form.exact:
        cause, it = newton_substep(i, work.y, hs, form, work, data.memory, solver)
    else:
        cause, it, sweeps = closed_substep(i, work.y, hs, form, work, data.memory, solver)
    if cause == Failure.OK:
        add_increment(work.y, work.y_low, work.dy, work.y.shape[0])
    return cause, it, sweeps


# ----------------------------------------------------------------------------------------------
# Python


_FORMS: weakref.WeakKeyDictionary = weakref.WeakKeyDictionary()
"""`closed_form` of the systems seen, while they live."""


def _lie_entries(C: np.ndarray):
    """K(p)'s entries that are not identically zero, as `ClosedForm`'s pairs, starts, cols, coefs."""
    n = C.shape[0]
    pairs, starts, cols, coefs = [], [0], [], []
    for i in range(n):
        for k in range(n):
            js = np.flatnonzero(C[i, :, k])
            if js.size:
                pairs.append((i, k))
                cols += js.tolist()
                coefs += (-C[i, js, k]).tolist()
                starts.append(len(cols))
    return (np.array(pairs, np.int64).reshape(-1, 2), np.array(starts, np.int64),
            np.array(cols, np.int64), np.array(coefs, np.float64))


def closed_form(system) -> ClosedForm:
    """The data of the direct form for a system of the constant, lie-poisson or log-canonical
    family with the symmetric realisation (the family's base birealisation itself); InputError
    otherwise. The structure is read back from the system's pi, which is constant, linear
    (pi(x)_ij = sum_k C_ijk x_k) or lambda_ij x_i x_j on these families. Kept per system (a run
    of a few steps spends its time in Python, and the choice of the substep provider and the run
    each ask for it)."""
    form = _FORMS.get(system)
    if form is None:
        form = _FORMS[system] = _read_form(system)
    return form


def _read_form(system) -> ClosedForm:
    """`closed_form`, read from the system."""
    if system.family not in KINDS or system.realisation != "symmetric":
        raise InputError(f"{system.name}: the closed-form direct Euler step needs the family "
                         f"constant, lie-poisson or log-canonical with the symmetric realisation; "
                         f"this system is {system.family}, realisation {system.realisation}")
    h = system.h_tape
    if h.main != 0 or any(int(code) not in SCALAR_CODES for code in h.ops[:, 0]):
        raise InputError(f"{system.name}: the direct Euler step evaluates + - * / and the "
                         f"functions of mathematical text; the Hamiltonian's tape holds another "
                         f"operation")
    n, kind = system.dim, KINDS[system.family]
    matrix = np.zeros((n, n))
    C = np.zeros((n, n, n))
    if kind == CONSTANT:
        matrix = np.array(system.poisson(np.zeros(n)), dtype=np.float64)
    elif kind == LOG_CANONICAL:
        matrix = np.array(system.poisson(np.ones(n)), dtype=np.float64)
    else:
        for k in range(n):
            C[:, :, k] = system.poisson(np.eye(n)[k])
    entries = _lie_entries(C)
    rotation = _rotation_scale(C) if kind == LIE_POISSON else 0.0
    diagonal = _diagonal_entries(entries[0], n) if kind == LIE_POISSON and rotation == 0.0 else np.zeros(0, np.int64)
    tape = shared(Tape(*h))
    quadratic = polynomial_degree(tape) <= 2
    newton = (rotation != 0.0 and n == 3) or (kind != LIE_POISSON and n <= EXACT_DIMENSION)
    address = derivatives_at(system, hessian=newton and not quadratic)
    exact = newton and (quadratic or address != 0)
    point_at = diagonal_point_at(*entries, diagonal, n) if diagonal.size else 0
    form = ClosedForm(kind, np.ascontiguousarray(matrix), *entries, tape, rotation, diagonal, exact, quadratic,
                      np.zeros((n, n)), address, point_at)
    if quadratic:
        _quadratic_hessian(form, closed_work(form, n), n)
    return form


def _quadratic_hessian(form: ClosedForm, work: ClosedWork, n: int) -> None:
    """form.hessian := the constant Hessian of a quadratic H, column k = grad H(e_k) - grad H(0)
    (exact for a quadratic, up to the rounding of the gradients)."""
    gradient(form, work, np.zeros(n), n)
    at_zero = work.g.copy()
    for k in range(n):
        gradient(form, work, np.eye(n)[k], n)
        form.hessian[:, k] = work.g - at_zero


def _rotation_scale(C: np.ndarray) -> float:
    """s when the structure constants are those of so(3) or se(3) scaled: C = -s epsilon on
    so(3); on se(3), x = (M, Gamma), C = -s epsilon on the (M, M, M) and (M, Gamma, Gamma) blocks
    and +s epsilon on (Gamma, M, Gamma) (the heavy top's). Then K(z) = hat(s z), or
    [[hat(q), hat(r)], [0, hat(q)]] with (q, r) = s z (`ClosedForm.rotation`); else 0."""
    if C.shape not in ((3, 3, 3), (6, 6, 6)):
        return 0.0
    epsilon = np.zeros((3, 3, 3))
    for i, j, k in ((0, 1, 2), (1, 2, 0), (2, 0, 1)):
        epsilon[i, j, k], epsilon[i, k, j] = 1.0, -1.0
    unit = -epsilon
    if C.shape == (6, 6, 6):
        unit = np.zeros((6, 6, 6))
        unit[:3, :3, :3] = unit[:3, 3:, 3:] = -epsilon
        unit[3:, :3, 3:] = epsilon.transpose(1, 0, 2)
    s = -float(C[0, 1, 2])
    return s if s != 0.0 and np.array_equal(C, s * unit) else 0.0


def _diagonal_entries(pairs: np.ndarray, n: int) -> np.ndarray:
    """`ClosedForm.diagonal` from K's entries (pairs (i, k)): the entry of K_kk per k (-1 where
    none) when K is diagonal on the set A of its non-zero columns and zero on the others (every
    entry (i, k) off the diagonal has its row i outside A), else an empty array."""
    columns = set(pairs[:, 1].tolist())
    if any(i != k and i in columns for i, k in pairs.tolist()):
        return np.zeros(0, np.int64)
    diagonal = np.full(n, -1, np.int64)
    for e, (i, k) in enumerate(pairs.tolist()):
        if i == k:
            diagonal[k] = e
    return diagonal


def closed_form_available(system) -> bool:
    """Whether `closed_form` accepts `system`."""
    try:
        closed_form(system)
    except InputError:
        return False
    return True


class ClosedSubstep(NamedTuple):
    """What the direct form's substeps of one run use: the system's `ClosedForm`, the work arrays
    and the memory of the composition's substeps; the state the substeps advance, y (work.y, the
    high part of the double-double y + y_low)."""

    form: ClosedForm
    work: ClosedWork
    memory: ChordMemory
    y: np.ndarray


def closed_substep_data(system, substeps: int) -> ClosedSubstep:
    """The data of `substeps` direct-form substeps on `system` (InputError for a system that
    `closed_form` refuses)."""
    form = closed_form(system)
    work = closed_work(form, system.dim)
    return ClosedSubstep(form, work, chord_memory(substeps, system.dim), work.y)


def closed_extra(data: ClosedSubstep) -> dict:
    """What a run reports of its direct-form substeps: how often each rebuilt its chord matrix."""
    return {"refreshes": data.memory.refreshes.tolist()}
