"""Seeded multistart: least-squares solves of the order conditions from random starts.

Restart k of a problem starts from ``numpy.random.default_rng([seed, stages, order, k])``, so every
restart is reproducible on its own, whatever the number of workers or the order they finish in.
A restart succeeds when scipy's least_squares (trust region, exact Jacobian) brings every residual
below 1e-6 with coefficients bounded by ``bound``, and Newton in mpmath then polishes it to D digits.
Restarts run on an executor (:mod:`rkhp.base.executors`: in process, local processes or a Dask cluster);
Ctrl-C cancels them and returns what was found.
"""

from __future__ import annotations

import time
from dataclasses import dataclass
from functools import lru_cache

import numpy as np

from ..base.executors import InProcess, first_done
from .polish import Polished, polish
from .system import ResidualSystem

#: A float64 solve is handed to the mpmath polish when every residual is below this (Newton
#: converges quadratically from there when the solution is regular; the polish decides).
FLOAT_TOLERANCE = 1e-6
#: Largest |coefficient| accepted: larger ones signal a solution escaping to infinity.
COEFFICIENT_BOUND = 20.0


@dataclass(frozen=True)
class Problem:
    """What is searched: ``stages``, conditions of ``cls`` up to ``order``, explicit or implicit."""

    stages: int
    order: int
    cls: str = "general"
    implicit: bool = False

    def system(self) -> ResidualSystem:
        return _system(self)


@lru_cache(maxsize=16)
def _system(problem: Problem) -> ResidualSystem:
    return ResidualSystem.build(problem.stages, problem.order, problem.cls, problem.implicit,
                                with_error=True)


@dataclass(frozen=True)
class Attempt:
    """One restart.

    Attributes:
        index: restart number k (its seed is [seed, stages, order, k]).
        residual: max |residual| reached in float64.
        x: the float64 end point (unknowns: a_ij by rows, then b).
        polished: the mpmath polish of a float64 candidate, else None.
        seconds: wall time of this restart.
    """

    index: int
    residual: float
    x: tuple[float, ...]
    polished: Polished | None
    seconds: float
    timed_out: bool = False

    @property
    def success(self) -> bool:
        return self.polished is not None and self.polished.converged


class _Cached:
    """Residuals and Jacobian at the last point, so least_squares' fun and jac share one pass."""

    def __init__(self, system: ResidualSystem, deadline: float | None = None):
        self.system = system
        self.deadline = deadline
        self.x = None
        self.value = None

    def _eval(self, x):
        if self.deadline is not None and time.time() > self.deadline:
            raise TimeLimitReached
        if self.x is None or not np.array_equal(x, self.x):
            self.x = x.copy()
            self.value = self.system.residuals(x)
        return self.value

    def fun(self, x):
        return self._eval(x)[0]

    def jac(self, x):
        return self._eval(x)[1]


def start_point(problem: Problem, seed: int, index: int) -> np.ndarray:
    """The starting point of restart ``index`` (reproducible)."""
    rng = np.random.default_rng([seed, problem.stages, problem.order, index])
    return problem.system().random_start(rng)


class TimeLimitReached(Exception):
    """The search's time limit passed during a restart (raised by its residual evaluations)."""


def solve_float(system: ResidualSystem, x0: np.ndarray, max_nfev: int = 200, deadline: float | None = None):
    """scipy least_squares (trf, exact Jacobian) from x0: (end point, max |residual|).
    TimeLimitReached when the clock (time.time()) passes ``deadline`` during the solve."""
    from scipy.optimize import least_squares

    cached = _Cached(system, deadline)
    with np.errstate(all="ignore"):
        sol = least_squares(cached.fun, x0, jac=cached.jac, method="trf", xtol=1e-12, ftol=1e-12,
                            gtol=1e-12, max_nfev=max_nfev)
    residual = float(np.max(np.abs(sol.fun))) if sol.fun.size else 0.0
    if not np.isfinite(residual):
        residual = float("inf")
    return sol.x, residual


def attempt(problem: Problem, seed: int, index: int, digits: int = 30, deadline: float | None = None) -> Attempt:
    """Run restart ``index``: float64 least squares, then mpmath polishing of a candidate. With a
    ``deadline`` (time.time(), the same on every worker up to the clocks' agreement) the restart
    stops when it passes, between two evaluations of the residuals: ``timed_out`` is then True
    and the attempt does not count."""
    t0 = time.perf_counter()
    system = problem.system()
    start = start_point(problem, seed, index)
    try:
        x, residual = solve_float(system, start, deadline=deadline)
        polished = None
        if residual < FLOAT_TOLERANCE and np.max(np.abs(x)) <= COEFFICIENT_BOUND:
            polished = polish(system, x, digits, deadline=deadline)
            if not polished.converged and deadline is not None and time.time() > deadline:
                raise TimeLimitReached
    except TimeLimitReached:
        return Attempt(index, float("inf"), tuple(float(v) for v in start), None, time.perf_counter() - t0, True)
    return Attempt(index, residual, tuple(float(v) for v in x), polished, time.perf_counter() - t0)


@dataclass(frozen=True)
class Restarts:
    """The restarts run for one problem.

    Attributes:
        problem: what was searched.
        attempts: the restarts that finished, by index.
        seconds: wall time.
        interrupted: Ctrl-C stopped the run.
        timed_out: the time limit stopped the run before the restart budget was used.
        seconds_to_first: wall time until the first success was known, or None.
    """

    problem: Problem
    attempts: tuple[Attempt, ...]
    seconds: float
    interrupted: bool
    timed_out: bool
    seconds_to_first: float | None

    @property
    def successes(self) -> tuple[Attempt, ...]:
        return tuple(a for a in self.attempts if a.success)

    @property
    def first(self) -> Attempt | None:
        """The successful restart of lowest index."""
        wins = self.successes
        return wins[0] if wins else None

    @property
    def best_residual(self) -> float:
        """Smallest float64 max-residual over the restarts (inf when none ran)."""
        return min((a.residual for a in self.attempts), default=float("inf"))


def run_restarts(problem: Problem, restarts: int, seed: int = 0, executor=None,
                 time_limit: float | None = None, digits: int = 30, stop_after: int | None = 1,
                 on_progress=None) -> Restarts:
    """Run up to ``restarts`` restarts (indices 0..restarts-1) on ``executor`` (default: in this
    process; see :mod:`rkhp.base.executors`), stopping after ``stop_after`` successes (None: run them all).

    The restarts kept are those of index up to the ``stop_after``-th success, and every one of
    them has run, so the answer does not depend on the executor or its number of workers (only the
    time does). About twice as many restarts as the executor has slots are submitted at a time;
    those beyond the needed success are cancelled. ``on_progress(done, total)`` is called after
    each finished restart. Ctrl-C cancels the submitted restarts and returns what finished;
    ``time_limit`` (seconds) is checked inside every restart too (`attempt`), so the run ends
    within it (plus one evaluation of the residuals).
    """
    executor = InProcess() if executor is None else executor
    t0 = time.perf_counter()
    deadline = None if time_limit is None else t0 + time_limit
    wall_deadline = None if time_limit is None else time.time() + time_limit
    done: dict[int, Attempt] = {}
    interrupted = timed_out = False
    first_at = None

    def keep_attempt(a: Attempt) -> None:
        nonlocal first_at
        done[a.index] = a
        if a.success and first_at is None:
            first_at = time.perf_counter() - t0
        if on_progress is not None:
            on_progress(len(done), restarts)

    def last_needed():
        """Index of the stop_after-th success so far (None while there are fewer)."""
        if stop_after is None:
            return None
        wins = sorted(k for k, a in done.items() if a.success)
        return wins[stop_after - 1] if len(wins) >= stop_after else None

    problem.system()  # build once here (and in forked workers' memory)
    pending: dict[int, tuple] = {}  # id(task) -> (task, restart index)
    next_index = 0
    try:
        while True:
            win = last_needed()
            while (len(pending) < 2 * executor.slots and next_index < restarts
                   and (win is None or next_index < win)):
                if deadline is not None and time.perf_counter() > deadline:
                    timed_out = True
                    break
                task = executor.submit(attempt, problem, seed, next_index, digits, wall_deadline)
                pending[id(task)] = (task, next_index)
                next_index += 1
            if win is not None:
                beyond = [key for key, (_, k) in pending.items() if k > win]
                executor.cancel([pending.pop(key)[0] for key in beyond])
            if not pending:
                break
            task = first_done(executor, [t for t, _ in pending.values()])
            del pending[id(task)]
            result = task.result()
            if result.timed_out:  # the limit passed inside it: stop, the unfinished restart does not count
                timed_out = True
                break
            keep_attempt(result)
    except KeyboardInterrupt:
        interrupted = True
        executor.cancel([t for t, _ in pending.values()])
        executor.terminate()  # the running restarts' results would not be used
    finally:
        executor.cancel([t for t, _ in pending.values()])
    attempts = tuple(done[k] for k in sorted(done))
    last = last_needed()
    if last is not None:
        attempts = tuple(a for a in attempts if a.index <= last)
    return Restarts(problem, attempts, time.perf_counter() - t0, interrupted, timed_out, first_at)
