"""What the direct forms of the RKHP Euler step share (`rkhp.integrators.closed_euler`,
`rkhp.integrators.spray_euler`; docs/theory.md §9, §12): the constants of their iterations, H's
gradient and Hessian at a point, the extrapolated start from a substep's previous solutions, and
the state kept as a double-double.

`gradient` and `hessian` take the provider's tapes (a NamedTuple whose field ``hamiltonian`` is
H's plain tape over (x, p), and ``derivatives_at`` the address of H's derivatives compiled for
the system, 0 for none: `rkhp.integrators.derivatives`) and work arrays (fields W, g, hess,
xbar).
"""

from __future__ import annotations

import math

import numpy as np

from ..taylor.compiler import NJIT_NORC
from ..taylor.compiler import numba as nb
from ..taylor.generated import call_at
from ..taylor.scalar import gradients

RATE_MARGIN = 2.0
"""Safety factor on a substep's last measured contraction when it predicts the second correction
from the first (so that one iteration can suffice)."""
SLOW_CONTRACTION = 0.25
"""A chord iteration contracting by more than this refreshes the substep's matrix (once per
substep; as the engine's Newton iteration, `rkhp.integrators.engine.rkhp_step`). The matrix is
kept across steps: it goes stale by O(h) a step, which the first iteration of a step feels (its
p-columns: measured 0.05 on nambu at h = 0.1 even just after a refresh), the later ones less."""
MAX_PICARD = 30
"""Fixed-point sweeps of a substep at most (`rkhp.integrators.spray_euler._sweeps`,
`rkhp.integrators.closed_euler._sweeps_z`); the chord iterations go on from there."""
PICARD_RATE = 0.25
"""The fixed-point sweeps give way to the chord iterations when a sweep's change exceeds this
times the one before: a sweep then gains less than 0.6 decades, where a chord iteration with a
kept matrix gains 1.3 to 1.7 (contraction 0.02 to 0.05) at the price of the sweep and a product
with the matrix's inverse."""
HESSIAN_STEP = 2.0**-17
"""Relative step of the central differences that give Hess H for the chord matrix."""
STAGNATION = 64 * 2.0**-52
"""Corrections at most this (relative to max(1, |y0|)) that no longer halve are round-off: the
iterations have converged as far as float64 allows."""
DIRECT_TOLERANCE = 2.0**-60
"""The chord iterations' default tolerance (relative): below round-off, so that they run until
the corrections stagnate (`STAGNATION`). Stopping at 1e-15 left the stages off the collocation
solution by that much, which moves a non-quadratic Casimir systematically (docs/general-poisson.md
"The Euler step in direct form"); stopping at a quarter of a unit of round-off (2^-54) leaves a
symmetric composition run forward and back an order of magnitude further from its start on the
charged particle and toda:12."""
REFRESH_FLOOR = 1e3 * DIRECT_TOLERANCE
"""No new matrix for a correction at most max(1e3 tol, this) (relative to max(1, |y0|)): at the
default tolerance 1e3 tol, about four units of round-off, where the corrections no longer
measure a contraction (they wander at round-off, in cycles that a new matrix each iteration
would keep from stagnating); so a tolerance below the default iterates to stagnation."""
HISTORY = 4
"""Previous solutions of a substep kept for the closed form's extrapolated start (cubic: on the
charged particle at h = 0.1, step 11, a cubic start erred by 8.3e-7 against 7.4e-6 for a
quadratic, one chord iteration fewer; six, a quintic, gained no iteration on toda:12 and the heavy
top at the race's settings); the spray's form keeps its own, `rkhp.integrators.spray_euler.
HISTORY`."""


@nb.njit(inline="always", **NJIT_NORC)
def gradient(tapes, work, x, n):
    """grad H(x) into work.g: compiled for the system where it is (x C-contiguous), else by forward
    mode on the tape (`rkhp.taylor.scalar.gradients`)."""
    if tapes.derivatives_at != 0:
        call_at(tapes.derivatives_at, x, work.g, 0)
        return
    W = work.W
    for k in range(n):
        for m in range(1, n + 1):
            W[k, m] = 1.0 if m == 1 + k else 0.0
            W[n + k, m] = 0.0
        W[k, 0] = x[k]
        W[n + k, 0] = 0.0
    gradients(tapes.hamiltonian, W, n)
    out = tapes.hamiltonian.outputs[0]
    for k in range(n):
        work.g[k] = W[out, 1 + k]


SWEEP_ON, SWEEP_CONVERGED, SWEEP_UNDO, SWEEP_SLOW = 0, 1, 2, 3
"""`sweep_verdict`'s answers: sweep again; converged; undo the last sweep (its change grew or is
not finite) and iterate with a chord matrix from there; iterate with a chord matrix from here."""


@nb.njit(inline="always", **NJIT_NORC)
def sweep_verdict(sweeps, size, previous, tol, stagnation, slow):
    """What a direct form's fixed-point sweeps do after their sweep number `sweeps` changed the
    unknowns by `size` (largest component; the sweep before by `previous`), with the stop tests
    of the chord iterations (tol and stagnation absolute): converged when the change, or its
    predicted successor theta / (1 - theta) size (theta = size / previous), is at most tol, or
    when changes at most `stagnation` stop halving; the chord iterations take over where a change
    grows (the sweep undone) or, above `stagnation` (below it the changes are round-off, not a
    contraction), contracts by more than `slow` (PICARD_RATE, or the spray's own threshold,
    `rkhp.integrators.spray_euler.SLOW_SWEEPS`)."""
    if not size < np.inf:
        return SWEEP_UNDO
    if size <= tol or (sweeps >= 2 and size >= 0.5 * previous and size <= stagnation):
        return SWEEP_CONVERGED
    if size > previous:
        return SWEEP_UNDO
    if sweeps >= 2:
        theta = size / previous
        if theta < 0.5 and theta / (1.0 - theta) * size <= tol:
            return SWEEP_CONVERGED
        if theta > slow and size > stagnation:
            return SWEEP_SLOW
    return SWEEP_ON


@nb.njit(**NJIT_NORC)
def hessian(tapes, work, x, n):
    """Hess H(x) into work.hess by central differences of the gradient, steps
    HESSIAN_STEP max(1, |x_k|) (error about 1e-10 relative: the chord matrix needs no more), made
    symmetric; work.xbar is overwritten."""
    H, xs = work.hess, work.xbar
    for k in range(n):
        xs[k] = x[k]
    for k in range(n):
        step = HESSIAN_STEP * max(1.0, abs(x[k]))
        xs[k] = x[k] + step
        gradient(tapes, work, xs, n)
        for r in range(n):
            H[r, k] = work.g[r]
        xs[k] = x[k] - step
        gradient(tapes, work, xs, n)
        for r in range(n):
            H[r, k] = (H[r, k] - work.g[r]) / (2.0 * step)
        xs[k] = x[k]
    for k in range(n):
        for r in range(k):
            H[r, k] = H[k, r] = 0.5 * (H[r, k] + H[k, r])



def _extrapolation_weights(most: int) -> np.ndarray:
    """WEIGHTS for counts up to `most`."""
    table = np.zeros((most + 1, most))
    for count in range(most + 1):
        for r in range(count):
            table[count, r] = (-1) ** r * math.comb(count, r + 1)
    return table


WEIGHTS = _extrapolation_weights(8)
"""WEIGHTS[count, r]: the weight of the r-th newest of `count` equally spaced values in their
polynomial extrapolation one step ahead, (-1)^r binom(count, r + 1) (exact integers), for
counts up to 8."""


@nb.njit(inline="always", **NJIT_NORC)
def weight(count, r):
    """WEIGHTS[count, r] (a table: computing the binomial at each use cost divisions in the
    innermost loop of the extrapolated start)."""
    return WEIGHTS[count, r]



@nb.njit(inline="always", **NJIT_NORC)
def add_increment(y, low, dy, n):
    """y + low += dy, the state kept as a double-double (Knuth's two-sum per component)."""
    for k in range(n):
        a, b = y[k], low[k] + dy[k]
        total = a + b
        bb = total - a
        y[k], low[k] = total, (a - (total - bb)) + (b - bb)
