"""The constant step that meets a tolerance, from a pilot error estimate (docs/solve.md).

A geometric method keeps its step constant (a step that changes with the state is no longer the
time-h flow of one modified Hamiltonian, docs/theory.md §11); the tolerance chooses that step.
The error at T of a method of order p with N steps is e(N) = C (T/N)^p + O(N^-(p+1)). Pilot runs
of N, 2N, 4N and 8N steps give the differences d_k = |y(2^k N) - y(2^(k+1) N)|; when the two
observed orders log2(d_1/d_2) and log2(d_2/d_3) agree and are not below p, the runs are in the
asymptotic range, and Richardson's estimate of the error of y(8N) is d_3 / (2^q - 1), q the
smaller of p and the observed order. Otherwise N is doubled (a pilot that fails is doubled too).
The chosen number of steps meets SAFETY times the tolerance by the model e(M) = e(8N) (8N/M)^q
(towards coarser steps with the larger of the two orders), and is at least N. After the run its
error is estimated again, by Richardson against the finest pilot when it has at least twice its
steps, and a run whose estimate misses the tolerance is replaced by a finer one (at most
RETRIES times), estimated against the run before.

Each step rounds the state: over N steps the round-off can add up like N eps |y| (a rounding
bias of each step, not only the random walk eps |y| sqrt(N)), which no finer step removes. The
predicted and estimated errors add that bound, and a tolerance whose chosen N steps would have a
bound above it is refused before the run: a method of higher order reaches it in fewer steps.

The tolerance is on the 2-norm of the error at the end, relative to max(1, |y(T)|): absolute for
states of norm up to 1, relative beyond.
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass, field

import numpy as np

from ..base import bounds
from ..base.errors import InputError, NumericalFailure
from .run import Span

#: the chosen run aims at SAFETY times the tolerance (the model's constant C varies with h)
SAFETY = 0.5
#: the coarsest pilot run
PILOT_START = 4
#: the finest pilot run has at most this many steps
PILOT_MAX = 2**16
#: the observed orders of the pilot may fall short of p by ORDER_BELOW, and differ from each
#: other by ORDER_SPREAD (an order above p: the estimate with p is conservative)
ORDER_BELOW = 0.5
ORDER_SPREAD = 0.6
#: differences below ROUND_OFF eps |y| sqrt(N) are round-off, not a measured error
ROUND_OFF = 100.0
#: runs after the first that may replace a run whose error estimate misses the tolerance
RETRIES = 2
#: the smallest tolerance (a run's round-off grows like eps sqrt(N))
MIN_TOLERANCE = 1e-13
EPS = float(np.finfo(float).eps)


def round_off_bound(steps: int) -> float:
    """The bound N eps of the round-off of a run of N steps, relative to the scale max(1, |y|)."""
    return steps * EPS


def check_tolerance(tol) -> float:
    """A tolerance MIN_TOLERANCE <= tol < 1 (InputError otherwise)."""
    return bounds.number(tol, "tol", MIN_TOLERANCE, 1.0, high_open=True)


@dataclass(frozen=True)
class Pilot:
    """The pilot runs of one method: their numbers of steps (the last four, N to 8N, decide), the
    differences between successive end states, the observed order of the finest pair, the
    estimated error of the finest run (absolute), whether that is round-off, the coarsest run of
    the asymptotic range (N) and the CPU seconds a step costs."""

    steps: tuple[int, ...]
    differences: tuple[float, ...]
    observed_order: float | None
    estimate: float
    round_off: bool
    coarsest: int
    seconds_per_step: float
    finest: np.ndarray = field(repr=False, compare=False)

    json_keys = ("steps", "differences", "observed_order", "estimate", "round_off", "seconds_per_step")

    @property
    def finest_steps(self) -> int:
        return self.steps[-1]


@dataclass(frozen=True)
class ToleranceStep:
    """The step chosen for a tolerance: ``steps`` steps of size ``h`` of ``method`` (of order
    ``order`` on the system), from its ``pilot``; ``predicted_error`` is the model's error of that
    run relative to ``scale`` = max(1, |y(T)|), as the tolerance."""

    method: str
    order: int
    tolerance: float
    scale: float
    steps: int
    h: float
    predicted_error: float
    pilot: Pilot

    json_keys = ("method", "order", "tolerance", "scale", "steps", "h", "predicted_error", "predicted_seconds",
                 "pilot")

    @property
    def predicted_seconds(self) -> float:
        return self.steps * self.pilot.seconds_per_step


def norm(x) -> float:
    return float(np.linalg.norm(x))


def pilot_runs(system, method, span: Span, order: int, x0=None, start: int = PILOT_START) -> Pilot:
    """The pilot runs of ``method`` (order ``order`` on ``system``) over ``span`` (module
    docstring); NumericalFailure when no pilot up to PILOT_MAX steps is in the asymptotic range."""
    ends: dict[int, np.ndarray | None] = {}
    seconds: dict[int, float] = {}

    def end(n: int):
        if n not in ends:
            started = time.thread_time()
            trajectory = method.integrate(system, span.step(n), n, system.start(x0), keep_all=False)
            seconds[n] = time.thread_time() - started
            ends[n] = trajectory.final_state if trajectory.ok else None
        return ends[n]

    n = start
    while 8 * n <= PILOT_MAX:
        runs = [end(n * 2**k) for k in range(4)]
        if any(y is None for y in runs):
            n *= 2
            continue
        d = [norm(a - b) for a, b in zip(runs, runs[1:], strict=False)]
        scale = max(1.0, norm(runs[-1]))
        noise = ROUND_OFF * EPS * scale * math.sqrt(8 * n)
        orders = [math.log2(a / b) if a > 0 and b > 0 else None for a, b in zip(d, d[1:], strict=False)]
        if d[-1] <= noise or asymptotic(orders, order):
            steps = tuple(sorted(ends))
            differences = tuple(norm(ends[a] - ends[b]) for a, b in zip(steps, steps[1:], strict=False)
                                if ends[a] is not None and ends[b] is not None)
            observed = None if d[-1] <= noise else orders[-1]
            low = order if observed is None else min(order, observed)
            estimate = max(d[-1] / (2**low - 1), noise if d[-1] <= noise else 0.0)
            return Pilot(steps, differences, observed, estimate, d[-1] <= noise, n,
                         _seconds_per_step(seconds, 2 * n), runs[-1])
        n *= 2
    tried = ", ".join(str(k) for k in sorted(ends))
    raise NumericalFailure(f"{method.name} on {system.name}: the pilot runs ({tried} steps) show no error "
                           f"of order {order} in h (they fail, or the error does not fall as h^{order}): "
                           "the step cannot be chosen for a tolerance; give --steps")


def asymptotic(orders, order: int) -> bool:
    """Whether two successive observed orders say the runs are in the asymptotic range: both at
    least ``order`` - ORDER_BELOW, within ORDER_SPREAD of each other."""
    if any(q is None for q in orders):
        return False
    return min(orders) >= order - ORDER_BELOW and max(orders) - min(orders) <= ORDER_SPREAD


def _seconds_per_step(seconds: dict[int, float], n: int) -> float:
    """CPU seconds a step costs, from the runs of 2N and 4N steps (their difference removes the
    fixed cost of a call), or the 4N run's mean where the difference is not positive."""
    extra = seconds[4 * n] - seconds[2 * n]
    return extra / (2 * n) if extra > 0 else seconds[4 * n] / (4 * n)


def exponents(order: int, observed: float | None) -> tuple[float, float]:
    """The exponents of the error model e(N) = e(M) (M/N)^q: towards finer steps the smaller of
    the method's order and the observed one, towards coarser steps the larger (each
    overestimates the error on its side)."""
    if observed is None:
        return float(order), float(order)
    return min(order, observed), max(order, observed)


def steps_for(error: float, steps: int, order: int, observed: float | None, target: float) -> int:
    """The fewest steps whose modelled error (from ``error`` at ``steps`` steps, :func:`exponents`)
    is at most ``target``."""
    finer, coarser = exponents(order, observed)
    if error > target:
        return math.ceil(steps * (error / target) ** (1.0 / finer))
    return max(1, math.ceil(steps * (error / target) ** (1.0 / coarser))) if error > 0 else 1


def modelled(error: float, steps: int, n: int, order: int, observed: float | None) -> float:
    """The modelled error of a run of ``n`` steps from ``error`` at ``steps`` steps."""
    finer, coarser = exponents(order, observed)
    return error * (steps / n) ** (finer if n >= steps else coarser)


def too_many(method, system, tol: float, n: int) -> InputError:
    return InputError(f"{method} on {system}: tol {tol:g} needs about {n:.3g} steps (at most "
                      f"{bounds.MAX_STEPS}); choose a looser tolerance or a method of higher order")


def check_reachable(method, system, tol: float, n: int, truncation: float) -> None:
    """InputError when a run of ``n`` steps whose modelled error is ``truncation`` cannot promise
    ``tol``: the round-off bound of its steps (:func:`round_off_bound`) takes it past the tolerance."""
    if truncation + round_off_bound(n) > tol:
        raise InputError(f"{method} on {system}: tol {tol:g} needs {n} steps, whose round-off (up to "
                         f"{n} eps = {round_off_bound(n):.1e}) may exceed it; choose a looser tolerance or a "
                         f"method of higher order")


def choose_tolerance_step(system, method, span: Span, tol: float, x0=None,
                          pilot_run: Pilot | None = None) -> ToleranceStep:
    """The step of ``method`` (a Method) on ``system`` over ``span`` for the tolerance ``tol``
    (module docstring): the fewest steps, at least the pilot's coarsest run of the asymptotic
    range, whose modelled error is SAFETY times the tolerance; InputError when that is more than
    bounds.MAX_STEPS steps."""
    tol = check_tolerance(tol)
    order = method.expected_order_on(system)
    found = pilot_run or pilot_runs(system, method, span, order, x0)
    scale = max(1.0, norm(found.finest))
    observed = found.observed_order
    n = max(steps_for(found.estimate, found.finest_steps, order, observed, SAFETY * tol * scale),
            found.coarsest)
    if n > bounds.MAX_STEPS:
        raise too_many(method.name, system.name, tol, n)
    predicted = modelled(found.estimate, found.finest_steps, n, order, observed) / scale
    check_reachable(method.name, system.name, tol, n, predicted)
    return ToleranceStep(method.name, order, tol, scale, n, span.step(n), predicted + round_off_bound(n), found)


def estimated_error(choice: ToleranceStep, final: np.ndarray, steps: int | None = None,
                    reference: np.ndarray | None = None) -> float:
    """The error estimate of the chosen run's end state ``final``, relative to the scale: by
    Richardson against a coarser run (``reference`` of ``steps`` steps; default the finest pilot)
    when the chosen run has at least twice its steps, else the model's prediction; each with the
    round-off bound of its steps (:func:`round_off_bound`)."""
    if reference is None:
        steps, reference = choice.pilot.finest_steps, choice.pilot.finest
    ratio = choice.steps / steps
    if ratio >= 2 and not choice.pilot.round_off:
        finer, _ = exponents(choice.order, choice.pilot.observed_order)
        return norm(final - reference) / (ratio**finer - 1) / choice.scale + round_off_bound(choice.steps)
    return choice.predicted_error


def refine(choice: ToleranceStep, error: float, span: Span, system) -> ToleranceStep:
    """A finer choice after a run whose estimated error ``error`` (relative) missed the tolerance."""
    observed = choice.pilot.observed_order
    n = max(steps_for(error, choice.steps, choice.order, observed, SAFETY * choice.tolerance), 2 * choice.steps)
    if n > bounds.MAX_STEPS:
        raise too_many(choice.method, system.name, choice.tolerance, n)
    predicted = modelled(error, choice.steps, n, choice.order, observed)
    check_reachable(choice.method, system.name, choice.tolerance, n, predicted)
    predicted += round_off_bound(n)
    return ToleranceStep(choice.method, choice.order, choice.tolerance, choice.scale, n, span.step(n), predicted,
                      choice.pilot)


def run_to_tolerance(choice: ToleranceStep, span: Span, system, run):
    """Run ``choice`` (``run(choice)`` returns the run's result and its end state at t1, or None
    when it did not reach t1) and estimate its error (:func:`estimated_error`); while the estimate
    misses the tolerance, a finer run (:func:`refine`, at most RETRIES), estimated against the
    run before. Returns the last choice, its result and its estimate (the model's prediction for
    a run that did not reach t1)."""
    previous = (None, None)
    attempt = 0
    while True:
        result, final = run(choice)
        if final is None:
            return choice, result, choice.predicted_error
        estimate = estimated_error(choice, final, *previous)
        if estimate <= choice.tolerance or attempt == RETRIES:
            return choice, result, estimate
        previous = (choice.steps, final)
        choice = refine(choice, estimate, span, system)
        attempt += 1
