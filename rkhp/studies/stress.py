"""Stress tests of numerical stability (paper §5.2: the implicit step may have no solution).

(a) step sizes swept upward to T: the largest h at which every Newton solve converges and the
    error stays bounded (relative energy error and relative error at T at most 1), and the range
    where the run fails;
(b) a long run (>= 10^5 steps by default): Casimir and energy error per window (the maximum in
    each window), against classical RK4 on the ODE; for an RKHP method also the error of its
    modified Hamiltonian H~_N (docs/modified.md), N = the method's order in the class + 2 (at most
    8, lower where the tree series stops), evaluated on at most MODIFIED_SAMPLES evenly strided
    states;
(c) near-singular starts of a log-canonical system (first species at 1e-3 and 1e-6): positivity
    and Casimir kept;
(d) tiny steps (h = T/N down to T/10^5): where the round-off floor starts, i.e. the first step
    size past the asymptotic range of the fit of :mod:`rkhp.studies.fit`, for the error at T
    (limited by the reference's accuracy) and for the energy error (which needs no reference).
Each part ends with a plain verdict line.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from ..base import bounds
from ..base.errors import InputError
from ..base.executors import InProcess, run_all, run_until_interrupted
from ..base.interrupts import is_interrupt
from ..base.json_form import json_form
from ..integrators.failure import Failure
from ..integrators.methods import condition_class, require_steps, resolve_method, resolve_methods, resolve_system
from ..integrators.modified_energy import ModifiedEnergy, method_series
from ..series.modified import MAX_ORDER, method_character
from ..systems.families import LOG_CANONICAL
from .converge import check_t_final, study_methods
from .fit import fit_order
from .invariants import declared_errors, invariant_deviations, max_deviations, window_maxima
from .reference import reference

SWEEP_COARSEST = 200
SWEEP_FACTOR = 2 ** 0.25
LONG_STEPS = 100_000
LONG_WINDOWS = 10
SINGULAR_VALUES = (1e-3, 1e-6)
SINGULAR_STEPS = 200
ROUND_OFF_STEPS = tuple(int(round(10 ** (1.5 + k / 2))) for k in range(8))
NOT_RUN = "not run (interrupted)"
PEER = "classical:rk4"
"""Part (b)'s peer, run besides the methods (once, also when it is one of them)."""
CASIMIR_KEPT = 1e-10
"""A Casimir error at most this (over a whole run) counts as kept."""
MODIFIED_SAMPLES = 2000
"""Part (b) evaluates H~_N on at most this many states of a long run (a stride, first and last
state included): about 1 ms per state at N = 6 on the rigid body."""


def _fmt(x: float | None) -> str:
    return "n/a" if x is None else f"{x:.2g}"


@dataclass(frozen=True)
class SweepRow:
    """One run of part (a): ``steps`` steps of size ``h`` to T; errors relative to |x(T)|, |H(x0)|;
    ``failure``: how the run ended (`rkhp.integrators.failure`), ``status`` its status line."""

    h: float
    steps: int
    status: str
    newton_max: int
    relative_error: float | None
    relative_energy_error: float | None
    failure: Failure = Failure.OK

    json_keys = ("h", "steps", "ok", "status", "cause", "newton_max", "relative_error",
                 ("relative_energy_error_max", "relative_energy_error"))

    @property
    def ok(self) -> bool:
        return (self.failure == Failure.OK and self.relative_error is not None and self.relative_error <= 1.0
                and self.relative_energy_error <= 1.0)

    @property
    def cause(self) -> str:
        """Why the run does not count: the failure's cause, or an unbounded error."""
        if self.failure != Failure.OK:
            return self.failure.text
        return "" if self.ok else "error not bounded (relative error or energy error above 1)"


@dataclass(frozen=True)
class SweepResult:
    """Part (a) for one method, rows in increasing h."""

    method: str
    rows: tuple[SweepRow, ...]

    json_keys = ("method", "largest_ok_h", "first_failure_h", ("first_failure", "first_failure_status"), "rows",
                 "verdict")

    @property
    def largest_ok_h(self) -> float | None:
        """The largest h below the first failure (every smaller h in the sweep also succeeded)."""
        best = None
        for r in self.rows:
            if not r.ok:
                break
            best = r.h
        return best

    @property
    def first_failure(self) -> SweepRow | None:
        return next((r for r in self.rows if not r.ok), None)

    @property
    def first_failure_h(self) -> float | None:
        bad = self.first_failure
        return None if bad is None else bad.h

    @property
    def first_failure_status(self) -> str | None:
        bad = self.first_failure
        return None if bad is None else bad.status

    def verdict(self) -> str:
        bad = self.first_failure
        if bad is None:
            return (f"{self.method}: Newton converges and the error stays bounded for every h up to "
                    f"{self.rows[-1].h:.3g}")
        failing = [r.h for r in self.rows if not r.ok]
        if self.largest_ok_h is None:
            return (f"{self.method}: fails at the smallest step size tried, h = {bad.h:.3g} ({len(failing)} of "
                    f"{len(self.rows)} step sizes fail, in [{min(failing):.3g}, {max(failing):.3g}]; first cause: "
                    f"{bad.cause}); sweep from a smaller h (--sweep-coarsest)")
        return (f"{self.method}: Newton converges and the error stays bounded up to h = {_fmt(self.largest_ok_h)}; "
                f"fails from h = {bad.h:.3g} ({len(failing)} of {len(self.rows)} step sizes, in "
                f"[{min(failing):.3g}, {max(failing):.3g}]; first cause: {bad.cause})")


def sweep(method, system, t_final: float, coarsest: int = SWEEP_COARSEST, factor: float = SWEEP_FACTOR) -> SweepResult:
    """Part (a): h = T/n for n = coarsest, coarsest/factor, ... 1 (distinct n), upward in h."""
    ref = reference(system, t_final)
    scale = float(np.linalg.norm(ref.state))
    H0 = abs(float(system.hamiltonian(np.asarray(system.x0, dtype=float)))) or 1.0
    counts = sorted({max(1, int(round(coarsest / factor**k))) for k in range(int(math.log(coarsest, factor)) + 2)},
                    reverse=True)
    rows = []
    for n in counts:
        h = t_final / n
        traj = method.integrate(system, h, n)
        newton = np.asarray(traj.newton_iterations)
        n_max = int(newton.max()) if newton.size else 0
        if traj.ok:
            err = float(np.linalg.norm(traj.final_state - ref.state)) / scale
            _, energy = max_deviations(system, traj.states)
            rows.append(SweepRow(h, n, "ok", n_max, err, energy / H0))
        else:
            rows.append(SweepRow(h, n, traj.status, n_max, None, None, traj.cause))
    return SweepResult(method.name, tuple(rows))


@dataclass(frozen=True)
class LongRun:
    """Part (b) for one method: the maximum Casimir and energy error in each window."""

    method: str
    casimir_windows: tuple[float, ...]
    energy_windows: tuple[float, ...]
    status: str
    seconds: float
    modified: ModifiedWindows | None = None
    failure: Failure = Failure.OK
    kind: str = "rkhp"
    invariant_errors: tuple[float, ...] = ()

    #: RUN of docs/json.md "rkhp stress"
    json_keys = ("method", "status", "casimir_windows", "energy_windows", "casimir_max", "energy_growth", "seconds",
                 ("invariant_errors_max", "invariant_errors"), "invariant_max", ("modified_energy", "modified"))

    @property
    def invariant_max(self) -> float | None:
        """The largest drift of the declared invariants; None for a system without any."""
        return max(self.invariant_errors) if self.invariant_errors else None

    @property
    def casimir_max(self) -> float | None:
        """The largest Casimir error of the run; None for a system without Casimirs."""
        return max(self.casimir_windows) if self.casimir_windows else None

    @property
    def energy_growth(self) -> float | None:
        """Energy error of the last window over that of the first (about 1: bounded; about the
        number of windows: linear drift); None when the first window's error is 0."""
        first = self.energy_windows[0]
        return self.energy_windows[-1] / first if first > 0 else None


@dataclass(frozen=True)
class ModifiedWindows:
    """Part (b): max |H~_N(y_n) - H~_N(y_0)| per window, over the states n multiple of ``stride``."""

    order: int
    condition_class: str
    stride: int
    windows: tuple[float, ...]

    json_keys = ("order", ("class", "condition_class"), "stride", "windows", "max")

    @property
    def max(self) -> float:
        return max(self.windows)


@dataclass(frozen=True)
class LongRunResult:
    """Part (b): the methods' long runs and the classical RK4 peer's."""

    h: float
    steps: int
    windows: int
    runs: tuple[LongRun, ...]
    peer: LongRun

    json_keys = ("h", "steps", "windows", "runs", "peer", "verdict")

    def verdict(self) -> str:
        rkhp = [r for r in self.runs if r.kind == "rkhp"]
        kept = [r for r in rkhp if r.failure == Failure.OK and r.casimir_max is not None
                and r.casimir_max <= CASIMIR_KEPT]
        parts = [f"{r.method} Casimir {_fmt(r.casimir_max)}, energy growth x{_fmt(r.energy_growth)}" for r in self.runs]
        peer = self.peer
        if peer.casimir_max is None:
            head = f"over {self.steps} steps (the system has no Casimir)"
        else:
            head = (f"over {self.steps} steps, {len(kept)} of {len(rkhp)} RKHP methods keep the Casimir "
                    f"(<= {CASIMIR_KEPT:g})")
        return (f"{head}: {'; '.join([*parts, ''])}{peer.method} (the peer) drifts to Casimir "
                f"{_fmt(peer.casimir_max)}, energy growth x{_fmt(peer.energy_growth)}")


def _long_run(method, system, h: float, steps: int, windows: int) -> LongRun:
    traj = method.integrate(system, h, steps)
    casimir, energy = invariant_deviations(system, traj.states)
    modified = _modified_windows(method, system, h, traj.states, windows) if method.kind == "rkhp" and traj.ok else None
    casimirs = tuple(window_maxima(casimir, windows)) if system.casimirs else ()
    return LongRun(method.name, casimirs, tuple(window_maxima(energy, windows)),
                   traj.status, traj.run_seconds, modified, traj.cause, method.kind,
                   tuple(declared_errors(system, traj.states)))


def _modified_windows(method, system, h: float, states, windows: int) -> ModifiedWindows | None:
    """H~_N's error per window (None for a tableau given in decimals: no exact series)."""
    cls = condition_class(system)
    order = min(MAX_ORDER, method.expected_order(cls) + 2)
    if not method.tableau.is_exact:
        return None
    series = method_series(method_character(method.tableau, order), order, cls)
    stride = max(1, math.ceil((len(states) - 1) / MODIFIED_SAMPLES))
    picked = np.unique(np.append(np.arange(0, len(states), stride), len(states) - 1))
    values = ModifiedEnergy(system, series, h).along(np.asarray(states)[picked])
    full = np.full(len(states), np.nan)
    full[picked] = np.abs(values - values[0])
    maxima = tuple(float(np.nanmax(c)) for c in np.array_split(full, windows) if len(c) and not np.isnan(c).all())
    return ModifiedWindows(series.order, cls, stride, maxima)


def long_run(methods, system, h: float, steps: int = LONG_STEPS, windows: int = LONG_WINDOWS,
             executor=None) -> LongRunResult:
    """Part (b): Casimir and energy error per window, the methods against classical RK4 (one task
    per method on ``executor``, rkhp.base.executors)."""
    if steps < windows:
        raise InputError(f"a long run needs at least {windows} steps, got {steps}")
    peer = resolve_method(PEER)
    everyone = [*(m for m in methods if m.name != peer.name), peer]  # a method named as the peer runs once
    *runs, peer = run_all(executor or InProcess(), _long_run, [(m, system, h, steps, windows) for m in everyone])
    return LongRunResult(h, steps, windows, tuple(runs), peer)


@dataclass(frozen=True)
class NearSingularRun:
    """Part (c): one method from a start with the first species at ``first_species``."""

    method: str
    first_species: float
    status: str
    min_component: float | None
    casimir_error: float | None
    failure: Failure = Failure.OK

    json_keys = ("method", "first_species", "status", "min_component", ("casimir_error_max", "casimir_error"), "kept")

    @property
    def kept(self) -> bool:
        return (self.failure == Failure.OK and self.min_component > 0
                and (self.casimir_error is None or self.casimir_error <= CASIMIR_KEPT))


@dataclass(frozen=True)
class SingularResult:
    """Part (c): every run, or why the part does not apply."""

    applicable: bool
    runs: tuple[NearSingularRun, ...]
    reason: str = ""

    json_keys = ("applicable", "runs", "verdict")

    def verdict(self) -> str:
        if not self.applicable:
            return f"not applicable: {self.reason}"
        bad = [r for r in self.runs if not r.kept]
        if not bad:
            worst = max((r.casimir_error for r in self.runs if r.casimir_error is not None), default=None)
            return f"positivity and Casimir (to {_fmt(worst)}) kept by every method from every near-singular start"
        return "; ".join(f"{r.method} from x1 = {r.first_species:g}: "
                         + (r.status if r.failure != Failure.OK else
                            f"min component {r.min_component:.3g}, Casimir error {_fmt(r.casimir_error)}")
                         for r in bad) + " (not kept)"


def near_singular(methods, system, t_final: float, steps: int = SINGULAR_STEPS,
                  values=SINGULAR_VALUES, executor=None) -> SingularResult:
    """Part (c): starts with the first species at 1e-3 and 1e-6 (log-canonical systems only), one
    task per start and method on ``executor`` (rkhp.base.executors)."""
    if system.family != LOG_CANONICAL:
        return SingularResult(False, (), f"near-singular starts are defined for log-canonical systems, "
                                         f"{system.name} is {system.family}")
    runs = run_all(executor or InProcess(), _near_singular_run,
                   [(m, system, t_final, steps, value) for value in values for m in methods])
    return SingularResult(True, tuple(runs))


def _near_singular_run(method, system, t_final: float, steps: int, value: float) -> NearSingularRun:
    x0 = np.array(system.x0, dtype=float)
    x0[0] = value
    traj = method.integrate(system, t_final / steps, steps, x0=x0)
    if not traj.ok:
        return NearSingularRun(method.name, value, traj.status, None, None, traj.cause)
    casimir, _ = max_deviations(system, traj.states)
    return NearSingularRun(method.name, value, "ok", float(traj.states.min()), casimir)


def _floor_row(fit) -> int | None:
    rows = [i for i, why in fit.excluded if why == "round-off floor"]
    return rows[0] if rows else None


@dataclass(frozen=True)
class RoundOffResult:
    """Part (d). ``studies``: the convergence tables (error at T against the reference);
    ``energy_fits``: fits of the energy error (max over the run), which needs no reference, so its
    round-off floor shows even where the error at T is below the reference's accuracy."""

    t_final: float
    reference_kind: str
    reference_floor: float
    studies: tuple
    energy_fits: tuple

    json_keys = ("t_final", ("reference", "reference_summary"), ("methods", "method_rows"), "verdict")

    @property
    def reference_summary(self) -> dict:
        return {"kind": self.reference_kind, "floor": self.reference_floor}

    @property
    def method_rows(self) -> list[dict]:
        """Each method's convergence table (as ``rkhp converge`` gives it) with the round-off
        floors of its error at T and of its energy error, and the energy error's observed order."""
        out = []
        for m, energy in zip(self.studies, self.energy_fits, strict=True):
            floor, e_floor = _floor_row(m.fit), _floor_row(energy)
            out.append({**json_form(m), "floor_h": None if floor is None else m.rows[floor].h,
                        "energy_observed_order": energy.slope,
                        "energy_floor_h": None if e_floor is None else m.rows[e_floor].h})
        return out

    @staticmethod
    def _line(m, energy) -> str:
        floor = _floor_row(m.fit)
        below = [i for i, why in m.fit.excluded if why == "below reference accuracy"]
        if floor is not None:
            r = m.rows[floor]
            head = (f"{m.method}: error at T reaches a round-off floor from h = {r.h:.3g} "
                    f"(error {_fmt(r.measured_error)})")
        elif below:
            head = (f"{m.method}: error at T reaches the reference's accuracy at h = {m.rows[below[0]].h:.3g} "
                    f"before any round-off floor")
        else:
            head = f"{m.method}: no round-off floor in the error at T down to h = {m.rows[-1].h:.3g}"
        e_floor = _floor_row(energy)
        if e_floor is not None:
            r = m.rows[e_floor]
            return f"{head}; energy error at its round-off floor from h = {r.h:.3g} ({_fmt(r.energy_error)})"
        return f"{head}; no round-off floor in the energy error down to h = {m.rows[-1].h:.3g}"

    def verdict(self) -> str:
        return "; ".join(self._line(m, e) for m, e in zip(self.studies, self.energy_fits, strict=True))


def round_off(methods, system, t_final: float, steps=ROUND_OFF_STEPS, executor=None) -> RoundOffResult:
    """Part (d): errors at T and energy errors for h down to T/10^5; the first row past the
    asymptotic range of each fit (energy errors at or below 2 eps |H(x0)| are not measurements).
    Each run is a task on ``executor`` (rkhp.base.executors)."""
    ref = reference(system, t_final)
    studies = study_methods(methods, system, ref, tuple(steps), t_final, executor=executor)
    h0 = abs(float(system.hamiltonian(np.asarray(system.x0, dtype=float))))
    energy_floor = 2 * np.finfo(float).eps * max(h0, 1e-300)
    energy = tuple(fit_order([r.h for r in m.rows], [r.energy_error for r in m.rows], floor=energy_floor)
                   for m in studies)
    return RoundOffResult(t_final, ref.kind, ref.floor, studies, energy)


@dataclass(frozen=True)
class StressStudy:
    """``rkhp stress``'s result (JSON keys in the README's studies section)."""

    system: str
    realisation: str
    t_final: float
    sweep: tuple[SweepResult, ...]
    long_run: LongRunResult | None
    near_singular: SingularResult | None
    round_off: RoundOffResult | None
    x0: tuple[float, ...] = ()
    interrupted: bool = False

    json_keys = ("system", "realisation", "x0", "t_final", "interrupted", ("sweep", "sweep_part"), "long_run",
                 "near_singular", "round_off")

    @property
    def sweep_part(self) -> dict:
        """Part (a): every method's sweep and their verdict."""
        return {"methods": self.sweep, "verdict": self.verdicts()["a"]}

    def verdicts(self) -> dict[str, str]:
        """Each part's verdict ("not run (interrupted)" for a part an interrupt left out)."""
        def verdict_of(part):
            return NOT_RUN if part is None else part.verdict()

        return {"a": " | ".join(s.verdict() for s in self.sweep) if self.sweep or not self.interrupted else NOT_RUN,
                "b": verdict_of(self.long_run), "c": verdict_of(self.near_singular), "d": verdict_of(self.round_off)}


def stress(system, methods, t_final=None, long_steps: int = LONG_STEPS, long_h: float | None = None,
           sweep_coarsest: int = SWEEP_COARSEST, round_off_steps=ROUND_OFF_STEPS, on_part=None,
           executor=None) -> StressStudy:
    """Run parts (a)-(d) for ``methods`` (names of :mod:`rkhp.integrators.methods` or Methods; the defaults
    when empty) on ``system`` (a name, a spec file or a PoissonSystem), one part after the other,
    each part's independent runs as tasks on ``executor`` (rkhp.base.executors; default: in this
    process); the results do not depend on it. Ctrl-C ends the study early: ``interrupted`` is then
    True, with the parts finished before it (of part (a): the methods' sweeps finished), the
    others None."""
    system = resolve_system(system)
    methods = require_steps(resolve_methods(methods))
    t_final = check_t_final(system.t_final if t_final is None else t_final)
    bounds.integer(long_steps, "--long-steps", 1, bounds.MAX_STEPS)
    bounds.integer(sweep_coarsest, "--sweep-coarsest", 1, bounds.MAX_STEPS)
    round_off_steps = tuple(bounds.integer(n, "--round-off-steps", 1, bounds.MAX_STEPS) for n in round_off_steps)
    bounds.check_trajectory(max(long_steps, sweep_coarsest, *round_off_steps), system.dim, "the longest run")
    h_long = t_final / 100 if long_h is None else bounds.positive(long_h, "--long-h")

    def tick(part):
        if on_part:
            on_part(part)

    executor = executor or InProcess()
    x0 = tuple(float(v) for v in system.x0)
    found, interrupted = run_until_interrupted(executor, sweep, [(m, system, t_final, sweep_coarsest)
                                                                 for m in methods])
    a = tuple(r for r in found if r is not None)
    parts = []
    if not interrupted:
        tick("a")
        try:
            parts.append(long_run(methods, system, h_long, long_steps, executor=executor))
            tick("b")
            parts.append(near_singular(methods, system, t_final, executor=executor))
            tick("c")
            parts.append(round_off(methods, system, t_final, round_off_steps, executor=executor))
            tick("d")
        except BaseException as exc:
            if not is_interrupt(exc):
                raise
            interrupted = True
    b, c, d = (*parts, None, None, None)[:3]
    return StressStudy(system.name, system.realisation, t_final, a, b, c, d, x0, interrupted)
