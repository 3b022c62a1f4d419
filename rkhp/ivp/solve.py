"""``rkhp.solve``: an initial value problem to a tolerance, in the shape of scipy's ``solve_ivp``
(docs/solve.md).

The method keeps a constant step h = (t1 - t0) / N; the tolerance chooses N from a pilot error
estimate (`rkhp.ivp.tolerance`), or ``method="auto"`` chooses the method too: the candidate of
:data:`AUTO_CANDIDATES` whose chosen run the pilot predicts to be cheapest. The run is made in
chunks (`rkhp.ivp.run`); along it: the states at ``t_eval`` and the dense output by steps of the
method (`rkhp.ivp.dense`), events located by steps of the method (`rkhp.ivp.events`), and the
largest drifts of the energy, the Casimirs and the declared invariants.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np

from ..base import bounds
from ..base.errors import InputError, NumericalFailure
from ..base.provenance import provenance
from ..integrators.methods import DEFAULT_METHOD, Method, require_steps, resolve_method, resolve_system
from ..integrators.output_times import check_output_times, states_at
from ..integrators.trajectory import Trajectory, energies
from . import tolerance as tolerances
from .dense import DenseOutput
from .events import as_events, scan
from .run import Span, check_span, chunks

#: the tolerance of a solve given neither ``tol`` nor ``steps``
DEFAULT_TOLERANCE = 1e-6
AUTO = "auto"
#: the methods ``method="auto"`` chooses from, by increasing order: the RKHP Euler method
#: (order 2 on symmetric realisations), the paper's three-stage method (4), a searched symmetric
#: method of order 6, and compositions of Euler steps of orders 6, 8 and 10 (docs/compositions.md)
AUTO_CANDIDATES = ("euler", "paper-three-stage", "search-symmetric-o6-s5", "kahan-li6", "kahan-li8",
                   "sofroniou-spaletta10")
#: the status codes of scipy's solve_ivp
FAILED, REACHED_END, TERMINATED = -1, 0, 1


@dataclass(frozen=True)
class Candidate:
    """One method ``method="auto"`` considered: its step choice, or why it was left out."""

    method: str
    choice: tolerances.ToleranceStep | None
    reason: str = ""

    json_keys = ("method", "order", "steps", "predicted_seconds", "left_out")

    @property
    def order(self) -> int | None:
        return None if self.choice is None else self.choice.order

    @property
    def steps(self) -> int | None:
        return None if self.choice is None else self.choice.steps

    @property
    def predicted_seconds(self) -> float | None:
        return None if self.choice is None else self.choice.predicted_seconds

    @property
    def left_out(self) -> str | None:
        """Why the candidate was left out (None when it was not)."""
        return self.reason or None


@dataclass(frozen=True)
class Plan:
    """What a solve will do, known before the run: the method, the steps N and h, and (with a
    tolerance) the step choice and the candidates of ``method="auto"``."""

    system: str
    method: str
    steps: int
    h: float
    span: Span
    choice: tolerances.ToleranceStep | None = None
    candidates: tuple[Candidate, ...] = ()

    json_keys = ("method", "steps", "h", "choice", "candidates")


@dataclass
class SolveResult:
    """The result of :func:`solve`: scipy's fields, then rkhp's.

    scipy's: ``t`` (times, shape (m,)), ``y`` (states, shape (n, m)), ``sol`` (the dense output,
    or None), ``t_events`` and ``y_events`` (per event, the times (k,) and states (k, n) of its
    occurrences; None without events), ``status`` (-1 failed, 0 reached t1, 1 a terminal event),
    ``message``, ``success`` (status >= 0).

    rkhp's: ``system``, ``method``, ``order`` (its order on the system), ``steps`` and ``h`` (of the
    run; ``steps_taken`` before a failure or a terminal event), ``tolerance`` (None when the steps
    were given), ``estimated_error`` (the error at t1 estimated after the run, relative to
    max(1, |y(t1)|); None when the steps were given), ``plan`` (the step choice and the candidates),
    ``casimir_error_max``, ``energy_error_max`` and ``invariant_errors_max`` (the largest |C(y) - C(y_0)|,
    |H(y) - H(y_0)| and |I(y) - I(y_0)| over the grid, each declared invariant; None without
    Casimirs), ``newton_mean``, ``newton_max``, ``run_seconds``, ``provenance``.
    """

    t: np.ndarray
    y: np.ndarray
    sol: DenseOutput | None
    t_events: list | None
    y_events: list | None
    status: int
    message: str
    success: bool
    system: str = ""
    method: str = ""
    order: int | None = None
    steps: int = 0
    h: float = 0.0
    steps_taken: int = 0
    tolerance: float | None = None
    estimated_error: float | None = None
    plan: Plan | None = None
    casimir_error_max: float | None = None
    energy_error_max: float = 0.0
    invariant_errors_max: list = field(default_factory=list)
    newton_mean: float = 0.0
    newton_max: int = 0
    run_seconds: float = 0.0
    provenance: dict = field(default_factory=dict)

    #: docs/json.md "rkhp.solve": scipy's fields and rkhp's, the states one per row
    json_keys = ("system", "method", "order", "steps", "h", "steps_taken", "tolerance", "estimated_error", "status",
                 "message", "success", "t", ("y", "states"), "t_events", "y_events", "casimir_error_max",
                 "energy_error_max", "invariant_errors_max", "invariant_error_max", "newton_mean", "newton_max",
                 "run_seconds", "plan")

    @property
    def states(self) -> np.ndarray:
        """The states one per row, shape (m, n): ``y`` transposed."""
        return self.y.T

    @property
    def invariant_error_max(self) -> float | None:
        """The largest drift of the declared invariants (None without any)."""
        return max(self.invariant_errors_max) if self.invariant_errors_max else None


def choose_method(system, span: Span, tol: float, x0=None, candidates=AUTO_CANDIDATES,
                  on_candidate: Callable[[int, int], None] | None = None
                  ) -> tuple[Method, tolerances.ToleranceStep, tuple[Candidate, ...]]:
    """The candidate whose step choice for ``tol`` the pilot predicts to be cheapest (CPU time of
    a step in the pilot times the steps chosen), with every candidate's choice; a candidate whose
    pilot fails or that needs too many steps is left out with its reason. NumericalFailure when
    none is left."""
    considered, best = [], None
    for k, name in enumerate(candidates):
        method = resolve_method(name)
        try:
            choice = tolerances.choose_tolerance_step(system, method, span, tol, x0)
        except (NumericalFailure, InputError) as exc:
            considered.append(Candidate(name, None, " ".join(str(exc).split())))
        else:
            considered.append(Candidate(name, choice))
            if best is None or choice.predicted_seconds < best[1].predicted_seconds:
                best = (method, choice)
        if on_candidate is not None:
            on_candidate(k + 1, len(candidates))
    if best is None:
        raise NumericalFailure(f"method auto on {system.name}: no candidate can meet tol {tol:g} "
                               f"({'; '.join(f'{c.method}: {c.reason}' for c in considered)})")
    return best[0], best[1], tuple(considered)


def plan(system, t_span=None, method=DEFAULT_METHOD, tol=None, steps=None, x0=None,
         on_candidate=None) -> tuple[Method, Plan]:
    """The method and the plan of a solve (see :func:`solve`), before its run."""
    span = check_span((0.0, system.t_final) if t_span is None else t_span)
    if tol is not None and steps is not None:
        raise InputError("give at most one of tol and steps")
    if steps is not None:
        n = bounds.integer(steps, "steps", 1, bounds.MAX_STEPS)
        if is_auto(method):
            raise InputError("method auto chooses by a tolerance: give tol, not steps")
        chosen = require_steps([resolve_method(method)])[0]
        return chosen, Plan(system.name, chosen.name, n, span.step(n), span)
    tol = tolerances.check_tolerance(DEFAULT_TOLERANCE if tol is None else tol)
    if is_auto(method):
        chosen, choice, considered = choose_method(system, span, tol, x0, on_candidate=on_candidate)
        return chosen, Plan(system.name, chosen.name, choice.steps, choice.h, span, choice, considered)
    chosen = require_steps([resolve_method(method)])[0]
    choice = tolerances.choose_tolerance_step(system, chosen, span, tol, x0)
    return chosen, Plan(system.name, chosen.name, choice.steps, choice.h, span, choice)


class _Progress:
    """Progress over the runs of a solve (a finer run after the first adds its steps)."""

    def __init__(self, callback):
        self.callback, self.before, self.total = callback, 0, 0

    def start(self, steps: int) -> None:
        self.before = self.total
        self.total += steps

    def update(self, done: int) -> None:
        if self.callback is not None:
            self.callback(self.before + done, self.total)


class _Run:
    """What one run keeps as its chunks arrive: the grid (for ``y`` and the dense output) or the
    states at the chosen times, the events, the drifts, the Newton counts."""

    def __init__(self, system, method, span: Span, steps: int, t_eval, keep_grid: bool, events):
        self.system, self.method, self.span, self.steps = system, method, span, steps
        self.t_eval, self.keep_grid, self.events = t_eval, keep_grid, events
        self.times, self.states, self.timed = [], [], []
        self.occurrences = [[] for _ in events]
        self.counts = [0] * len(events)
        self.previous = None  # the event values at the last grid point
        self.start = None
        self.energy = self.casimir = 0.0
        self.invariants = np.zeros(len(system.invariants))
        self.newton_sum, self.newton_max, self.taken, self.seconds = 0, 0, 0, 0.0
        self.status, self.message, self.final = REACHED_END, "the run reached t1", None
        self.end = None  # (t, y) of a terminal event

    def step(self, y, s: float) -> np.ndarray:
        return self.method.integrate(self.system, s, 1, y).raise_if_failed().final_state

    def add(self, chunk) -> bool:
        """Take a chunk; True when the run must stop (a failure or a terminal event)."""
        times, states = chunk.times, chunk.states
        if self.start is None:
            self.start = states[0]
            self.h0, self.c0 = float(self.system.hamiltonian(states[0])), self.system.casimir_values(states[0])
            self.i0 = self.system.invariant_values(states[0])
        first = 0 if chunk.first == 0 else 1
        stop = False
        if self.events:
            values = [e.values(states, times) for e in self.events]
            found, stop = scan(self.events, self.step, times, states, values, self.counts)
            for o in found:
                self.occurrences[o.event].append((o.t, o.state))
            if stop:
                last = found[-1]
                self.end = (last.t, last.state)
                # the grid up to the step of the event
                k = int(np.searchsorted((times - times[0]) * np.sign(times[-1] - times[0]),
                                        (last.t - times[0]) * np.sign(times[-1] - times[0]), side="left"))
                times, states = times[:k], states[:k]
        m = len(states) - 1
        self._drifts(states[first:])
        newton = chunk.newton_iterations[: max(m, 0)]
        self.newton_sum += int(newton.sum())
        self.newton_max = max(self.newton_max, int(newton.max()) if newton.size else 0)
        self.taken = chunk.first + max(m, 0)
        self.seconds += chunk.run_seconds
        if self.keep_grid:
            self.times.append(times[first:])
            self.states.append(states[first:])
        if self.t_eval is not None and len(times):
            self._timed(times, states, chunk)
        if self.end is not None:
            t, y = self.end
            self._drifts(y[None, :])
            if self.keep_grid:
                self.times.append(np.array([t]))
                self.states.append(y[None, :])
            self.status = TERMINATED
            self.message = f"a terminal event occurred at t = {t:.15g}"
            return True
        if not chunk.ok:
            self.status, self.message = FAILED, chunk.status
            return True
        self.final = states[-1]
        return stop

    def _drifts(self, states) -> None:
        if not len(states):
            return
        self.energy = max(self.energy, float(np.abs(energies(self.system, states) - self.h0).max()))
        if self.system.casimirs:
            values = np.array([self.system.casimir_values(x) for x in states])
            self.casimir = max(self.casimir, float(np.abs(values - self.c0).max()))
        if self.system.invariants:
            values = np.array([self.system.invariant_values(x) for x in states])
            self.invariants = np.maximum(self.invariants, np.abs(values - self.i0).max(axis=0))

    def _timed(self, times, states, chunk) -> None:
        """The states at the chosen times within this chunk's grid (up to its last point, or the
        terminal event)."""
        direction = 1.0 if self.span.t1 >= self.span.t0 else -1.0
        low = direction * times[0]
        high = direction * (self.end[0] if self.end is not None else times[-1])
        done = sum(len(t) for t, _ in self.timed)
        rest = self.t_eval[done:]
        inside = rest[(direction * rest >= low) & (direction * rest <= high)]
        if chunk.ok and self.end is None and chunk.first + len(times) - 1 < self.steps:
            inside = inside[direction * inside < high]  # the chunk's last point: the next chunk's first
        if not inside.size:
            return
        grid_times, grid_states = times, states
        if self.end is not None:
            grid_times = np.append(times, self.end[0])
            grid_states = np.vstack([states, self.end[1][None, :]])
        grid = Trajectory(grid_times, grid_states, np.zeros(len(grid_times) - 1, dtype=np.int64),
                          poisson=self.system)
        self.timed.append((inside, states_at(grid, self.method, inside, self.system).states))


def solve(system, t_span=None, method=DEFAULT_METHOD, tol=None, *, steps=None, t_eval=None,
          dense_output: bool = False, events=None, x0=None, realisation: str = "symmetric",
          on_plan: Callable[[Plan], None] | None = None,
          on_progress: Callable[[int, int], None] | None = None,
          on_candidate: Callable[[int, int], None] | None = None) -> SolveResult:
    """Solve the initial value problem of ``system`` over ``t_span`` (default (0, T) of the
    system) with ``method`` at a constant step (docs/solve.md).

    Args:
        system: a built-in name, a spec file or a PoissonSystem (``realisation``: of a name or file).
        t_span: (t0, t1); t1 < t0 runs backwards.
        method: any name of docs/methods.md but scipy's, a Method or a Tableau, or "auto".
        tol: the error allowed at t1, relative to max(1, |y(t1)|) (default DEFAULT_TOLERANCE);
            or ``steps``: N steps, no estimate.
        t_eval: times where the solution is reported (else: the grid).
        dense_output: return ``sol``, the solution at any time of the run.
        events: an expression in x1..xn, an :class:`rkhp.ivp.events.Event`, a function g(t, y)
            (with scipy's ``terminal`` and ``direction`` attributes), or a list of them.
        x0: the start (default: the system's).
        on_plan: called with the :class:`Plan` before the run; on_progress(done, total) after each
            chunk of steps; on_candidate(done, total) after each candidate of "auto".

    Bad input raises InputError; a run that fails returns status -1 (as solve_ivp) with the grid
    up to the failure.
    """
    poisson = resolve_system(system, realisation, x0)
    event_list = as_events(events, poisson.x0)
    chosen, planned = plan(poisson, t_span, method, tol, steps, None, on_candidate)
    span = planned.span
    times = None
    if t_eval is not None:
        times = check_output_times(t_eval, span.t0, span.t1, "t_eval")
    keep_grid = t_eval is None or dense_output
    if on_plan is not None:
        on_plan(planned)
    progress = _Progress(on_progress)

    def run_steps(steps: int):
        if keep_grid:
            bounds.check_trajectory(steps, poisson.dim)
        run = _Run(poisson, chosen, span, steps, times, keep_grid, event_list)
        progress.start(steps)
        for chunk in chunks(poisson, chosen, span, steps):
            stop = run.add(chunk)
            progress.update(run.taken)
            if stop:
                break
        return run, run.final if run.status == REACHED_END else None

    choice, estimate = planned.choice, None
    if choice is None:
        run, _ = run_steps(planned.steps)
        n = planned.steps
    else:
        choice, run, estimate = tolerances.run_to_tolerance(choice, span, poisson, lambda c: run_steps(c.steps))
        n = choice.steps
        if run.status == FAILED:
            estimate = None
        elif estimate > choice.tolerance:
            run.status, run.message = FAILED, (f"the estimated error {estimate:.3g} misses tol "
                                               f"{choice.tolerance:g} after {tolerances.RETRIES} finer runs")
    return _result(poisson, chosen, planned, choice, n, run, times, dense_output, estimate, provenance())


def _result(system, method, planned: Plan, choice, n: int, run: _Run, times, dense_output, estimate,
            record) -> SolveResult:
    if run.keep_grid and run.times:
        grid_t, grid_y = np.concatenate(run.times), np.concatenate(run.states)
    else:
        grid_t, grid_y = np.zeros(0), np.zeros((0, system.dim))
    if times is not None:
        t = np.concatenate([a for a, _ in run.timed]) if run.timed else np.zeros(0)
        y = np.concatenate([b for _, b in run.timed]) if run.timed else np.zeros((0, system.dim))
    else:
        t, y = grid_t, grid_y
    sol = DenseOutput(system, method, grid_t, grid_y) if dense_output and len(grid_t) > 1 else None
    t_events = y_events = None
    if run.events:
        t_events = [np.array([o[0] for o in found], dtype=float) for found in run.occurrences]
        y_events = [np.array([o[1] for o in found], dtype=float).reshape(len(found), system.dim)
                    for found in run.occurrences]
    taken = run.taken
    plan_final = planned if choice is planned.choice else Plan(
        planned.system, planned.method, n, planned.span.step(n), planned.span, choice, planned.candidates)
    return SolveResult(
        t=t, y=y.T, sol=sol, t_events=t_events, y_events=y_events, status=run.status, message=run.message,
        success=run.status >= 0, system=system.name, method=method.name,
        order=_order(method, system), steps=n, h=planned.span.step(n), steps_taken=taken,
        tolerance=None if choice is None else choice.tolerance, estimated_error=estimate, plan=plan_final,
        casimir_error_max=run.casimir if system.casimirs else None, energy_error_max=run.energy,
        invariant_errors_max=[float(v) for v in run.invariants], newton_mean=run.newton_sum / taken if taken else 0.0,
        newton_max=run.newton_max, run_seconds=run.seconds, provenance=record)


def _order(method, system) -> int | None:
    try:
        return method.expected_order_on(system)
    except InputError:
        return None


def is_auto(method) -> bool:
    """Whether ``method`` asks for the choice of :func:`choose_method`."""
    return isinstance(method, str) and method.strip() == AUTO
