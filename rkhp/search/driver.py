"""The tableau search: restarts order by order, polishing, verification, closed forms, proofs.

``search(stages, order)`` looks for an explicit (or implicit) tableau with ``stages`` stages meeting
the order conditions of a class (paper, Theorems 5.1–5.2: "general" over T, "degenerate" over
T_0; docs/theory.md §8 for "symmetric") up to ``order``; without an order it raises N until the restarts
fail and reports the evidence against the first order not reached. Every reported tableau has
been verified by :func:`rkhp.tableaux.verification.verify`, exactly when a closed form was recognised, else at D
digits after Newton polishing; ``decided_by`` says which.
"""

from __future__ import annotations

import dataclasses
import hashlib
import time
from dataclasses import dataclass, field
from typing import NamedTuple

import numpy as np

from ..base import bounds
from ..base.errors import InputError
from ..base.json_form import json_form
from ..trees.conditions import check_class
from .multistart import Problem, Restarts, run_restarts
from .optimise import KnownMethod, known_methods, minimise_error, minimise_phase, polish_phase, refine_optimum
from .polish import polish
from .prove import Proof, choose_engine, prove_impossible
from .recognise import find_closed_form, recognise_point
from .system import MAX_SEARCH_ORDER, check_problem

#: Digits of the polished solutions unless asked otherwise, and the accepted range.
DEFAULT_DIGITS = 30
MIN_DIGITS, MAX_DIGITS = 20, 500
#: Proof time limit when no --time-limit is given (seconds).
DEFAULT_PROOF_SECONDS = 60.0
#: Solutions collected as starting points for --optimize error and --optimize phase.
OPTIMISATION_STARTS = 8


@dataclass(frozen=True)
class SearchOptions:
    """How to search: restart budget, seed, time limit (of the whole search: every order and the
    proof), digits D, ``optimize`` ("error" or None), ``prove``, ``proof_engine`` ("auto",
    "singular" or "sympy": :mod:`.prove`), ``closed_form`` (recognition). Where the restarts run is
    not an option of the search: it is the executor handed to :func:`search`."""

    restarts: int = 50
    seed: int = 0
    time_limit: float | None = None
    digits: int = DEFAULT_DIGITS
    optimize: str | None = None
    prove: bool = False
    closed_form: bool = True
    proof_engine: str = "auto"

    def check(self) -> None:
        bounds.integer(self.restarts, "--restarts", 1, bounds.MAX_RESTARTS)
        bounds.seed(self.seed, "--seed")
        if self.time_limit is not None:
            bounds.number(self.time_limit, "--time-limit", 0.0, bounds.MAX_SECONDS, low_open=True)
        bounds.integer(self.digits, "--digits")
        if not MIN_DIGITS <= self.digits <= MAX_DIGITS:
            raise InputError(f"--digits must be between {MIN_DIGITS} and {MAX_DIGITS}, "
                             f"got {self.digits}")
        if self.optimize not in (None, "error", "phase"):
            raise InputError(f"--optimize must be 'error' or 'phase', got {self.optimize!r}")
        if self.prove:
            choose_engine(self.proof_engine)


@dataclass(frozen=True)
class Found:
    """A verified tableau of order ``order`` in the searched class.

    Attributes:
        tableau: rkhp.tableaux.tableau.Tableau (exact entries when a closed form verified, else D digits).
        verification: rkhp.tableaux.verification.Verification of that tableau.
        residual: max |order-condition residual| of the polished solution (0 when exact).
        restart: index of the restart it came from (None for an optimum).
    """

    order: int
    tableau: object
    verification: object
    residual: float
    restart: int | None

    @property
    def exact(self) -> bool:
        return self.verification.precision == "exact"


@dataclass(frozen=True)
class Optimisation:
    """--optimize error: the optimum's principal error norm beside known methods' norms, and the
    KKT residual of the D-digit refinement (None when the refinement did not converge).
    --optimize phase (``objective`` "phase"): also the phase order and constant of the tableau
    found (theta(z) - z = constant z^(p+1) + ..., docs/stability.md; None when no optimum was
    verified)."""

    error_norm: float
    starts: int
    known: tuple[KnownMethod, ...]
    kkt_residual: float | None
    objective: str = "error"
    phase_order: int | None = None
    phase_constant: float | None = None

    json_keys = ("error_norm", "starts", "kkt_residual", "objective", "phase_order", "phase_constant", "known")


class ProofSummary(NamedTuple):
    """A proof attempt in brief: how (``method``) and what it decided (``result``, a sentence)."""

    method: str
    result: str


class NextOrderEvidence(NamedTuple):
    """The restarts of the first order not reached: the order, their number and the best residual
    they met (None without restarts)."""

    order: int
    restarts: int
    best_residual: float | None


@dataclass(frozen=True)
class SearchResult:
    """Everything a search found, with the evidence (its JSON form: ``json_keys``, docs/json.md)."""

    stages: int
    cls: str
    implicit: bool
    requested_order: int | None
    found: Found | None
    runs: tuple[Restarts, ...]
    seconds: float
    options: SearchOptions
    proof: Proof | None = None
    proof_order: int | None = None
    optimisation: Optimisation | None = None
    interrupted: bool = False
    seconds_to_first: dict[int, float] = field(default_factory=dict)

    #: docs/json.md "rkhp search": the result, then the evidence
    json_keys = ("stages", "degenerate", "implicit", "order", ("found", "reached"), ("tableau", "tableau_entries"),
                 "residual", ("restarts", "restart_count"), ("successes", "success_count"),
                 ("seconds", "rounded_seconds"), "principal_error", ("proof", "proof_summary"),
                 ("evidence_next_order", "next_order_evidence"), ("class", "cls"), "order_restarts",
                 "order_successes", "decided_by", "verified_orders", ("seed", "options.seed"), "interrupted",
                 ("optimization", "optimisation"), "proof_detail")

    @property
    def degenerate(self) -> bool:
        """Whether the class is over T_0 (degenerate or symmetric)."""
        return self.cls != "general"

    @property
    def reached(self) -> bool:
        """Whether a tableau was found."""
        return self.found is not None

    @property
    def tableau_entries(self) -> dict | None:
        """The entries of the tableau found as text, ``{"A", "b", "c"}`` (c of a D-digit tableau
        to D digits); None when none was found."""
        import mpmath

        from ..tableaux.tableau import entry_text

        if self.found is None:
            return None
        t = self.found.tableau
        with mpmath.workdps(self.options.digits):
            return {"A": [[entry_text(x) for x in row] for row in t.A],
                    "b": [entry_text(x) for x in t.b], "c": [entry_text(x) for x in t.c]}

    @property
    def residual(self) -> float | None:
        """The largest polished residual of the tableau found (None when none was)."""
        return None if self.found is None else self.found.residual

    @property
    def restart_count(self) -> int:
        return sum(len(r.attempts) for r in self.runs)

    @property
    def success_count(self) -> int:
        return sum(len(r.successes) for r in self.runs)

    @property
    def rounded_seconds(self) -> float:
        return round(self.seconds, 3)

    @property
    def proof_summary(self) -> ProofSummary | None:
        if self.proof is None:
            return None
        return ProofSummary(self.proof.method, self.proof.result_text(self.stages, self.proof_order, self.cls))

    @property
    def next_order_evidence(self) -> NextOrderEvidence | None:
        failed = self.failed_run
        if failed is None:
            return None
        return NextOrderEvidence(failed.problem.order, len(failed.attempts),
                                 failed.best_residual if failed.attempts else None)

    @property
    def order_restarts(self) -> int | None:
        """The restarts of the order reported (None when nothing was found)."""
        run = self.found_run
        return None if run is None else len(run.attempts)

    @property
    def order_successes(self) -> int | None:
        run = self.found_run
        return None if run is None else len(run.successes)

    @property
    def decided_by(self) -> str | None:
        """The verify tolerance rule that decided the tableau found."""
        return None if self.found is None else self.found.verification.tolerance_rule

    @property
    def verified_orders(self) -> dict | None:
        return None if self.found is None else self.found.verification.order_bounds

    @property
    def proof_detail(self) -> dict | None:
        """The proof attempt in full, after the order it was about (None without one)."""
        return None if self.proof is None else {"order": self.proof_order, **json_form(self.proof)}

    @property
    def order(self) -> int | None:
        """The requested order, or (without one) the highest order reached."""
        if self.requested_order is not None:
            return self.requested_order
        return self.found.order if self.found else None

    @property
    def failed_run(self) -> Restarts | None:
        """The restarts of the first order not reached (the evidence against it), if any."""
        for run in self.runs:
            if run.first is None:
                return run
        return None

    @property
    def principal_error(self) -> float | None:
        if self.found is None:
            return None
        return self.found.verification.principal_error.get(self.cls)

    @property
    def found_run(self) -> Restarts | None:
        """The restarts of the order reported (those that found it), if any."""
        if self.found is None:
            return None
        return next(r for r in self.runs if r.problem.order == self.found.order)

    def command_line(self) -> str:
        """The command that reproduces the reported tableau."""
        flags = {"general": "", "degenerate": " --degenerate", "symmetric": " --symmetric"}[self.cls]
        opts = self.options
        return (f"rkhp search --stages {self.stages} --order {self.found.order}{flags}"
                f"{' --implicit' if self.implicit else ''} --seed {opts.seed} "
                f"--restarts {opts.restarts} --digits {opts.digits}"
                f"{' --optimize ' + opts.optimize if opts.optimize else ''}")

    def tableau_to_save(self):
        """The reported tableau as a file would hold it: named by its content (its class, order,
        stages and a hash of its entries), claiming its verified order in every class (verified
        again without an order limit), with the command line that reproduces it."""
        from ..tableaux.verification import verify

        found = self.found
        orders = verify(found.tableau, precision=found.verification.precision
                        if found.exact else self.options.digits).orders
        return dataclasses.replace(
            found.tableau, name=content_name(found.tableau, method_name(
                Problem(self.stages, found.order, self.cls, self.implicit))),
            claimed_order=orders.get("general"), claimed_degenerate_order=orders.get("degenerate"),
            claimed_symmetric_order=orders.get("symmetric"), reference=self.command_line(),
            notes=f"verified: {found.verification.tolerance_rule}")


def make_tableau(problem: Problem, entries, name: str):
    """A Tableau from the unknowns (strings of D digits, or sympy closed forms)."""
    from ..tableaux.tableau import Tableau

    system = problem.system()
    s = problem.stages
    A = [["0"] * s for _ in range(s)]
    for (i, j), v in zip(system.pattern, entries, strict=False):
        A[i][j] = v
    b = list(entries[len(system.pattern):])
    return Tableau.from_arrays(A, b, name=name)


def verified(problem: Problem, x_float, polished, digits: int, closed: bool, name: str,
             restart: int | None) -> Found | None:
    """Verify a polished solution: exactly when its entries (or, with ``closed``, those of a
    nearby member of its family, see :func:`~rkhp.search.recognise.find_closed_form`) have closed
    forms that satisfy the conditions, else at D digits. None if the verification disagrees with
    the search."""
    from ..tableaux.verification import verify
    exact = recognise_point(problem.system(), polished)
    if exact is None and closed:
        exact, _ = find_closed_form(problem.system(), x_float, digits)
    if exact is not None:
        tab = make_tableau(problem, exact, name)
        ver = verify(tab, max_order=problem.order + 1, precision="exact")
        if ver.orders[problem.cls] >= problem.order:
            return Found(problem.order, tab, ver, 0.0, restart)
    tab = make_tableau(problem, list(polished.x), name)
    ver = verify(tab, max_order=problem.order + 1, precision=digits)
    if ver.orders[problem.cls] >= problem.order:
        return Found(problem.order, tab, ver, polished.residual, restart)
    return None


def method_name(problem: Problem) -> str:
    """``search-<class>-o<order>-s<stages>`` (``-implicit`` added for implicit tableaux)."""
    kind = "-implicit" if problem.implicit else ""
    return f"search-{problem.cls}-o{problem.order}-s{problem.stages}{kind}"


def content_name(tableau, base: str) -> str:
    """``base-<8 hex digits>``: the digits hash the entries of A and b, so that two files hold the
    same name only when they hold the same tableau."""
    from ..tableaux.tableau import entry_text

    text = ";".join(",".join(entry_text(x) for x in row) for row in tableau.A)
    text += "|" + ",".join(entry_text(x) for x in tableau.b)
    return f"{base}-{hashlib.sha256(text.encode()).hexdigest()[:8]}"


def search(stages: int, order: int | None = None, cls: str = "general", implicit: bool = False,
           options: SearchOptions = SearchOptions(), on_progress=None, executor=None,
           on_proof_progress=None) -> SearchResult:
    """Search tableaux (see the module docstring). ``on_progress(order, done, total)``; the
    restarts run on ``executor`` (:mod:`rkhp.base.executors`; default: in this process), with the same
    result whatever the executor. ``on_proof_progress(order, step, elapsed, limit)`` follows
    the proof (:func:`rkhp.search.prove.prove_impossible`)."""
    check_problem(stages, order)
    check_class(cls)
    options.check()
    t0 = time.perf_counter()
    orders = [order] if order is not None else list(range(1, MAX_SEARCH_ORDER + 1))
    runs: list[Restarts] = []
    best: Found | None = None
    firsts: dict[int, float] = {}
    interrupted = False
    optimisation = None
    try:
        for n in orders:
            problem = Problem(stages, n, cls, implicit)
            want_many = options.optimize and (order is None or n == order)
            left = _time_left(options, t0)
            if left is not None and left <= 0.0:
                break  # the limit is for the whole search, every order included
            run = run_restarts(
                problem, options.restarts, options.seed, executor, left,
                options.digits, stop_after=OPTIMISATION_STARTS if want_many else 1,
                on_progress=None if on_progress is None else
                (lambda d, tot, n=n: on_progress(n, d, tot)))
            runs.append(run)
            interrupted = run.interrupted
            first = run.first
            if first is None or interrupted:
                break
            found = verified(problem, first.x, first.polished, options.digits,
                             options.closed_form and order is not None, method_name(problem),
                             first.index)
            if found is None:
                break
            firsts[n] = time.perf_counter() - t0
            best = found
        left = _time_left(options, t0)
        if best is not None and order is None and options.closed_form and not interrupted and (
                left is None or left > 0.0):
            problem = Problem(stages, best.order, cls, implicit)
            run = next(r for r in runs if r.problem.order == best.order)
            best = verified(problem, run.first.x, run.first.polished, options.digits, True,
                            method_name(problem), run.first.index) or best
        if best is not None and options.optimize and not interrupted and (left is None or left > 0.0):
            optimise = _optimise if options.optimize == "error" else _optimise_phase
            best, optimisation = optimise(Problem(stages, best.order, cls, implicit),
                                          runs[[r.problem.order for r in runs].index(best.order)],
                                          options, best)
    except KeyboardInterrupt:
        interrupted = True
    proof = proof_order = None
    result_runs = tuple(runs)
    failed = next((r for r in result_runs if r.first is None), None)
    if options.prove and failed is not None and not interrupted:
        proof_order = failed.problem.order
        try:
            left = _time_left(options, t0)
            proof = prove_impossible(
                failed.problem.system(), DEFAULT_PROOF_SECONDS if left is None else max(left, 0.0),
                options.proof_engine, None if on_proof_progress is None else
                (lambda step, done, limit, n=proof_order: on_proof_progress(n, step, done, limit)))
        except KeyboardInterrupt:
            interrupted = True
    return SearchResult(stages, cls, implicit, order, best, result_runs,
                        time.perf_counter() - t0, options, proof, proof_order, optimisation,
                        interrupted, firsts)


def _time_left(options: SearchOptions, t0: float) -> float | None:
    """Seconds left of --time-limit (the whole search's), None without one."""
    if options.time_limit is None:
        return None
    return options.time_limit - (time.perf_counter() - t0)


def _optimise(problem: Problem, run: Restarts, options: SearchOptions, found: Found):
    """Minimise the principal error from the run's successes; the optimum (verified) if better."""
    system = problem.system()
    starts = [a.x for a in run.successes]
    opt = minimise_error(system, starts)
    known = tuple(known_methods(system))
    if opt is None:
        return found, Optimisation(float("nan"), len(starts), known, None)
    refined = refine_optimum(system, opt.x, options.digits)
    pol = polish(system, refined.x if refined.converged else np.array(opt.x), options.digits)
    candidate = None
    if pol.converged:
        name = method_name(problem) + "-min-error"
        candidate = verified(problem, opt.x, pol, options.digits, False, name, None)
    best = candidate or found
    norm = best.verification.principal_error.get(problem.cls)
    kkt = refined.kkt_residual if candidate is not None and refined.converged else None
    return best, Optimisation(norm, len(starts), known, kkt)


def _optimise_phase(problem: Problem, run: Restarts, options: SearchOptions, found: Found):
    """Minimise the phase error from the run's successes (`minimise_phase`), polish the optimum
    with its annihilated powers at D digits; the optimum (verified) if it verifies."""
    system = problem.system()
    starts = [a.x for a in run.successes]
    opt = minimise_phase(system, starts)
    known = tuple(known_methods(system))
    candidate = None
    if opt is not None:
        pol = polish_phase(system, opt, options.digits)
        if pol.converged:
            candidate = verified(problem, opt.x, pol, options.digits, False,
                                 method_name(problem) + "-min-phase", None)
    best = candidate or found
    norm = best.verification.principal_error.get(problem.cls)
    if candidate is None:
        return best, Optimisation(norm, len(starts), known, None, "phase")
    return best, Optimisation(norm, len(starts), known, None, "phase", opt.phase_order, opt.phase_constant)
