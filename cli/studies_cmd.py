"""`rkhp converge`, `rkhp bench`, `rkhp stress`: convergence, work-precision and stress studies."""

from __future__ import annotations

import click

from rkhp.base import bounds
from rkhp.base.errors import InputError, NumericalFailure
from rkhp.base.tables import booktabs
from rkhp.studies.plots import check_plot_path, data_path
from rkhp.studies.reference import KINDS as REFERENCE_KINDS

from .options import (
    METHOD_HELP,
    POSITIVE,
    SEED,
    STEPS,
    T_FINAL,
    compile_notice,
    console,
    cost_notice,
    emit_json,
    emit_table,
    executor_options,
    force_option,
    format_option,
    integer,
    integers,
    names,
    output_path,
    parse_x0,
    progress,
    real,
    reals,
    run_provenance,
    x0_option,
)
from .render import compact_table
from .terminal import plain, stop_interrupted

#: the steps of one run, listed
STEP_LIST = integers(1, bounds.MAX_STEPS)
#: a plot to write (checked before the study)
PLOT_FILE = output_path(check=check_plot_path)

METHODS_HELP = (METHOD_HELP + " Repeat or separate by commas. Default: euler, paper-two-stage, "
                "paper-three-stage, rk4.")


def _names(values) -> tuple[str, ...]:
    """The names of the --method values; a value that names none (`--method ""`) is refused, not
    read as "the default methods"."""
    for value in values:
        if not value.replace(",", "").strip():
            raise InputError(f"--method {value!r}: no method named")
    return tuple(v.strip() for value in values for v in value.split(",") if v.strip())


def _common(f):
    f = click.option("--realisation", default="symmetric", show_default=True,
                     help="Birealisation: symmetric (degenerate), shifted (general), quartic "
                          "(degenerate, not symmetric) or truncated:K (the spray series to degree "
                          "K in p, K = 1..12; the expected order is bounded accordingly).")(f)
    f = x0_option()(f)
    f = click.option("--method", "methods", multiple=True, metavar="METHOD", help=METHODS_HELP)(f)
    f = click.argument("system")(f)
    return f


def _setup(system_name, realisation, x0, methods, t_final, plot):
    """Validate the cheap inputs first (T; the plot path is checked by its option type), then load the
    system and the methods."""
    from rkhp.integrators.methods import resolve_methods, resolve_system
    from rkhp.studies.converge import check_t_final
    if t_final is not None:
        check_t_final(t_final)
    system = resolve_system(system_name, realisation, parse_x0(x0))
    return system, resolve_methods(_names(methods))


def _kinds(methods) -> tuple[str, ...]:
    """The kinds of compiled kernels a study of `methods` runs (rkhp.integrators.kernels): the
    methods' own, and the loop of H over trajectories."""
    return (*dict.fromkeys(m.kind for m in methods), "invariants")


def _vector(x) -> str:
    return "(" + ", ".join(f"{v:.6g}" for v in x) + ")"


def _e(x) -> str:
    return "—" if x is None else f"{x:.2e}"


def _e1(x) -> str:
    return "—" if x is None else f"{x:.1e}"


def _f(x, digits=2) -> str:
    return "—" if x is None else f"{x:.{digits}f}"


# ----------------------------------------------------------------------------------------------
# converge


@click.command()
@_common
@click.option("--t-final", type=T_FINAL, help="Final time T (default: the system's).")
@click.option("--steps", type=STEP_LIST,
              help="Numbers of steps N1,N2,... (one value: the coarsest, doubled --refinements times). "
                   "Default: chosen for each method by pilot runs (docs/studies.md).")
@click.option("--refinements", type=integer(0, bounds.MAX_REFINEMENTS, "K"),
              help="Halvings of h after the coarsest step (default 6, from N = 20).")
@click.option("--reference", "reference_kind", type=click.Choice(REFERENCE_KINDS), default="auto", show_default=True,
              help="Reference solution: the closed form where there is one, else DOP853 (auto); mpmath: "
                   "a Taylor-series solve at 26 digits of the system's expressions (spec files, built-in "
                   "systems; docs/theory.md §6).")
@click.option("--plot", type=PLOT_FILE, help="Log-log plot of error against h (.png, .svg, .pdf).")
@force_option()
@executor_options("runs")
@format_option("table", "json", "csv", "latex")
def converge(system, methods, x0, realisation, t_final, steps, refinements, reference_kind, plot, force, workers,
             scheduler, fmt):
    """Empirical convergence: global error at T against h, observed and expected orders, verdicts."""
    from rkhp.base.executors import open_executor
    from rkhp.studies.converge import converge as run
    from rkhp.studies.converge import step_counts
    from rkhp.studies.steps import ROWS

    rows = len(step_counts(steps, refinements)) if steps or refinements is not None else ROWS
    sys_, resolved = _setup(system, realisation, x0, methods, t_final, plot)
    compile_notice(_kinds(resolved), fmt != "json", sys_)
    if steps or refinements is not None:  # else pilot runs choose each method's steps
        counts = step_counts(steps, refinements)
        bounds.check_trajectory(max(counts), sys_.dim, "the finest run")
        cost_notice(resolved, sys_, sum(counts))
    with open_executor(workers, scheduler) as executor, progress(fmt != "json") as bar:
        task = bar.add_task("converge", total=len(resolved) * rows)
        study = run(sys_, resolved, steps, t_final, refinements, executor=executor, reference_kind=reference_kind,
                    on_run=lambda done, total: bar.update(task, completed=done, total=total))
    if plot and not study.interrupted:
        from rkhp.studies.plots import plot_convergence

        plot_convergence(study, plot, run_provenance(), force)
    if fmt == "json":
        emit_json(study)
    elif fmt in ("csv", "latex"):
        _emit_converge(study, fmt)
    else:
        _render_converge(study, plot if not study.interrupted else None)
    if study.interrupted:
        stop_interrupted()


SHORT_ROLES = {"pre-asymptotic": "pre", "round-off floor": "floor", "order drift": "drift",
               "no asymptotic range": "no fit", "below reference accuracy": "<ref"}


def _role(method, i) -> str:
    """The row's part in the fit: fit, pre-asymptotic, round-off floor, below reference accuracy..."""
    if i in method.fit.fit_rows:
        return "fit"
    return dict(method.fit.excluded).get(i, "")


CONVERGE_COLUMNS = ("h", "steps", "error", "order", "Casimir", "energy", "Newton", "s", "fit")


def _converge_cells(study, m, i, r) -> list[str]:
    """Row i of method m's table, as the terminal shows it (and --format latex)."""
    error = _e(r.error) if r.status == "ok" and r.error is not None else (
        f"<{study.reference.floor:.0e}" if r.status == "ok" else "failed")
    role = SHORT_ROLES.get(_role(m, i), _role(m, i))
    return [f"{r.h:.3g}", str(r.steps), error, _f(r.local_order), _e1(r.casimir_error), _e1(r.energy_error),
            f"{r.newton_mean:.1f}/{r.newton_max}", f"{r.seconds:.4f}", role if r.status == "ok" else "failed"]


def _verdict_basis(study, m) -> str:
    kind = {"rkhp": study.condition_class, "taylor": "THP", "implicit-midpoint": "midpoint rule",
            "composition": f"composition, {study.condition_class}"}.get(m.kind, "general")
    basis = f"{kind} order"
    if m.realisation_bound is not None:
        basis += f", at most {m.realisation_bound} with {study.realisation}"
    return basis


#: the columns of `converge --format csv` (docs/results.md)
CONVERGE_CSV = ("method", "kind", "h", "steps", "error", "local_order", "casimir_error_max", "energy_error_max",
                "newton_mean", "newton_max", "seconds", "role", "status", "observed_order", "expected_order",
                "verdict", "invariant_error_max")


def _emit_converge(study, fmt) -> None:
    """converge as CSV (one row per run, the method's fit repeated) or LaTeX (the runs, then the
    verdicts)."""
    rows = [(m.method, m.kind, r.h, r.steps, r.error, r.local_order, r.casimir_error, r.energy_error,
             r.newton_mean, r.newton_max, r.seconds, _role(m, i) or None, r.status, m.observed_order,
             m.expected_order, m.verdict, r.invariant_error)
            for m in study.methods for i, r in enumerate(m.rows)]
    cells, groups = [], []
    for m in study.methods:
        groups.append(len(cells))
        cells += [[m.method if i == 0 else "", *_converge_cells(study, m, i, r)] for i, r in enumerate(m.rows)]
    caption = (f"Convergence on {study.system} ({study.realisation} realisation), T = {study.t_final:g}; "
               f"reference: {study.reference.kind}, estimated error {study.reference.error_estimate:.1e}. "
               "Global error at T, local order, max Casimir and energy errors over the run, Newton "
               "iterations mean/max, run seconds, role in the fit.")
    runs = booktabs(("method", *CONVERGE_COLUMNS), cells, caption, "l" + "r" * 8 + "l", groups)
    verdicts = booktabs(("method", "observed order", "fitted rows", "expected order", "verdict"),
                        [(m.method, _f(m.observed_order), ",".join(map(str, m.fit.fit_rows)) or "—",
                          f"{m.expected_order} ({_verdict_basis(study, m)})", m.verdict) for m in study.methods],
                        f"Observed and expected orders on {study.system}.", "lrlll")
    emit_table(fmt, CONVERGE_CSV, rows, [runs, verdicts])


def _render_converge(study, plot) -> None:
    from rkhp.studies.fit import drift

    out = console()
    ref = study.reference
    out.print(f"[bold]{plain(study.system)}[/] ({plain(study.realisation)} realisation, "
              f"{'degenerate' if study.degenerate else 'not degenerate'}), x0 = {_vector(study.x0)}, "
              f"T = {study.t_final:g}")
    out.print(f"reference: {ref.kind}, estimated error {ref.error_estimate:.1e} ({ref.detail}); "
              f"errors <= {ref.floor:.1e} are not reported as measurements")
    if study.reference_choice:
        out.print(f"reference chosen: {plain(study.reference_choice)}")
    for m in study.methods:
        table = compact_table(f"{plain(m.method)} ({m.kind})")
        for col in ("h", "steps", "error", "order", "Casimir", "energy", "Newton", "s", "fit"):
            table.add_column(col, justify="right" if col != "fit" else "left", no_wrap=True)
        for i, r in enumerate(m.rows):
            table.add_row(*map(plain, _converge_cells(study, m, i, r)))
        out.print(table)
        if m.steps_chosen:
            out.print(f"  steps: {plain(m.steps_chosen)}")
        failed = [r.status for r in m.rows if r.status != "ok"]
        if failed:
            out.print(f"  failed runs: {plain('; '.join(failed))}")
        drifts = [r.invariant_error for r in m.rows if r.invariant_error is not None]
        if drifts:
            out.print(f"  declared invariants, largest drift per run: {', '.join(_e1(d) for d in drifts)}")
    out.print("columns: global error at T (2-norm), local order, max Casimir and energy errors over the run, "
              "Newton iterations mean/max, run seconds (compile apart), role in the fit (pre = pre-asymptotic, "
              "floor = round-off floor, drift = order drift, <ref = below the reference's accuracy)")
    out.print("[bold]verdicts[/]")
    for m in study.methods:
        left = ", ".join(f"row {i} {why}" for i, why in m.fit.excluded) or "none"
        basis = _verdict_basis(study, m)
        moving = drift(m.fit) if m.verdict == "inconclusive" and m.observed_order is not None else None
        trend = "" if moving is None else (
            f" (local orders {moving} steadily over the fit: {_f(m.fit.local_orders[m.fit.fit_rows[1]])} to "
            f"{_f(m.fit.local_orders[m.fit.fit_rows[-1]])}, not yet asymptotic)")
        out.print(f"{plain(m.method)}: observed order {_f(m.observed_order)} over rows "
                  f"{','.join(map(str, m.fit.fit_rows)) or '—'} (left out: {left}); expected {m.expected_order} "
                  f"({plain(basis)}): {m.verdict}{trend}")
    if plot:
        out.print(f"plot written to {plain(plot)} (its data: {plain(data_path(plot))})")


# ----------------------------------------------------------------------------------------------
# bench


@click.command()
@_common
@click.option("--peers", type=names(),
              default="numbalsoda:dop853,scipy:dop853,scipy:rk45,classical:rk4,implicit-midpoint", show_default=True,
              help="Peers, run by tolerance: numbalsoda:dop853, diffrax:dopri8, diffrax:tsit5 (compiled; the "
                   "optional extra peers, an absent one is named), scipy:NAME (solve_ivp's dop853, rk45, rk23, "
                   "radau, bdf, lsoda on a plain-arithmetic field); by steps, in the grammar of --method but not "
                   "RKHP tableaux: classical:NAME, implicit-midpoint, thpN; empty for none (docs/studies.md).")
@click.option("--t-final", type=T_FINAL, help="Final time T (default: the system's).")
@click.option("--steps", type=STEP_LIST, help="Numbers of steps of the integrators (default 10,20,...,2560).")
@click.option("--tolerances", type=reals(bounds.tolerance, "RTOL,..."),
              help=f"rtol values of the adaptive peers ({bounds.MIN_TOLERANCE:g} <= rtol < 1; default "
                   "1e-3,...,1e-13; atol = 1e-3 rtol).")
@click.option("--repeats", type=integer(1, bounds.MAX_REPEATS, "N"), default=3, show_default=True,
              help="Timed repeats per point (minimum).")
@click.option("--ensemble", type=integer(1, bounds.MAX_ENSEMBLE, "K"),
              help="Time K initial conditions near x0 at once (per-trajectory times).")
@click.option("--seed", type=SEED, default=0, show_default=True, help="Seed of the ensemble's starts.")
@click.option("--plot", type=PLOT_FILE, help="Log-log plot of time against error (.png, .svg, .pdf).")
@force_option()
@executor_options("curves (with --ensemble: the trajectories)")
@format_option("table", "json", "csv", "latex")
def bench(system, methods, x0, realisation, peers, t_final, steps, tolerances, repeats, ensemble, seed, plot,
          force, workers, scheduler, fmt):
    """Work-precision: CPU and wall time (minimum of repeats) against error, methods and peers."""
    from rkhp.base.executors import open_executor
    from rkhp.studies import bench as B

    step_list = steps or B.DEFAULT_STEPS
    tol_list = tolerances or B.DEFAULT_TOLERANCES
    peer_list = peers or ()
    peer_methods = [B.resolve_peer(p) for p in peer_list]
    sys_, resolved = _setup(system, realisation, x0, methods, t_final, plot)
    if not _names(methods):  # the default list, less the methods too costly on this system
        resolved, _ = B.default_methods(sys_, step_list, repeats)
    compile_notice(_kinds((*resolved, *peer_methods)), fmt != "json", sys_)
    bounds.check_trajectory(max(step_list), sys_.dim, "the finest run")
    cost_notice(resolved, sys_, B.bench_steps(step_list, repeats) * (ensemble or 1) * max(1, len(resolved)))
    with open_executor(workers, scheduler) as executor, progress(fmt != "json") as bar:
        task = bar.add_task("bench", total=len(resolved) + len(peer_list))
        study = B.bench(sys_, resolved if _names(methods) else (), peer_list, step_list, tol_list, t_final,
                        repeats, ensemble, seed, on_curve=lambda done, _: bar.update(task, completed=done),
                        executor=executor)
    if plot and not study.interrupted:
        from rkhp.studies.plots import plot_work_precision

        plot_work_precision(study, plot, run_provenance(), force)
    if fmt == "json":
        emit_json(study)
    elif fmt in ("csv", "latex"):
        _emit_bench(study, fmt)
    else:
        _render_bench(study, plot if not study.interrupted else None)
    if study.interrupted:
        stop_interrupted("the points finished so far are shown")


def _bench_cells(study, p) -> list[str]:
    """A point of a curve as the terminal shows it (and --format latex): setting, error, CPU
    seconds, wall seconds, f evals, status."""
    setting = str(p.steps) if p.steps is not None else f"{p.tolerance:g}"
    error = (_e(p.error) if p.error is not None else
             (f"< {study.reference.floor:.1e}" if p.status == "ok" else "—"))
    cpu = "—" if p.cpu_seconds is None else f"{p.cpu_seconds:.2e}"
    return [setting, error, cpu, f"{p.seconds:.2e}", "—" if p.evaluations is None else str(p.evaluations), p.status]


#: the columns of `bench --format csv` (docs/results.md)
BENCH_CSV = ("method", "kind", "steps", "tolerance", "error", "cpu_seconds", "seconds", "evaluations", "status",
             "compile_seconds", "trajectories")


def _emit_bench(study, fmt) -> None:
    """bench as CSV (one row per point) or LaTeX (the points, then the cheapest per target)."""
    rows = [(c.method, c.kind, p.steps, p.tolerance, p.error, p.cpu_seconds, p.seconds, p.evaluations, p.status,
             c.compile_seconds, c.trajectories) for c in study.curves for p in c.points]
    cells, groups = [], []
    for c in study.curves:
        groups.append(len(cells))
        cells += [[c.method if i == 0 else "", c.kind if i == 0 else "", *_bench_cells(study, p)]
                  for i, p in enumerate(c.points)]
    mode = (f"ensemble of {study.ensemble} starts, seconds per trajectory" if study.ensemble
            else "one trajectory")
    caption = (f"Work-precision on {study.system} ({study.realisation} realisation), T = {study.t_final:g}, "
               f"{mode}, minimum of {study.repeats} repeats (CPU: of the calling thread); reference: "
               f"{study.reference.kind}. Setting: steps, or rtol for the adaptive peers.")
    points = booktabs(("method", "kind", "setting", "error", "CPU s", "wall s", "f evals", "status"), cells,
                      caption, "llrrrrrl", groups)
    cheapest = booktabs(("error at most", "cheapest", "setting", "CPU s", "wall s"),
                        [(f"{c.target:.0e}", c.method or "no method reached it", c.setting or "—",
                          "—" if c.cpu_seconds is None else f"{c.cpu_seconds:.2e}",
                          "—" if c.seconds is None else f"{c.seconds:.2e}") for c in study.cheapest],
                        f"Cheapest method per error target on {study.system}.", "rllrr")
    emit_table(fmt, BENCH_CSV, rows, [points, cheapest])


def _render_bench(study, plot) -> None:
    out = console()
    ref = study.reference
    mode = (f"ensemble of {study.ensemble} starts, seconds per trajectory" if study.ensemble
            else "one trajectory")
    out.print(f"[bold]{plain(study.system)}[/] ({plain(study.realisation)} realisation), x0 = {_vector(study.x0)}, "
              f"T = {study.t_final:g}, {mode}; "
              f"minimum of {study.repeats} repeats, warm (compile apart); CPU: of the calling thread")
    out.print(f"reference: {ref.kind}, estimated error {ref.error_estimate:.1e}")
    for _, reason in study.absent_peers:
        out.print(plain(reason))
    for name, seconds in study.left_out:
        out.print(f"{plain(name)} left out of the default methods: about {seconds:.2g} s of CPU on this "
                  "system (name it with --method to run it)")
    for c in study.curves:
        extra = f", compile {c.compile_seconds:.2f} s apart" if c.compile_seconds else ""
        timed = f", {c.trajectories} trajectories timed" if study.ensemble else ""
        out.print(f"[bold]{plain(c.method)}[/] ({c.kind}{extra}{timed})")
        table = compact_table(None)
        by_steps = c.points and c.points[0].steps is not None
        for col in ("steps" if by_steps else "rtol", "error", "CPU s", "wall s", "f evals", "status"):
            table.add_column(col, justify="right")
        for p in c.points:
            table.add_row(*map(plain, _bench_cells(study, p)))
        out.print(table)
    out.print("[bold]cheapest[/]")
    for c in study.cheapest:
        if c.method is None:
            out.print(f"error <= {c.target:.0e}: no method reached it")
        else:
            cpu = "" if c.cpu_seconds is None else f"{c.cpu_seconds:.2e} s CPU, "
            out.print(f"error <= {c.target:.0e}: {plain(c.method)} ({plain(c.setting)}), {cpu}{c.seconds:.2e} s wall")
    if plot:
        out.print(f"plot written to {plain(plot)} (its data: {plain(data_path(plot))})")


# ----------------------------------------------------------------------------------------------
# stress


@click.command()
@_common
@click.option("--t-final", type=T_FINAL, help="Horizon T of parts (a) and (c) (default: the system's).")
@click.option("--long-steps", type=STEPS, default=100_000, show_default=True, help="Steps of the long run (b).")
@click.option("--long-h", type=POSITIVE, help="Step size of the long run (default T/100).")
@click.option("--sweep-coarsest", type=STEPS, default=200, show_default=True,
              help="Part (a) sweeps h = T/N upward from N = this down to 1.")
@click.option("--round-off-steps", type=STEP_LIST, help="Numbers of steps of part (d) over T (default 32 to 10^5).")
@click.option("--plot", type=PLOT_FILE, help="Plot of the long run's drift (.png, .svg, .pdf).")
@force_option()
@executor_options("runs of each part")
@format_option("table", "json", "csv", "latex")
def stress(system, methods, x0, realisation, t_final, long_steps, long_h, sweep_coarsest, round_off_steps, plot,
           force, workers, scheduler, fmt):
    """Stress tests: (a) step sweep to Newton failure, (b) long-run drift, (c) near-singular starts,
    (d) round-off floor; each part ends with a verdict."""
    from rkhp.base.executors import open_executor
    from rkhp.studies import stress as S

    ro = round_off_steps or S.ROUND_OFF_STEPS
    if len(ro) < 3:
        raise click.BadParameter("a fit needs at least 3 step sizes", param_hint="--round-off-steps")
    sys_, resolved = _setup(system, realisation, x0, methods, t_final, plot)
    # part (b)'s peer: classical RK4; its modified Hamiltonians
    compile_notice((*_kinds(resolved), "classical", "modified"), fmt != "json", sys_)
    with open_executor(workers, scheduler) as executor, progress(fmt != "json") as bar:
        task = bar.add_task("stress", total=4)
        study = S.stress(sys_, resolved, t_final, long_steps, long_h, sweep_coarsest, ro,
                         on_part=lambda *_: bar.advance(task), executor=executor)
    if plot and not study.interrupted:
        from rkhp.studies.plots import plot_stress

        plot_stress(study, plot, run_provenance(), force)
    if fmt == "json":
        emit_json(study)
    elif fmt in ("csv", "latex"):
        _emit_stress(study, fmt)
    else:
        _render_stress(study, plot if not study.interrupted else None)
    if study.interrupted:
        stop_interrupted("the parts finished so far are shown")


SWEEP_COLUMNS = ("h", "steps", "ok", "Newton max", "rel. error", "rel. energy err")
LONG_RUN_COLUMNS = ("method", "Casimir max", "energy, 1st window", "last window", "growth", "modified energy max",
                    "seconds")
SINGULAR_COLUMNS = ("method", "x1(0)", "status", "min component", "Casimir err", "kept")


def _sweep_cells(r) -> list[str]:
    return [f"{r.h:.3g}", str(r.steps), "yes" if r.ok else "no", str(r.newton_max), _e(r.relative_error),
            _e(r.relative_energy_error)]


def _long_run_cells(r) -> list[str]:
    modified = "—" if r.modified is None else f"{_e(r.modified.max)} (H~_{r.modified.order})"
    return [r.method, _e(r.casimir_max), _e(r.energy_windows[0]), _e(r.energy_windows[-1]),
            "—" if r.energy_growth is None else f"x{r.energy_growth:.2g}", modified, f"{r.seconds:.2f}"]


def _singular_cells(r) -> list[str]:
    return [r.method, f"{r.first_species:g}", r.status, _e(r.min_component), _e(r.casimir_error),
            "yes" if r.kept else "no"]


def _round_off_cells(ro, i, r) -> list[str]:
    """Row i of part (d): steps, then per method "error [mark] | energy error [mark]"."""
    cells = []
    for m, energy in zip(ro.studies, ro.energy_fits, strict=True):
        row = m.rows[i]
        if row.status != "ok":
            cells.append("failed")
            continue
        role = SHORT_ROLES.get(_role(m, i), _role(m, i))
        error = f"<{ro.reference_floor:.0e}" if row.error is None else _e1(row.error)
        e_role = "" if i in energy.fit_rows else SHORT_ROLES.get(dict(energy.excluded).get(i, ""), "")
        cells.append(f"{error}{'' if role == 'fit' else ' ' + role} | {_e1(row.energy_error)}"
                     f"{'' if not e_role else ' ' + e_role}")
    return [str(r.steps), *cells]


#: the columns of `stress --format csv`, one measured quantity per row (docs/results.md)
STRESS_CSV = ("part", "method", "h", "steps", "start", "quantity", "value")


def _stress_rows(study, verdicts):
    """The long-form rows of `stress --format csv` (a part an interrupt left out: its verdict only)."""
    for s in study.sweep:
        for r in s.rows:
            for key, attr in (("ok", "ok"), ("newton_max", "newton_max"), ("relative_error", "relative_error"),
                              ("relative_energy_error_max", "relative_energy_error"), ("status", "status")):
                yield ("a", s.method, r.h, r.steps, None, key, getattr(r, attr))
    lr = study.long_run
    for r in () if lr is None else (*lr.runs, lr.peer):
        values = {"casimir_max": r.casimir_max, "invariant_max": r.invariant_max,
                  "energy_first_window": r.energy_windows[0],
                  "energy_last_window": r.energy_windows[-1], "energy_growth": r.energy_growth,
                  "modified_energy_max": None if r.modified is None else r.modified.max,
                  "seconds": r.seconds, "status": r.status}
        for key, value in values.items():
            yield ("b", r.method, lr.h, lr.steps, None, key, value)
    for r in () if study.near_singular is None else study.near_singular.runs:
        for key, attr in (("status", "status"), ("min_component", "min_component"),
                          ("casimir_error_max", "casimir_error"), ("kept", "kept")):
            yield ("c", r.method, None, None, r.first_species, key, getattr(r, attr))
    for m in () if study.round_off is None else study.round_off.studies:
        for r in m.rows:
            for key, attr in (("error", "error"), ("energy_error_max", "energy_error"), ("status", "status")):
                yield ("d", m.method, r.h, r.steps, None, key, getattr(r, attr))
    for part, text in verdicts.items():
        yield (part, None, None, None, None, "verdict", text)


def _emit_stress(study, fmt) -> None:
    """stress as CSV (long form: one measured quantity per row) or LaTeX (one table per part)."""
    verdicts = study.verdicts()
    where = f"{study.system} ({study.realisation} realisation)"
    cells, groups = [], []
    for s in study.sweep:
        groups.append(len(cells))
        cells += [[s.method if i == 0 else "", *_sweep_cells(r)] for i, r in enumerate(s.rows)]
    tables = [booktabs(("method", *SWEEP_COLUMNS), cells,
                       f"(a) Step-size sweep on {where}, T = {study.t_final:g}: {verdicts['a']}", "lrrlrrr", groups)]
    lr = study.long_run
    if lr is not None:
        tables.append(booktabs(LONG_RUN_COLUMNS, [_long_run_cells(r) for r in (*lr.runs, lr.peer)],
                               f"(b) Long run on {where}, {lr.steps} steps of h = {lr.h:g}, max error per window "
                               f"({lr.windows} windows): {verdicts['b']}", "lrrrrrr"))
    if study.near_singular is not None and study.near_singular.applicable:
        tables.append(booktabs(SINGULAR_COLUMNS, [_singular_cells(r) for r in study.near_singular.runs],
                               f"(c) Near-singular starts on {where}: {verdicts['c']}", "lrlrrl"))
    ro = study.round_off
    if ro is not None:
        tables.append(booktabs(("steps", *(m.method for m in ro.studies)),
                               [_round_off_cells(ro, i, r) for i, r in enumerate(ro.studies[0].rows)],
                               f"(d) Tiny steps on {where}, T = {ro.t_final:g}: error at T | max energy error "
                               f"(pre = pre-asymptotic, floor = round-off floor, drift = order drift): {verdicts['d']}",
                               "r" * (1 + len(ro.studies))))
    emit_table(fmt, STRESS_CSV, _stress_rows(study, verdicts), tables)


def _render_stress(study, plot) -> None:
    out = console()
    verdicts = study.verdicts()
    out.print(f"[bold]{plain(study.system)}[/] ({plain(study.realisation)} realisation), x0 = {_vector(study.x0)}, "
              f"T = {study.t_final:g}")
    out.print("[bold](a) step-size sweep[/]")
    for s in study.sweep:
        table = compact_table(plain(s.method))
        for col in ("h", "steps", "ok", "Newton max", "rel. error", "rel. energy err"):
            table.add_column(col, justify="right")
        for r in s.rows:
            table.add_row(*map(plain, _sweep_cells(r)))
        out.print(table)
    for s in study.sweep:
        out.print(f"verdict (a): {plain(s.verdict())}")
    for part, name, render in ((study.long_run, "(b) long run", _render_long_run),
                               (study.near_singular, "(c) near-singular starts", _render_near_singular),
                               (study.round_off, "(d) tiny steps", _render_round_off)):
        if part is None:
            out.print(f"[bold]{name}[/]: not run (interrupted)")
        else:
            render(out, part, verdicts)
    if plot:
        out.print(f"plot written to {plain(plot)} (its data: {plain(data_path(plot))})")


def _render_long_run(out, lr, verdicts) -> None:
    out.print(f"[bold](b) long run[/]: {lr.steps} steps of h = {lr.h:g}, max error per window ({lr.windows} windows)")
    table = compact_table(None)
    table.add_column("method", no_wrap=True)
    for col in ("Casimir max", "energy, 1st window", "last window", "growth", "modified energy max", "seconds"):
        table.add_column(col, justify="right")
    for r in (*lr.runs, lr.peer):
        table.add_row(*map(plain, _long_run_cells(r)))
    out.print(table)
    for r in (*lr.runs, lr.peer):
        if r.status != "ok":
            out.print(f"  {plain(r.method)}: {plain(r.status)}")
        if r.invariant_max is not None:
            out.print(f"  {plain(r.method)}: declared invariants' largest drift {_e(r.invariant_max)}")
    out.print(f"verdict (b): {plain(verdicts['b'])}")


def _render_near_singular(out, near_singular, verdicts) -> None:
    out.print("[bold](c) near-singular starts[/]")
    if near_singular.applicable:
        table = compact_table(None)
        for col in ("method", "x1(0)", "status", "min component", "Casimir err", "kept"):
            table.add_column(col)
        for r in near_singular.runs:
            table.add_row(*map(plain, _singular_cells(r)))
        out.print(table)
    out.print(f"verdict (c): {plain(verdicts['c'])}")


def _render_round_off(out, ro, verdicts) -> None:
    out.print(f"[bold](d) tiny steps[/]: T = {ro.t_final:g}, reference {ro.reference_kind} "
              f"(errors <= {ro.reference_floor:.1e} not measured); error at T and max energy error")
    table = compact_table(None)
    table.add_column("steps", justify="right")
    for m in ro.studies:
        table.add_column(plain(m.method), justify="right")
    for i, r in enumerate(ro.studies[0].rows):
        table.add_row(*map(plain, _round_off_cells(ro, i, r)))
    out.print(table)
    out.print("marks: pre = pre-asymptotic, floor = round-off floor, drift = order drift (left out of the fit)")
    out.print(f"verdict (d): {plain(verdicts['d'])}")


# ----------------------------------------------------------------------------------------------
# long-time


@click.command("long-time")
@_common
@click.option("--h", "h", type=POSITIVE, default=0.1, show_default=True, help="Step size h.")
@click.option("--steps", type=integer(100, 10**8, "steps"), default=10**6, show_default=True,
              help="Number of steps (the run goes to t = h * steps).")
@click.option("--tolerance", type=real(1e-14, 1e-2, name="RTOL"), default=1e-8, show_default=True,
              help="Relative tolerance of scipy methods (scipy:dop853) over the same time.")
@click.option("--plot", type=PLOT_FILE, help="Log-log plot of the energy error against t (.png, .svg, .pdf).")
@force_option()
@format_option("table", "json")
def long_time(system, methods, x0, realisation, h, steps, tolerance, plot, force, fmt):
    """Long-time energy behaviour: the running maximum of |H(y_n) - H(y_0)| over `--steps` steps,
    fitted as C t^k over the last three decades (k about 0: bounded; 1: a drift). Methods: RKHP
    tableaux, compositions (tj4, kahan-li6, ...), any fixed-step method and scipy's adaptive ones;
    default paper-three-stage, euler and scipy:dop853 (docs/stability.md)."""
    from rkhp.integrators.methods import resolve_methods, resolve_system
    from rkhp.studies.longtime import check_long_time, energy_growth

    check_long_time(h, steps)
    sys_ = resolve_system(system, realisation, parse_x0(x0))
    resolved = resolve_methods(_names(methods) or ("paper-three-stage", "euler", "scipy:dop853"))
    compile_notice(_kinds(resolved), fmt != "json", sys_)
    runs = []
    with progress(fmt != "json") as bar:
        task = bar.add_task("long runs", total=len(resolved))
        for method in resolved:
            runs.append(energy_growth(sys_, method, h, steps, tolerance))
            bar.advance(task)
    if plot:
        from rkhp.studies.plots import plot_long_time

        plot_long_time(sys_.name, runs, plot, run_provenance(), force)
    doc = {"system": sys_.name, "realisation": sys_.realisation, "h": h, "steps": steps,
           "t_final": h * steps, "runs": runs}
    if fmt == "json":
        emit_json(doc)
    else:
        _render_long_time(sys_.name, h, steps, runs, plot)
    failed = [r for r in runs if r.status != "ok"]
    if failed:
        raise NumericalFailure(f"{sys_.name}: " + "; ".join(f"{r.method} ({_long_setting(r)}): {r.status}"
                                                             for r in failed))


def _long_setting(r) -> str:
    """A long run's setting: its step, or the rtol of a scipy method."""
    return f"rtol {r.tolerance:g}" if r.tolerance is not None else f"h = {r.h:g}"


def _render_long_time(system: str, h: float, steps: int, runs, plot) -> None:
    out = console()
    out.print(f"{system}: |H(y_n) - H(y_0)| up to t = {h * steps:g} (h = {h:g}, {steps} steps)", markup=False)
    for r in runs:
        if r.status != "ok":
            out.print(f"  {r.method} ({_long_setting(r)}): {r.status}", markup=False)
            continue
        k = "—" if r.exponent is None else f"{r.exponent:.2f}"
        drift = "".join(f", invariant {i + 1} drift {e:.2e}" for i, e in enumerate(r.invariant_errors))
        out.print(f"  {r.method} ({_long_setting(r)}): final error {r.errors[-1]:.2e}, growth exponent {k}{drift}",
                  markup=False)
    if plot:
        out.print(f"plot written to {plot}", markup=False)
