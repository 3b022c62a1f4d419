"""Empirical convergence studies: global error at T against h, observed and expected orders.

The numbers of steps are given, or chosen for each method by pilot runs (`rkhp.studies.steps`). For
each method and step size: the global error at T (2-norm against the reference, docs/theory.md §6),
the local observed order, Casimir and energy errors (max over the run), Newton iterations and run
time; per method the fitted slope over the asymptotic range (see :mod:`rkhp.studies.fit`), the
expected order from the verify engine (symmetric order on a symmetric realisation, docs/theory.md §8;
degenerate order on a degenerate one, else general order: paper, Theorem 5.1 and §4), bounded by
what a ``truncated:K`` realisation allows (docs/theory.md §9), and a verdict.
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np

from ..base import bounds
from ..base.errors import InputError
from ..base.executors import InProcess, run_all, run_until_interrupted
from ..integrators.methods import condition_class, require_steps, resolve_methods, resolve_system
from ..systems.singular import flow_stop
from .fit import MIN_FIT_POINTS, OrderFit, fit_order, verdict
from .invariants import declared_error, max_deviations
from .reference import Reference, reference
from .steps import StepChoice, choose_steps

DEFAULT_COARSEST = 20
DEFAULT_REFINEMENTS = 6


@dataclass(frozen=True)
class ConvergenceRow:
    """One run: ``steps`` steps of size ``h``; ``error`` is None when it failed or is not above
    the reference's accuracy (see ``note``); ``casimir_error`` and ``energy_error`` are the largest
    over the run (JSON ``casimir_error_max``, ``energy_error_max``)."""

    h: float
    steps: int
    error: float | None
    local_order: float | None
    casimir_error: float | None
    energy_error: float | None
    newton_mean: float
    newton_max: int
    seconds: float
    compile_seconds: float
    status: str
    measured_error: float | None
    invariant_error: float | None = None

    json_keys = ("h", "steps", "error", "local_order", ("casimir_error_max", "casimir_error"),
                 ("energy_error_max", "energy_error"), "newton_mean", "newton_max", "seconds",
                 ("invariant_error_max", "invariant_error"))

    @property
    def note(self) -> str:
        if self.status != "ok":
            return self.status
        if self.error is None:
            return "below reference accuracy"
        return ""


@dataclass(frozen=True)
class MethodConvergence:
    """The convergence table of one method, its fit and verdict."""

    method: str
    kind: str
    expected_order: int
    fit: OrderFit
    verdict: str
    rows: tuple[ConvergenceRow, ...]
    realisation_bound: int | None = None
    steps_chosen: str | None = None

    json_keys = ("method", "expected_order", "realisation_bound", "observed_order", "verdict",
                 ("fit_rows", "fit.fit_rows"), "steps_chosen", "rows")

    @property
    def observed_order(self) -> float | None:
        return self.fit.slope


@dataclass(frozen=True)
class ConvergenceStudy:
    """``rkhp converge``'s result (JSON keys as in the README's studies section)."""

    system: str
    realisation: str
    degenerate: bool
    t_final: float
    reference: Reference
    methods: tuple[MethodConvergence, ...]
    condition_class: str = "general"
    x0: tuple[float, ...] = ()
    interrupted: bool = False
    reference_choice: str | None = None

    json_keys = ("system", "realisation", "degenerate", "symmetric", "x0", "t_final", "interrupted",
                 ("reference", "reference_summary"), "methods")

    @property
    def symmetric(self) -> bool:
        return self.condition_class == "symmetric"

    @property
    def reference_summary(self) -> dict:
        """The reference's kind and error estimate, and why an automatic reference is mpmath."""
        return {"kind": self.reference.kind, "error_estimate": self.reference.error_estimate,
                "choice": self.reference_choice}


def step_counts(steps=None, refinements: int | None = None) -> tuple[int, ...]:
    """The numbers of steps of a study, coarsest first.

    ``steps`` with several values is used as given; one value N (or none: DEFAULT_COARSEST) is the
    coarsest and is doubled ``refinements`` times (default DEFAULT_REFINEMENTS).
    """
    steps = tuple(bounds.integer(s, "numbers of steps", 1, bounds.MAX_STEPS) for s in (steps or ()))
    if len(steps) > 1 and refinements is not None:
        raise InputError("give either several --steps or --refinements, not both")
    if len(steps) <= 1:
        k = DEFAULT_REFINEMENTS if refinements is None else refinements
        bounds.integer(k, "refinements", 0, bounds.MAX_REFINEMENTS)
        first = steps[0] if steps else DEFAULT_COARSEST
        steps = tuple(first * 2**i for i in range(k + 1))
    if len(set(steps)) != len(steps):
        raise InputError(f"numbers of steps repeat: {list(steps)}")
    steps = tuple(sorted(steps))
    if len(steps) < MIN_FIT_POINTS:
        raise InputError(f"a fit needs at least {MIN_FIT_POINTS} step sizes, got {len(steps)}")
    return steps


def check_t_final(t_final) -> float:
    """A positive, finite final time (InputError otherwise)."""
    return bounds.positive(t_final, "final time T")


def run_row(method, system, ref: Reference, steps: int, t_final: float) -> ConvergenceRow:
    """Integrate with ``steps`` steps to ``t_final`` and measure against the reference."""
    h = t_final / steps
    traj = method.integrate(system, h, steps)
    newton = np.asarray(traj.newton_iterations)
    n_mean = float(newton.mean()) if newton.size else 0.0
    n_max = int(newton.max()) if newton.size else 0
    if not traj.ok:
        stop = flow_stop(system, traj.final_state, h)
        status = traj.status if stop is None else f"{traj.status}; {stop}"
        return ConvergenceRow(h, steps, None, None, None, None, n_mean, n_max, traj.run_seconds,
                              traj.compile_seconds, status, None)
    measured = float(np.linalg.norm(traj.final_state - ref.state))
    casimir, energy = max_deviations(system, traj.states)
    error = measured if measured > ref.floor else None
    return ConvergenceRow(h, steps, error, None, casimir, energy, n_mean, n_max, traj.run_seconds,
                          traj.compile_seconds, "ok", measured, declared_error(system, traj.states))


def study_methods(methods, system, ref: Reference, steps, t_final: float, on_run=None,
                  executor=None) -> tuple[MethodConvergence, ...]:
    """Each method's convergence table, fit and verdict. Every (method, steps) run is one task on
    ``executor`` (rkhp.base.executors; default: in this process), reduced in method and step order;
    ``on_run(done, total)`` after each finished run."""
    results, _ = _study(methods, system, ref, [StepChoice(tuple(steps), (), False, "")] * len(methods), t_final,
                        on_run, executor, keep=False, chosen=False)
    return results


def _study(methods, system, ref: Reference, choices, t_final: float, on_run, executor, keep: bool,
           chosen: bool) -> tuple[tuple[MethodConvergence, ...], bool]:
    """The runs of each method at its StepChoice's numbers of steps, and whether an interrupt
    stopped them (with ``keep``: the tables then hold the rows finished before it, methods without
    any left out); with ``chosen``, each table says how its steps were chosen."""
    runs = [(m, system, ref, n, t_final) for m, c in zip(methods, choices, strict=True) for n in c.counts]
    if keep:
        rows, interrupted = run_until_interrupted(executor or InProcess(), run_row, runs, on_run)
    else:
        rows, interrupted = run_all(executor or InProcess(), run_row, runs, on_run), False
    tables, start = [], 0
    for m, c in zip(methods, choices, strict=True):
        done = [r for r in rows[start:start + len(c.counts)] if r is not None]
        start += len(c.counts)
        if done:
            tables.append(_method_convergence(m, system, ref, done, c.how if chosen else None))
    return tuple(tables), interrupted


def pilot(method, system, t_final: float):
    """n -> x(T) of the method's run of n steps to t_final (None where it fails), each run once."""
    runs: dict[int, np.ndarray | None] = {}

    def final_state(n: int):
        if n not in runs:
            traj = method.integrate(system, t_final / n, n, keep_all=False)
            ok = traj.ok and bool(np.all(np.isfinite(traj.final_state)))
            runs[n] = np.array(traj.final_state) if ok else None
        return runs[n]

    return final_state


def choose_study_steps(methods, system, ref: Reference, t_final: float, reference_kind: str):
    """Each method's StepChoice (`rkhp.studies.steps`) and the reference, with why where it was
    changed: an automatic reference that is DOP853 gives way to mpmath (a system given by
    expressions) when its floor leaves some method a narrow range of steps."""
    finals = [pilot(m, system, t_final) for m in methods]
    orders = [m.expected_order_on(system) for m in methods]
    choices = [choose_steps(f, ref, p) for f, p in zip(finals, orders, strict=True)]
    narrow = [f"{m.name} (order {p})" for m, p, c in zip(methods, orders, choices, strict=True) if c.narrow]
    if not narrow or reference_kind != "auto" or ref.kind != "dop853" or system.symbolic() is None:
        return ref, choices, None
    try:
        better = reference(system, t_final, kind="mpmath")
    except InputError as exc:
        return ref, choices, (f"DOP853, whose floor leaves a narrow range of steps to {', '.join(narrow)}; "
                              f"no mpmath reference: {exc}")
    why = (f"mpmath, as DOP853's floor ({ref.floor:.1e}) left a narrow range of steps to {', '.join(narrow)}")
    return better, [choose_steps(f, better, p) for f, p in zip(finals, orders, strict=True)], why


def _method_convergence(method, system, ref: Reference, rows, steps_chosen: str | None = None
                        ) -> MethodConvergence:
    expected = method.expected_order_on(system)
    bound = method.realisation_bound(system)
    if len(rows) < MIN_FIT_POINTS:  # an interrupted study: too few rows to fit
        fit = OrderFit(None, (), tuple((i, "too few rows") for i in range(len(rows))), (None,) * len(rows))
        return MethodConvergence(method.name, method.kind, expected, fit, "inconclusive", tuple(rows), bound,
                                 steps_chosen)
    fit = fit_order([r.h for r in rows], [r.measured_error for r in rows], floor=ref.floor)
    rows = [_with_local_order(r, p) for r, p in zip(rows, fit.local_orders, strict=True)]
    return MethodConvergence(method.name, method.kind, expected, fit, verdict(fit.slope, expected, fit),
                             tuple(rows), bound, steps_chosen)


def _with_local_order(row: ConvergenceRow, p) -> ConvergenceRow:
    return replace(row, local_order=p)


def converge(system, methods, steps=None, t_final=None, refinements=None, on_run=None,
             executor=None, reference_kind: str = "auto") -> ConvergenceStudy:
    """Run a convergence study of ``methods`` (names of :mod:`rkhp.integrators.methods` or Methods; the
    defaults when empty) on ``system`` (a name, a spec file or a PoissonSystem) up to ``t_final``
    (default: the system's). The numbers of steps are ``steps`` and ``refinements``
    (:func:`step_counts`) where either is given, else chosen for each method by pilot runs
    (:func:`choose_study_steps`). The runs are independent tasks on ``executor``
    (rkhp.base.executors; default: in this process), ``on_run(done, total)`` after each; the
    reference is computed here, once, of ``reference_kind`` (`rkhp.studies.reference.KINDS`).
    Ctrl-C during the runs ends the study early: ``interrupted`` is then True and the tables hold
    the rows finished before it."""
    system = resolve_system(system)
    methods = require_steps(resolve_methods(methods))
    t_final = check_t_final(system.t_final if t_final is None else t_final)
    chosen = not steps and refinements is None
    if not chosen:
        counts = step_counts(steps, refinements)
        bounds.check_trajectory(max(counts), system.dim, "the finest run")
    ref = reference(system, t_final, kind=reference_kind)
    why = None
    if chosen:
        ref, choices, why = choose_study_steps(methods, system, ref, t_final, reference_kind)
        bounds.check_trajectory(max(max(c.counts) for c in choices), system.dim, "the finest run")
    else:
        choices = [StepChoice(counts, (), False, "")] * len(methods)
    results, interrupted = _study(methods, system, ref, choices, t_final, on_run, executor, True, chosen)
    return ConvergenceStudy(system.name, system.realisation, bool(system.degenerate), t_final, ref, results,
                            condition_class(system), tuple(float(v) for v in system.x0), interrupted, why)
