"""Empirical convergence studies: global error at T against h, observed and expected orders.

For each method and step size: the global error at T (2-norm against the reference, docs/theory.md §6),
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
from .fit import MIN_FIT_POINTS, OrderFit, fit_order, verdict
from .invariants import max_deviations
from .reference import Reference, reference

DEFAULT_COARSEST = 20
DEFAULT_REFINEMENTS = 6


@dataclass(frozen=True)
class ConvergenceRow:
    """One run: ``steps`` steps of size ``h``; ``error`` is None when it failed or is not above
    the reference's accuracy (see ``note``)."""

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

    @property
    def note(self) -> str:
        if self.status != "ok":
            return self.status
        if self.error is None:
            return "below reference accuracy"
        return ""

    def to_json(self) -> dict:
        return {"h": self.h, "steps": self.steps, "error": self.error, "local_order": self.local_order,
                "casimir_error": self.casimir_error, "energy_error": self.energy_error,
                "newton_mean": self.newton_mean, "newton_max": self.newton_max, "seconds": self.seconds}


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

    @property
    def observed_order(self) -> float | None:
        return self.fit.slope

    def to_json(self) -> dict:
        return {"method": self.method, "expected_order": self.expected_order,
                "realisation_bound": self.realisation_bound,
                "observed_order": self.observed_order, "verdict": self.verdict,
                "fit_rows": list(self.fit.fit_rows), "rows": [r.to_json() for r in self.rows]}


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

    @property
    def symmetric(self) -> bool:
        return self.condition_class == "symmetric"

    def to_json(self) -> dict:
        return {"system": self.system, "realisation": self.realisation, "degenerate": self.degenerate,
                "symmetric": self.symmetric, "x0": list(self.x0),
                "t_final": self.t_final, "interrupted": self.interrupted,
                "reference": {"kind": self.reference.kind, "error_estimate": self.reference.error_estimate},
                "methods": [m.to_json() for m in self.methods]}


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
        return ConvergenceRow(h, steps, None, None, None, None, n_mean, n_max, traj.run_seconds,
                              traj.compile_seconds, traj.status, None)
    measured = float(np.linalg.norm(traj.final_state - ref.state))
    casimir, energy = max_deviations(system, traj.states)
    error = measured if measured > ref.floor else None
    return ConvergenceRow(h, steps, error, None, casimir, energy, n_mean, n_max, traj.run_seconds,
                          traj.compile_seconds, "ok", measured)


def study_methods(methods, system, ref: Reference, steps, t_final: float, on_run=None,
                  executor=None) -> tuple[MethodConvergence, ...]:
    """Each method's convergence table, fit and verdict. Every (method, steps) run is one task on
    ``executor`` (rkhp.base.executors; default: in this process), reduced in method and step order;
    ``on_run(done, total)`` after each finished run."""
    results, _ = study_rows(methods, system, ref, steps, t_final, on_run, executor, keep=False)
    return results


def study_rows(methods, system, ref: Reference, steps, t_final: float, on_run=None, executor=None,
               keep: bool = True) -> tuple[tuple[MethodConvergence, ...], bool]:
    """As :func:`study_methods`, and whether an interrupt stopped the runs (with ``keep``: the
    tables then hold the rows finished before it, methods without any left out)."""
    runs = [(m, system, ref, n, t_final) for m in methods for n in steps]
    if keep:
        rows, interrupted = run_until_interrupted(executor or InProcess(), run_row, runs, on_run)
    else:
        rows, interrupted = run_all(executor or InProcess(), run_row, runs, on_run), False
    tables = []
    for k, m in enumerate(methods):
        done = [r for r in rows[k * len(steps):(k + 1) * len(steps)] if r is not None]
        if done:
            tables.append(_method_convergence(m, system, ref, done))
    return tuple(tables), interrupted


def _method_convergence(method, system, ref: Reference, rows) -> MethodConvergence:
    expected = method.expected_order_on(system)
    bound = method.realisation_bound(system)
    if len(rows) < MIN_FIT_POINTS:  # an interrupted study: too few rows to fit
        fit = OrderFit(None, (), tuple((i, "too few rows") for i in range(len(rows))), (None,) * len(rows))
        return MethodConvergence(method.name, method.kind, expected, fit, "inconclusive", tuple(rows), bound)
    fit = fit_order([r.h for r in rows], [r.measured_error for r in rows], floor=ref.floor)
    rows = [_with_local_order(r, p) for r, p in zip(rows, fit.local_orders, strict=True)]
    return MethodConvergence(method.name, method.kind, expected, fit, verdict(fit.slope, expected, fit),
                             tuple(rows), bound)


def _with_local_order(row: ConvergenceRow, p) -> ConvergenceRow:
    return replace(row, local_order=p)


def converge(system, methods, steps=None, t_final=None, refinements=None, on_run=None,
             executor=None, reference_kind: str = "auto") -> ConvergenceStudy:
    """Run a convergence study of ``methods`` (names of :mod:`rkhp.integrators.methods` or Methods; the
    defaults when empty) on ``system`` (a name, a spec file or a PoissonSystem) up to ``t_final``
    (default: the system's). The runs are independent tasks on ``executor`` (rkhp.base.executors;
    default: in this process), ``on_run(done, total)`` after each; the reference is computed here,
    once, of ``reference_kind`` (`rkhp.studies.reference.KINDS`). Ctrl-C during the runs ends the
    study early: ``interrupted`` is then True and the tables hold the rows finished before it."""
    system = resolve_system(system)
    methods = require_steps(resolve_methods(methods))
    t_final = check_t_final(system.t_final if t_final is None else t_final)
    counts = step_counts(steps, refinements)
    bounds.check_trajectory(max(counts), system.dim, "the finest run")
    ref = reference(system, t_final, kind=reference_kind)
    results, interrupted = study_rows(methods, system, ref, counts, t_final, on_run, executor)
    return ConvergenceStudy(system.name, system.realisation, bool(system.degenerate), t_final, ref, results,
                            condition_class(system), tuple(float(v) for v in system.x0), interrupted)
