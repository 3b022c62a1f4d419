"""Work-precision: time against global error, for the methods and their peers.

Every method runs over numbers of steps; the adaptive peers (:mod:`rkhp.studies.peers`: scipy's
``solve_ivp`` on a plain-arithmetic field, numbalsoda's compiled DOP853, diffrax under ``jax.jit``)
run over tolerances. A point's times are the minima over ``repeats`` calls of the CPU time of the
calling thread (``cpu_seconds``, what the cheapest point is chosen by) and of the wall time
(``seconds``), after one warm-up call per curve whose compile (or trace) time is kept apart. A
peer whose package is not installed is named in ``absent_peers``. Without an ensemble, in this
process, the calls are interleaved: every curve is warmed up first, then each of the ``repeats``
rounds times every point of every curve once (each round starting one point further on), so that
a change of the machine's load or clock during the study falls on all curves alike
(:func:`_interleaved_curves`); with an executor of several workers each curve is one task, timed
on the worker that runs it. The error is
the 2-norm at T against the best reference rkhp has (:func:`rkhp.studies.peers.best_reference`:
the closed form, or the tighter of scipy's and the compiled DOP853); an error not above the
reference's accuracy is not a measurement (``error`` None) but still counts as reaching a target
error above that accuracy.

Ensemble mode (``ensemble`` = K): every point times K initial conditions near x0 (seeded); RKHP
methods and compositions run all K at once (`Method.integrate_ensemble`: threads over the
compiled loop, the final states those of one run at a time), the peers one after another on the
first min(K, ENSEMBLE_TIMED) starts; times are minimum wall times per trajectory (the RKHP
ensemble may run on several threads: no ``cpu_seconds``) and the error is the largest over the
first min(K, ENSEMBLE_CHECKED) starts, each against its own DOP853 reference.

Without methods, the bench races BENCH_METHODS (`rkhp.integrators.methods`), less any whose
estimated cost on the system exceeds BENCH_DEFAULT_SECONDS (`default_methods`; named in
``left_out``).
"""

from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import dataclass
from typing import NamedTuple

import numpy as np

from ..base import bounds
from ..base.errors import InputError
from ..base.executors import run_until_interrupted
from ..base.interrupts import Interrupted, is_interrupt
from ..integrators.methods import BENCH_METHODS, SCIPY_METHODS, Method, check_distinct, resolve_method, resolve_system
from .converge import check_t_final
from .peers import (
    ADAPTIVE_KINDS,
    ATOL_RATIO,
    COMPILED_PEERS,
    Peer,
    absent,
    best_reference,
    compiled_peer,
    plain_field,
    prepare,
    scipy_peer,
)
from .reference import Reference, dop853_reference

TARGETS = (1e-4, 1e-6, 1e-8, 1e-10, 1e-12)
DEFAULT_STEPS = tuple(10 * 2**k for k in range(9))
DEFAULT_TOLERANCES = tuple(10.0**-k for k in range(3, 14))
DEFAULT_PEERS = ("numbalsoda:dop853", "scipy:dop853", "scipy:rk45", "classical:rk4", "implicit-midpoint")
PEER_KINDS = ("scipy", "numbalsoda", "diffrax", "classical", "implicit-midpoint", "taylor")
#: Bare peer names of earlier versions (each is also a tableau name): refused with their spelling.
FORMER_PEER_NAMES = {**{k: f"scipy:{k}" for k in SCIPY_METHODS}, "rk4": "classical:rk4",
                     "midpoint": "implicit-midpoint (the implicit midpoint rule) or classical:midpoint"}
ENSEMBLE_TIMED = 16
ENSEMBLE_CHECKED = 4
ENSEMBLE_SPREAD = 0.05


@dataclass(frozen=True)
class BenchPoint:
    """One setting: ``steps`` (integrators) or ``tolerance`` (adaptive peers, rtol; atol = 1e-3 rtol);
    ``seconds`` wall and ``cpu_seconds`` CPU time of the calling thread (None in ensemble mode),
    minima over the repeats."""

    steps: int | None
    tolerance: float | None
    error: float | None
    measured_error: float | None
    seconds: float
    evaluations: int | None
    status: str
    cpu_seconds: float | None = None

    json_keys = ("steps", "tolerance", "error", "seconds", "cpu_seconds", "evaluations", "status")

    @property
    def cost(self) -> float:
        """What the cheapest point is chosen by: CPU seconds where measured, else wall seconds."""
        return self.seconds if self.cpu_seconds is None else self.cpu_seconds


@dataclass(frozen=True)
class BenchCurve:
    """A method's (or peer's) work-precision points; kind: rkhp, composition, taylor, classical,
    implicit-midpoint, or a peer's: scipy, numbalsoda, diffrax."""

    method: str
    kind: str
    compile_seconds: float
    trajectories: int
    points: tuple[BenchPoint, ...]


@dataclass(frozen=True)
class Cheapest:
    """The cheapest measured point (by :attr:`BenchPoint.cost`) whose error is at most ``target``
    (method None if none)."""

    target: float
    method: str | None
    setting: str | None
    seconds: float | None
    error: float | None
    cpu_seconds: float | None = None

    json_keys = ("target", "method", "setting", "seconds", "cpu_seconds", "error")


class AbsentPeer(NamedTuple):
    """A peer asked for whose package is not installed, and the line that says so."""

    peer: str
    reason: str


class LeftOutMethod(NamedTuple):
    """A method of the default list left out of a race for its estimated CPU time."""

    method: str
    estimated_seconds: float


@dataclass(frozen=True)
class BenchStudy:
    """``rkhp bench``'s result (JSON keys in the README's studies section)."""

    system: str
    realisation: str
    t_final: float
    reference: Reference
    repeats: int
    ensemble: int | None
    curves: tuple[BenchCurve, ...]
    cheapest: tuple[Cheapest, ...]
    targets: tuple[float, ...] = TARGETS
    x0: tuple[float, ...] = ()
    interrupted: bool = False
    absent_peers: tuple[tuple[str, str], ...] = ()
    left_out: tuple[LeftOutMethod, ...] = ()

    json_keys = ("system", "realisation", "x0", "t_final", "interrupted", ("reference", "reference_summary"),
                 "repeats", "ensemble", "curves", "cheapest", ("absent_peers", "absent_peer_reasons"), "left_out")

    @property
    def reference_summary(self) -> dict:
        return {"kind": self.reference.kind, "error_estimate": self.reference.error_estimate}

    @property
    def absent_peer_reasons(self) -> tuple[AbsentPeer, ...]:
        return tuple(AbsentPeer(name, reason) for name, reason in self.absent_peers)


def resolve_peer(name) -> Method:
    """A peer: a compiled peer of :data:`rkhp.studies.peers.COMPILED_PEERS` (``numbalsoda:dop853``,
    ``diffrax:dopri8``, ``diffrax:tsit5``), or a method of the grammar of
    :mod:`rkhp.integrators.methods` that is not an RKHP tableau (``scipy:NAME``, ``classical:NAME``,
    ``implicit-midpoint``, ``thpN``). A bare tableau name is refused, so that a name means the same
    in --peers as in --method (docs/methods.md)."""
    compiled = compiled_peer(name)
    if compiled is not None:
        return Method(compiled.name, compiled.kind, solver=compiled.solver)
    key = name.strip().lower() if isinstance(name, str) else None
    if key in FORMER_PEER_NAMES:
        raise InputError(f"peer {name!r} is a tableau name, an RKHP method (give it with --method); "
                         f"as a peer write {FORMER_PEER_NAMES[key]}")
    method = resolve_method(name)
    if method.kind not in PEER_KINDS:
        raise InputError(f"peer {method.name!r} is an RKHP method: give it with --method; peers are "
                         f"{', '.join(COMPILED_PEERS)}, scipy:NAME, classical:NAME, implicit-midpoint or thpN")
    return method


def peer_of(method: Method) -> Peer:
    """The :class:`rkhp.studies.peers.Peer` that runs an adaptive peer's Method."""
    return scipy_peer(method.solver) if method.kind == "scipy" else COMPILED_PEERS[method.name]


def _least_seconds(call, repeats: int):
    """(minimum wall seconds of ``repeats`` calls, the last call's result)."""
    best, result = float("inf"), None
    for _ in range(repeats):
        start = time.perf_counter()
        result = call()
        best = min(best, time.perf_counter() - start)
    return best, result


class Outcome(NamedTuple):
    """What one call of a point gives: its measured error (None: failed), f evaluations (scipy), status
    and the compile time the engine (or the peer's preparation) reported."""

    measured: float | None
    evaluations: int | None
    status: str
    compile_seconds: float


class Setting(NamedTuple):
    """A point to time: its curve (index), its setting (``steps`` or ``tolerance``) and its call."""

    curve: int
    steps: int | None
    tolerance: float | None
    call: Callable[[], Outcome]


def _method_call(method: Method, system, ref: Reference, n: int, t_final: float) -> Callable[[], Outcome]:
    def call_method() -> Outcome:
        traj = method.integrate(system, t_final / n, n, keep_all=False)
        measured = float(np.linalg.norm(traj.final_state - ref.state)) if traj.ok else None
        return Outcome(measured, None, traj.status, float(traj.compile_seconds))

    return call_method


def _peer_call(prepared, system, ref: Reference, rtol: float) -> Callable[[], Outcome]:
    x0 = np.asarray(system.x0, dtype=float)

    def call_peer() -> Outcome:
        sol = prepared.solve(x0, rtol)
        measured = float(np.linalg.norm(sol.state - ref.state)) if sol.ok else None
        return Outcome(measured, sol.evaluations, sol.message, prepared.compile_seconds)

    return call_peer


def _settings(curves, system, ref: Reference, steps, tolerances, t_final: float) -> list[Setting]:
    """Every point of every curve (integrators over ``steps``, adaptive peers over ``tolerances``,
    each peer prepared once: :func:`rkhp.studies.peers.prepare`)."""
    out = []
    for k, m in enumerate(curves):
        if m.kind in ADAPTIVE_KINDS:
            prepared = prepare(peer_of(m), system, t_final)
            out += [Setting(k, None, rtol, _peer_call(prepared, system, ref, rtol)) for rtol in tolerances]
        else:
            out += [Setting(k, n, None, _method_call(m, system, ref, n, t_final)) for n in steps]
    return out


def _timed(call) -> tuple[float, float, Outcome]:
    """(wall seconds, CPU seconds of the calling thread, outcome) of one call."""
    start, cpu = time.perf_counter(), time.thread_time()
    outcome = call()
    return time.perf_counter() - start, time.thread_time() - cpu, outcome


def _interleaved_curves(curves, system, ref: Reference, steps, tolerances, t_final: float, repeats: int,
                        on_curve=None) -> tuple[list[BenchCurve], bool]:
    """The curves of ``curves`` (Methods) timed in this process, interleaved (see the module): a
    warm-up call per curve, then ``repeats`` rounds over all points. Returns the curves and whether
    an interrupt cut the study short (the points then have the rounds finished before it; points
    never timed are left out)."""
    settings = _settings(curves, system, ref, steps, tolerances, t_final)
    times: list[list[float]] = [[] for _ in settings]
    cpu: list[list[float]] = [[] for _ in settings]
    outcomes: list[Outcome | None] = [None] * len(settings)
    compile_seconds = [0.0] * len(curves)
    calls = len(curves) + repeats * len(settings)
    done = 0
    interrupted = False

    def advance():
        nonlocal done
        done += 1
        if on_curve:
            on_curve(len(curves) * done / calls, len(curves))

    try:
        for k in range(len(curves)):
            first = next(s for s in settings if s.curve == k)
            compile_seconds[k] = first.call().compile_seconds
            advance()
        for r in range(repeats):
            for j in range(len(settings)):
                i = (j + r) % len(settings)
                seconds, cpu_seconds, outcome = _timed(settings[i].call)
                times[i].append(seconds)
                cpu[i].append(cpu_seconds)
                outcomes[i] = outcome
                compile_seconds[settings[i].curve] = max(compile_seconds[settings[i].curve], outcome.compile_seconds)
                advance()
    except BaseException as exc:
        if not is_interrupt(exc):
            raise
        interrupted = True
    built = []
    for k, m in enumerate(curves):
        points = tuple(
            _bench_point(o.measured, ref.floor, steps=s.steps, tolerance=s.tolerance, seconds=min(t),
                         cpu_seconds=min(c), evaluations=o.evaluations, status=o.status)
            for s, t, c, o in zip(settings, times, cpu, outcomes, strict=True) if s.curve == k and t)
        if points or not interrupted:
            built.append(BenchCurve(m.name, m.kind, compile_seconds[k], 1, points))
    return built, interrupted


def _bench_point(measured: float | None, ref_floor: float, **fields) -> BenchPoint:
    error = measured if measured is not None and measured > ref_floor else None
    return BenchPoint(error=error, measured_error=measured, **fields)


def _curve_task(method: Method, system, ref: Reference, steps, tolerances, t_final: float,
                repeats: int) -> BenchCurve:
    """One curve as a task of an executor: its points interleaved over ``repeats`` rounds
    (:func:`_interleaved_curves`); an interrupt raises :class:`Interrupted` carrying the points
    timed before it."""
    curves, interrupted = _interleaved_curves([method], system, ref, steps, tolerances, t_final, repeats)
    if interrupted:
        if curves and curves[0].points:
            raise Interrupted(curves[0])
        raise KeyboardInterrupt
    return curves[0]


def solve_peer(system, solver: str, x0, t_final: float, rtol: float):
    """scipy's solve_ivp(solver) from x0 to t_final at rtol (atol = 1e-3 rtol) on the system's field
    written with plain arithmetic (:func:`rkhp.studies.peers.plain_field`), with its whole history."""
    from scipy.integrate import solve_ivp

    return solve_ivp(plain_field(system), (0.0, t_final), x0, method=solver, rtol=rtol, atol=ATOL_RATIO * rtol)


def cheapest(curves, targets=TARGETS) -> tuple[Cheapest, ...]:
    """For each target error, the cheapest measured point reaching it (over all curves), by
    :attr:`BenchPoint.cost`."""
    out = []
    for target in targets:
        best = None
        for c in curves:
            for p in c.points:
                if p.status == "ok" and p.measured_error is not None and p.measured_error <= target:
                    if best is None or p.cost < best[1].cost:
                        best = (c, p)
        if best is None:
            out.append(Cheapest(target, None, None, None, None))
        else:
            c, p = best
            setting = f"{p.steps} steps" if p.steps is not None else f"rtol {p.tolerance:g}"
            out.append(Cheapest(target, c.method, setting, p.seconds, p.error, p.cpu_seconds))
    return tuple(out)


def ensemble_starts(system, k: int, seed: int = 0) -> np.ndarray:
    """K starts near ``system.x0``: x0 + 5% of |x0| times standard normals (seeded), multiplicative
    (x0 * exp(0.05 z)) where the additive start leaves the domain."""
    if k < 1:
        raise InputError(f"--ensemble must be >= 1, got {k}")
    rng = np.random.default_rng(seed)
    x0 = np.asarray(system.x0, dtype=float)
    scale = ENSEMBLE_SPREAD * max(float(np.max(np.abs(x0))), 1e-300)
    starts = np.empty((k, x0.size))
    for i in range(k):
        z = rng.standard_normal(x0.size)
        x = x0 + scale * z
        if not system.in_domain(x):
            x = x0 * np.exp(ENSEMBLE_SPREAD * z)
        starts[i] = x
    return starts


def _ensemble_errors(ensemble_states, refs) -> float | None:
    errors = [float(np.linalg.norm(ensemble_states[i] - r.state)) for i, r in enumerate(refs)]
    return max(errors) if all(np.isfinite(errors)) else None


def _ensemble_method_curve(method: Method, system, refs, floor, starts, steps, t_final, repeats,
                           executor=None) -> BenchCurve:
    if method.kind in ("rkhp", "composition"):
        def run_all_starts(n):
            return method.integrate_ensemble(system, t_final / n, n, starts, executor=executor)

        run = run_all_starts
        count = len(starts)
    else:
        count = min(len(starts), ENSEMBLE_TIMED)

        def run_each(n):
            return np.array([method.integrate(system, t_final / n, n, x0=x, keep_all=False)
                             .raise_if_failed().final_state for x in starts[:count]])

        run = run_each
    warm_start = time.perf_counter()
    run(steps[0])
    warm = time.perf_counter() - warm_start
    points, fastest_first = [], None
    for n in steps:
        seconds, finals = _least_seconds(lambda n=n: run(n), repeats)
        if n == steps[0]:
            fastest_first = seconds
        measured = _ensemble_errors(finals, refs)
        points.append(_bench_point(measured, floor, steps=n, tolerance=None, seconds=seconds / count,
                             evaluations=None, status="ok" if measured is not None else "non-finite state"))
    compile_seconds = max(0.0, warm - fastest_first) if method.kind in ("rkhp", "composition") else 0.0
    return BenchCurve(method.name, method.kind, compile_seconds, count, tuple(points))


def _ensemble_peer_curve(method, system, refs, floor, starts, tolerances, t_final, repeats) -> BenchCurve:
    """An adaptive peer on the first min(K, ENSEMBLE_TIMED) starts, one after another (prepared and
    warmed up once, :func:`rkhp.studies.peers.prepare`)."""
    count = min(len(starts), ENSEMBLE_TIMED)
    prepared = prepare(peer_of(method), system, t_final, starts[0])
    points = []
    for rtol in tolerances:
        def run_peer(rtol=rtol):
            sols = [prepared.solve(x, rtol) for x in starts[:count]]
            counted = all(s.evaluations is not None for s in sols)
            return (np.array([s.state if s.ok else np.full(len(x), np.nan) for s, x in zip(sols, starts)]),
                    sum(s.evaluations for s in sols) // count if counted else None)

        seconds, (finals, evaluations) = _least_seconds(run_peer, repeats)
        measured = _ensemble_errors(finals, refs)
        points.append(_bench_point(measured, floor, steps=None, tolerance=rtol, seconds=seconds / count,
                             evaluations=evaluations, status="ok" if measured is not None else "failed"))
    return BenchCurve(method.name, method.kind, prepared.compile_seconds, count, tuple(points))


BENCH_DEFAULT_SECONDS = 60.0
"""A method of the default list whose estimated CPU time for the bench exceeds this is left out."""


def bench_steps(steps, repeats: int) -> int:
    """Steps of one method's curve in a bench: a warm-up run of the coarsest, then `repeats`
    runs of each number of steps."""
    return min(steps) + repeats * sum(steps)


def default_methods(system, steps, repeats: int) -> tuple[tuple[Method, ...], tuple[LeftOutMethod, ...]]:
    """The methods of BENCH_METHODS whose estimated cost on `system` (`Method.cost`: the Taylor
    tower's jets) for the bench's steps is at most BENCH_DEFAULT_SECONDS, and those left out with
    their estimated CPU seconds."""
    kept, left_out = [], []
    for method in map(resolve_method, BENCH_METHODS):
        cost = method.cost(system)
        seconds = None if cost is None else cost.seconds(bench_steps(steps, repeats))
        if seconds is not None and seconds > BENCH_DEFAULT_SECONDS:
            left_out.append(LeftOutMethod(method.name, seconds))
        else:
            kept.append(method)
    return tuple(kept), tuple(left_out)


def bench(system, methods, peers=DEFAULT_PEERS, steps=DEFAULT_STEPS, tolerances=DEFAULT_TOLERANCES,
          t_final=None, repeats: int = 3, ensemble: int | None = None, seed: int = 0,
          on_curve=None, executor=None) -> BenchStudy:
    """Work-precision study of ``methods`` and ``peers`` (names of :mod:`rkhp.integrators.methods`, or Methods;
    a method may be ``scipy:NAME`` too; peers: :func:`resolve_peer`) on ``system`` (a name, a spec file
    or a PoissonSystem). A compiled peer whose package is not installed is left out and named, with
    the reason, in ``absent_peers``.

    With an ``executor`` (rkhp.base.executors): one trajectory per point, each curve is one task, timed
    on the worker that runs it; in ensemble mode the curves run here one after another and each
    RKHP point spreads its K trajectories over the workers (the time per trajectory is then the
    workers' throughput). The errors do not depend on the executor; ``on_curve(done, total)``.
    Ctrl-C ends the study early: ``interrupted`` is then True, with the curves (in this process:
    and the points) finished before it.
    """
    system = resolve_system(system)
    t_final = check_t_final(system.t_final if t_final is None else t_final)
    bounds.integer(repeats, "repeats", 1, bounds.MAX_REPEATS)
    steps = tuple(sorted(set(bounds.integer(n, "number of steps", 1, bounds.MAX_STEPS) for n in steps)))
    if not steps:
        raise InputError("no numbers of steps")
    tolerances = tuple(bounds.tolerance(t, "rtol") for t in tolerances)
    bounds.check_trajectory(steps[-1], system.dim, "the finest run")
    if ensemble is not None:
        bounds.integer(ensemble, "--ensemble", 1, bounds.MAX_ENSEMBLE)
        bounds.check_memory(4 * 8.0 * ensemble * system.dim, f"an ensemble of {ensemble} starts")
    bounds.seed(seed)
    chosen, left_out = (tuple(map(resolve_method, methods)), ()) if methods else default_methods(system, steps, repeats)
    curves_of = check_distinct([*chosen, *(resolve_peer(p) for p in peers)])
    missing = {m.name: absent(peer_of(m)) for m in curves_of if m.kind in ADAPTIVE_KINDS}
    absent_peers = tuple((name, reason) for name, reason in missing.items() if reason)
    integrators = [m for m in curves_of if m.kind not in ADAPTIVE_KINDS]
    solvers = [m for m in curves_of if m.kind in ADAPTIVE_KINDS and not missing[m.name]]
    bounds.check_work(repeats * (ensemble or 1) * sum(steps) * len(integrators),
                      f"the bench ({repeats} repeats x {ensemble or 1} starts x {sum(steps)} steps x "
                      f"{len(integrators)} methods)")
    if ensemble is None:
        ref = best_reference(system, t_final)
        if executor is None or executor.kind == "in-process":
            curves, interrupted = _interleaved_curves([*integrators, *solvers], system, ref, steps, tolerances,
                                                      t_final, repeats, on_curve)
        else:
            jobs = [(m, system, ref, steps, tolerances, t_final, repeats) for m in [*integrators, *solvers]]
            found, interrupted = run_until_interrupted(executor, _curve_task, jobs, on_curve)
            curves = [c for c in found if c is not None]
    else:
        starts = ensemble_starts(system, ensemble, seed)
        refs = [dop853_reference(system, t_final, x) for x in starts[:ENSEMBLE_CHECKED]]
        ref = max(refs, key=lambda r: r.error_estimate)
        curves = []
        interrupted = False
        try:
            for m in integrators:
                curves.append(_ensemble_method_curve(m, system, refs, ref.floor, starts, steps, t_final, repeats,
                                                     executor))
                if on_curve:
                    on_curve(len(curves), len(integrators) + len(solvers))
            for p in solvers:
                curves.append(_ensemble_peer_curve(p, system, refs, ref.floor, starts, tolerances, t_final,
                                                    repeats))
                if on_curve:
                    on_curve(len(curves), len(integrators) + len(solvers))
        except BaseException as exc:
            if not is_interrupt(exc):
                raise
            interrupted = True
    return BenchStudy(system.name, system.realisation, t_final, ref, repeats, ensemble, tuple(curves),
                      cheapest(curves), x0=tuple(float(v) for v in system.x0), interrupted=interrupted,
                      absent_peers=absent_peers, left_out=left_out)
