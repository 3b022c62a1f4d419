"""Classical peers of the RKHP integrators, in the same harness (paper §5; docs/theory.md §4).

Both integrate the Poisson ODE ``xdot = f(x) = pi(x) grad H(x)`` of a
:class:`rkhp.systems.PoissonSystem` directly, without the birealisation:

- :func:`integrate_classical`: an explicit Runge–Kutta method with any explicit tableau (e.g. the
  classical RK4). It keeps neither the Casimirs nor the symplectic leaf; it is the baseline the
  RKHP methods are compared with in ``rkhp converge``, ``rkhp bench`` and ``rkhp stress``.
- :func:`integrate_midpoint`: the implicit midpoint rule, solved by Newton's method with a
  finite-difference Jacobian of ``f``. It equals RKHP Euler when ``pi`` is constant (docs/theory.md §5)
  and keeps quadratic Casimirs (e.g. ``|x|^2`` of the rigid body).

The whole loop is one numba-compiled function (cached on disk like the RKHP engine, see
:mod:`rkhp.taylor.compiler`), generic over systems: ``grad H`` is read off the system's
Hamiltonian tape evaluated in first-order jets, and ``pi(x) = D^T - D`` with
``D = d_p alpha(x, 0)`` off its alpha tape (docs/theory.md §4), so the tableau and the system are data.

Both return a :class:`~rkhp.integrators.trajectory.Trajectory`; a failure (Newton not converging,
non-finite values, leaving the system's domain) ends the run and is named in its status with the
step and the time, keeping only the states computed before it.
"""

from __future__ import annotations

import math
import time
from typing import NamedTuple

import numpy as np

from ..base.bounds import check_step
from ..base.errors import InputError, NumericalFailure
from ..taylor.compiler import NJIT
from ..taylor.compiler import numba as nb
from ..taylor.interpreter import TapeWork, address_of, as_plain, interpreter, run_from, tape_work
from ..taylor.jets import JetSpace, jet_space
from ..taylor.linalg import lu_factor, lu_solve
from ..taylor.tape import Tape
from .engine_state import state_failure
from .failure import Failure, failure_status
from .newton import NEWTON_TOLERANCE
from .trajectory import Trajectory, checked

MIDPOINT_MAX_ITERATIONS = 30
"""Newton iterations after which a step of the implicit midpoint rule is declared failed."""


class FieldWork(NamedTuple):
    """What the compiled field evaluates with: the H and alpha tapes (plain), first-order jets in
    n variables, and the interpreter's work arrays for each tape (`_workspace`)."""

    htape: Tape
    atape: Tape
    space: JetSpace
    wh: TapeWork
    wa: TapeWork


class FieldAt(NamedTuple):
    """The addresses of copies of a `FieldWork`'s members for `run_from`, taken once by the
    kernel that evaluates the field (`_field_addresses`)."""

    htape: object
    atape: object
    space: object
    wh: object
    wa: object


class CompiledField(NamedTuple):
    """The compiled field's arguments: the address of the interpreter of the system's class of
    tapes (`rkhp.taylor.interpreter.Interpreter.address`) and the work."""

    run: int
    work: FieldWork


# ----------------------------------------------------------------------------------------------
# compiled kernels


@nb.njit(inline="always", **NJIT)
def _field_addresses(ws):
    """`FieldAt` of `ws`, on the stack of the kernel this is inlined into (`address_of`)."""
    return FieldAt(address_of(ws.htape), address_of(ws.atape), address_of(ws.space),
                   address_of(ws.wh), address_of(ws.wa))


@nb.njit(inline="always", **NJIT)
def _field(x, run, ws, at, out):
    """out = pi(x) grad H(x) by the interpreter of the tapes' class at the address `run`, on the
    copies of `ws` at `at` (`_field_addresses`): grad H from the H tape, pi = D^T - D from the
    alpha tape."""
    htape, atape, wh, wa = ws.htape, ws.atape, ws.wh, ws.wa
    n = x.shape[0]
    Wh, Wa = wh.W, wa.W
    Wh[:, :] = 0.0
    Wa[:, :] = 0.0
    for i in range(n):
        Wh[i, 0] = x[i]
        Wh[i, 1 + i] = 1.0
        Wa[i, 0] = x[i]
        Wa[n + i, 1 + i] = 1.0
    run_from(run, at.htape, np.int64(1), at.space, at.wh)
    run_from(run, at.atape, np.int64(1), at.space, at.wa)
    ho = htape.outputs[0]
    ao = atape.outputs
    for i in range(n):
        acc = 0.0
        for j in range(n):
            acc += (Wa[ao[j], 1 + i] - Wa[ao[i], 1 + j]) * Wh[ho, 1 + j]
        out[i] = acc


@nb.njit(inline="always", **NJIT)
def _record(states, row, x):
    """states[row] := x, entry by entry (numpy's row assignment would compile its shape-error
    message: seconds of a cold start)."""
    for q in range(x.shape[0]):
        states[row, q] = x[q]


@nb.njit(**NJIT)
def _rk_loop(run, ws, A, b, h, n_steps, x0, domain, states):
    """Explicit RK steps; returns (steps done, Failure)."""
    at = _field_addresses(ws)
    n = x0.shape[0]
    s = b.shape[0]
    K = np.empty((s, n))
    xi = np.empty(n)
    x = x0.copy()
    _record(states, 0, x)
    for k in range(n_steps):
        for i in range(s):
            for q in range(n):
                xi[q] = x[q]
            for j in range(i):
                a = h * A[i, j]
                if a != 0.0:
                    for q in range(n):
                        xi[q] += a * K[j, q]
            _field(xi, run, ws, at, K[i])
        for i in range(s):
            w = h * b[i]
            if w != 0.0:
                for q in range(n):
                    x[q] += w * K[i, q]
        cause = state_failure(x, domain)
        if cause != Failure.OK:
            return k, cause
        _record(states, k + 1, x)
    return n_steps, Failure.OK


@nb.njit(**NJIT)
def _midpoint_loop(run, ws, h, n_steps, x0, domain, tol, max_it, states, newton):
    """Implicit midpoint steps, Newton on the midpoint; returns (steps done, Failure). The Newton
    matrix is factorised by the engine's LU pair (`rkhp.taylor.linalg`; numpy's det and inv
    would compile their LAPACK wrappers and shape-error messages: seconds of a cold start)."""
    at = _field_addresses(ws)
    n = x0.shape[0]
    x = x0.copy()
    m = np.empty(n)
    g = np.empty(n)
    fp = np.empty(n)
    fm = np.empty(n)
    J = np.empty((n, n))
    perm = np.empty(n, dtype=np.int64)
    tmp = np.empty(n)
    y = np.empty(n)
    _record(states, 0, x)
    for k in range(n_steps):
        _field(x, run, ws, at, g)
        for q in range(n):
            m[q] = x[q] + 0.5 * h * g[q]
        fresh = True
        previous = np.inf
        done = False
        for it in range(1, max_it + 1):
            newton[k] = it
            if state_failure(m, 0) != Failure.OK:
                return k, Failure.NEWTON_NON_FINITE
            if fresh:
                # Newton matrix I - (h/2) Df(m), central differences (step cbrt(eps) scaled)
                for j in range(n):
                    d = 6.055e-6 * max(1.0, abs(m[j]))
                    for q in range(n):
                        y[q] = m[q]
                    y[j] = m[j] + d
                    _field(y, run, ws, at, fp)
                    y[j] = m[j] - d
                    _field(y, run, ws, at, fm)
                    for q in range(n):
                        J[q, j] = (1.0 if q == j else 0.0) - 0.5 * h * (fp[q] - fm[q]) / (2.0 * d)
                if not lu_factor(J, perm):
                    return k, Failure.SINGULAR
                fresh = False
            _field(m, run, ws, at, g)
            size = 0.0
            scale = 1.0
            for q in range(n):
                y[q] = m[q] - x[q] - 0.5 * h * g[q]
            lu_solve(J, perm, y, tmp)
            for q in range(n):
                dq = y[q]
                if not math.isfinite(dq):
                    return k, Failure.NEWTON_NON_FINITE
                m[q] -= dq
                size = max(size, abs(dq))
                scale = max(scale, abs(m[q]))
            if size <= tol * scale or (size <= 1e-12 * scale and size >= previous):
                done = True
                break
            if size > 1e3 * scale:
                return k, Failure.NEWTON_DIVERGED
            if size > 0.25 * previous:
                fresh = True  # slow contraction: recompute the Newton matrix
            previous = size
        if not done:
            return k, Failure.NEWTON_NO_CONVERGENCE
        for q in range(n):
            x[q] = 2.0 * m[q] - x[q]
        cause = state_failure(x, domain)
        if cause != Failure.OK:
            return k, cause
        _record(states, k + 1, x)
    return n_steps, Failure.OK


# ----------------------------------------------------------------------------------------------
# Python API


def _workspace(system) -> CompiledField:
    """The address of the interpreter of the system's tapes (compiled or loaded from numba's
    cache here), and its H and alpha tapes, first-order jets in n variables and work arrays for
    each tape."""
    space = jet_space(system.dim, 1)
    ht, at = system.h_tape, system.alpha_tape
    work = FieldWork(as_plain(ht), as_plain(at), space, tape_work((ht,), space.size), tape_work((at,), space.size))
    return CompiledField(interpreter(ht).address, work)


_VERIFIED: set[str] = set()


def _verify_kernel(name: str, system, field: CompiledField) -> None:
    """Once per process and kernel, compare a compiled kernel with the system's own evaluation
    (``system.vector_field``, ``system.hamiltonian``, through ``rkhp.taylor.interpreter.evaluate``).

    numba checks only the time stamp of the file defining a cached function, not of the
    interpreter's files that it calls; :mod:`rkhp.taylor.compiler` names the cache folder by a
    hash of the sources, but a user's own NUMBA_CACHE_DIR kept across a source change would still
    serve stale code. This check turns that into an error, never into wrong numbers.
    """
    if name in _VERIFIED:
        return
    x = np.array(system.x0, dtype=np.float64)
    f = np.asarray(system.vector_field(x), dtype=np.float64)
    h = 1e-3
    states = np.empty((2, x.size))
    if name == "rk":
        _rk_loop(*field, np.zeros((1, 1)), np.ones(1), h, 1, x, 0, states)
        got, want = states[1], x + h * f
    else:
        _midpoint_loop(*field, h, 1, x, 0, NEWTON_TOLERANCE, MIDPOINT_MAX_ITERATIONS, states,
                       np.zeros(1, dtype=np.int64))
        got = states[1]
        want = x + h * np.asarray(system.vector_field((x + got) / 2), dtype=np.float64)
    scale = max(1.0, float(np.max(np.abs(want))))
    if not np.all(np.abs(got - want) <= 1e-12 * scale):
        raise NumericalFailure(f"compiled {name} kernel of rkhp.integrators.classical disagrees with {system.name}'s "
                               "own evaluation (stale numba cache after a source change?): delete the *.nbi/*.nbc "
                               "files of classical in the numba cache folder and run again")
    _VERIFIED.add(name)


def _compiled(kernel) -> bool:
    return bool(kernel.signatures)


def _trajectory(system, method, h, k_done, cause, states, newton, started, compile_s, extra=None):
    failed = cause != Failure.OK
    n = k_done + 1
    return checked(Trajectory(times=h * np.arange(n, dtype=np.float64), states=states[:n].copy(),
                              newton_iterations=newton[:k_done + failed].copy(),
                              status=failure_status(cause, k_done, h, system.domain) if failed else "ok",
                              failed_step=k_done if failed else None, cause=cause,
                              compile_seconds=compile_s, run_seconds=time.perf_counter() - started - compile_s,
                              method=method, system=system.name, extra=extra or {}, poisson=system), system)


def _warm_up(kernel, args_of_one_step) -> float:
    """Compile ``kernel`` (or load it from the cache) by a one-step call; returns the seconds."""
    if _compiled(kernel):
        return 0.0
    start = time.perf_counter()
    kernel(*args_of_one_step)
    return time.perf_counter() - start


def integrate_classical(system, tableau, h, n_steps, x0=None) -> Trajectory:
    """Explicit Runge–Kutta on ``xdot = pi(x) grad H(x)`` with an explicit ``tableau``.

    Args:
        system: a PoissonSystem; tableau: an explicit :class:`rkhp.tableaux.tableau.Tableau`;
        h: step size (> 0); n_steps: number of steps (>= 1); x0: start (default ``system.x0``).

    Returns:
        A Trajectory (``newton_iterations`` all zero); a non-finite state or one outside the
        domain ends the run with a failure status. ``compile_seconds`` is the first call's
        compilation (or cache load), apart from ``run_seconds``.
    """
    h, n_steps = check_step(h, n_steps, system.dim)
    if not tableau.is_explicit:
        raise InputError(f"tableau {tableau.name} is {tableau.kind}; the classical peer needs an explicit one")
    # writable copies (a tableau's arrays are read-only): the array types of `_verify_kernel`'s call, so
    # that numba compiles one specialisation of the loop, not two
    A = np.array(tableau.A_float, dtype=np.float64)
    b = np.array(tableau.b_float, dtype=np.float64)
    x = system.start(x0)
    started = time.perf_counter()
    field = _workspace(system)
    domain = system.domain_code
    states = np.empty((n_steps + 1, x.size))
    loaded = time.perf_counter() - started  # the class's interpreter, compiled or loaded
    compile_s = loaded + _warm_up(_rk_loop, (*field, A, b, h, 1, x, domain, np.empty((2, x.size))))
    _verify_kernel("rk", system, field)
    k_done, cause = _rk_loop(*field, A, b, h, n_steps, x, domain, states)
    newton = np.zeros(n_steps, dtype=np.int64)
    return _trajectory(system, f"classical {tableau.name}", h, k_done, cause, states, newton, started, compile_s)


def integrate_midpoint(system, h, n_steps, x0=None) -> Trajectory:
    """The implicit midpoint rule ``x1 = x + h f((x + x1)/2)`` (order 2), Newton per step.

    Newton on the midpoint m, started at the explicit Euler predictor; the Newton matrix
    ``I - (h/2) Df(m)`` (central differences) is kept while corrections shrink at least 4-fold
    and recomputed otherwise. A step stops when the correction is below NEWTON_TOLERANCE
    max(1, |m|) (`rkhp.integrators.newton`, shared with RKHP and THP), or stagnates at round-off
    level (below 1e-12 max(1, |m|) and not smaller than the previous one); no convergence in
    MIDPOINT_MAX_ITERATIONS iterations, divergence or a non-finite iterate is a failure.

    Args:
        system: a PoissonSystem; h: step size (> 0); n_steps: number of steps;
        x0: start (default ``system.x0``).

    Returns:
        A Trajectory with the Newton iterations of every step and a status naming any failure.
    """
    h, n_steps = check_step(h, n_steps, system.dim)
    x = system.start(x0)
    started = time.perf_counter()
    field = _workspace(system)
    domain = system.domain_code
    states = np.empty((n_steps + 1, x.size))
    newton = np.zeros(n_steps, dtype=np.int64)
    tol, max_it = NEWTON_TOLERANCE, MIDPOINT_MAX_ITERATIONS
    loaded = time.perf_counter() - started  # the class's interpreter, compiled or loaded
    compile_s = loaded + _warm_up(_midpoint_loop, (*field, h, 1, x, domain, tol, max_it, np.empty((2, x.size)),
                                                   np.zeros(1, dtype=np.int64)))
    _verify_kernel("midpoint", system, field)
    k_done, cause = _midpoint_loop(*field, h, n_steps, x, domain, tol, max_it, states, newton)
    extra = {"newton_tolerance": tol, "newton_max_iterations": max_it}
    return _trajectory(system, "implicit midpoint", h, k_done, cause, states, newton, started, compile_s, extra)


