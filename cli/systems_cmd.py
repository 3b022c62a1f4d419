"""`rkhp systems`, `rkhp check`, `rkhp integrate`: Poisson systems and the RKHP integrators."""

from __future__ import annotations

import sys

import click

from rkhp.base import bounds
from rkhp.integrators.methods import DEFAULT_METHOD
from rkhp.ivp.tolerance import MIN_TOLERANCE

from .options import (
    METHOD_HELP,
    SEED,
    SIGNED,
    STEPS,
    compile_notice,
    console,
    cost_notice,
    emit_json,
    force_option,
    format_option,
    integer,
    output_path,
    parse_x0,
    progress,
    real,
    realisation_option,
    reals,
    run_provenance,
    x0_option,
)
from .render import compact_table, plan_line, print_table
from .terminal import plain


def _fmt(v, digits=6) -> str:
    if v is None:
        return "-"
    if isinstance(v, float):
        return f"{v:.{digits}g}"
    return str(v)


@click.command("systems")
@format_option("table", "json")
def systems(fmt):
    """List the built-in Poisson systems (docs/theory.md §6)."""
    from rkhp.systems import builtin_systems, get_system

    rows = []
    for name in builtin_systems():
        s = get_system(name)
        rows.append({"name": name, "family": s.family, "dim": s.dim, "domain": s.domain,
                     "x0": [float(v) for v in s.x0], "t_final": s.t_final,
                     "casimirs": list(s.casimir_names), "exact_solution": s.exact_solution
                     is not None, "description": s.description})
    if fmt == "json":
        emit_json({"systems": rows})
        return
    table = compact_table("Built-in Poisson systems (realisations: symmetric, shifted, quartic, "
                          "truncated:K)")
    for col in ("name", "family", "n", "domain", "x0", "t_final", "Casimirs", "exact"):
        table.add_column(col, no_wrap=col in ("name", "family"))
    for r in rows:
        table.add_row(plain(r["name"]), r["family"], str(r["dim"]), r["domain"],
                      ", ".join(f"{v:.4g}" for v in r["x0"]), _fmt(r["t_final"]),
                      plain("; ".join(r["casimirs"])) or "-", "yes" if r["exact_solution"] else "no")
    print_table(console(), table)


@click.command("check")
@click.argument("system")
@realisation_option()
@click.option("--samples", type=integer(1, bounds.MAX_SAMPLES, "N"), default=100, show_default=True,
              help="Random points (x, p) at which the axioms are checked.")
@click.option("--seed", type=SEED, default=0, show_default=True, help="Random seed.")
@format_option("table", "json")
def check(system, realisation, samples, seed, fmt):
    """Check the birealisation axioms of SYSTEM (built-in name or spec file) by automatic
    differentiation at random points; exit status 1 if a deviation exceeds 1e-12 of the size of
    what it is computed from (a bracket's: 2n max|dF| max|dG|)."""
    from rkhp.systems import get_system
    from rkhp.systems.check import check_birealisation

    poisson = get_system(system, realisation)
    compile_notice((), fmt != "json", poisson)
    result = check_birealisation(poisson, samples=samples, seed=seed)
    if fmt == "json":
        emit_json(result)
    else:
        from rich.table import Table

        table = Table(title=f"{plain(result.system)} ({plain(result.realisation)}): {samples} samples, "
                            f"seed {seed}")
        table.add_column("axiom")
        table.add_column("max deviation", justify="right")
        labels = {"identity": "alpha(x,0) = beta(x,0) = x",
                  "poisson": "{alpha_i, alpha_j} = pi_ij(alpha)",
                  "anti_poisson": "{beta_i, beta_j} = -pi_ij(beta)",
                  "commute": "{alpha_i, beta_j} = 0"}
        for key, value in result.deviations.items():
            table.add_row(labels[key], f"{value:.2e}")
        table.add_row("d_p alpha(x,0) antisymmetric", f"{result.degeneracy:.2e}")
        table.add_row("beta(x,p) = alpha(x,-p)", f"{result.symmetry:.2e}")
        out = console()
        print_table(out, table)
        out.print(f"degenerate: {'yes' if result.degenerate else 'no'}    "
                  f"symmetric: {'yes' if result.symmetric else 'no'}    "
                  f"axioms: {'ok' if result.ok else 'FAILED'} ({_tolerance_words(result)})")
    if not result.ok:
        from rkhp.base.errors import CheckFailed

        bad = ", ".join(f"{k} {v:.2e}" for k, v in result.deviations.items() if v > result.tolerance)
        raise CheckFailed(f"{result.system} ({result.realisation}): birealisation axioms violated "
                          f"({bad} > {_tolerance_words(result)})")


def _tolerance_words(result) -> str:
    """The tolerance of a check as used: relative, and the largest size it was applied to."""
    return f"tolerance {result.tolerance:g} relative to the brackets' size, at most {result.scale:.3g}"


def failure_status(system, trajectory, h: float) -> str:
    """A run's status; a failed one with where the exact flow stops, when it stops within the
    failed step (`rkhp.systems.singular.flow_stop`: pi or grad H blowing up, the domain left)."""
    from rkhp.systems.singular import flow_stop

    if trajectory.ok:
        return trajectory.status
    stop = flow_stop(system, trajectory.final_state, h)
    return trajectory.status if stop is None else f"{trajectory.status}; {stop}"


def integration_report(system, trajectory, method: str, h: float, steps: int) -> dict:
    """The JSON document of `rkhp integrate` (docs/json.md): the Casimir and energy errors at the
    last state (``casimir_error``, ``energy_error``) and the largest over the run (``..._max``)."""
    import numpy as np

    from rkhp.studies.invariants import declared_errors, max_deviations

    x0, xf = trajectory.states[0], trajectory.final_state
    casimir = (float(np.abs(system.casimir_values(xf) - system.casimir_values(x0)).max())
               if system.casimirs else None)
    casimir_max, energy_max = max_deviations(system, trajectory.states)
    iters = trajectory.newton_iterations
    invariants = declared_errors(system, trajectory.states)
    exact = None
    if system.exact_solution is not None and trajectory.ok:
        exact = float(np.abs(system.exact_solution(trajectory.times[-1]) - xf).max())
    return {
        "system": system.name, "method": method, "h": h, "steps": steps,
        "t_final": float(trajectory.times[-1]), "x_final": [float(v) for v in xf],
        "casimir_error": casimir,
        "energy_error": abs(system.hamiltonian(xf) - system.hamiltonian(x0)),
        "newton_mean": float(iters.mean()) if iters.size else 0.0,
        "newton_max": int(iters.max()) if iters.size else 0,
        "status": failure_status(system, trajectory, h), "compile_seconds": trajectory.compile_seconds,
        "run_seconds": trajectory.run_seconds, "realisation": system.realisation,
        "exact_error": exact, "casimir_error_max": casimir_max, "energy_error_max": energy_max,
        "invariant_errors_max": invariants, "invariant_error_max": max(invariants) if invariants else None,
    }


@click.command("integrate")
@click.argument("system")
@click.option("--method", "method", default=DEFAULT_METHOD, show_default=True, metavar="METHOD",
              help=METHOD_HELP + " With --tol also auto: the cheapest of the candidates of docs/solve.md.")
@click.option("--steps", type=STEPS, default=None, help="Number of steps over [0, T].")
@click.option("--tol", "tol", type=real(MIN_TOLERANCE, 1.0, high_open=True, name="TOL"), default=None,
              help="Choose the steps for this error at T (2-norm, relative to max(1, |x(T)|)) from a pilot "
                   "error estimate (docs/solve.md); instead of --steps and --h.")
@click.option("--h", "h", type=SIGNED, default=None,
              help="Step size; it must divide T (steps = T / h; docs/input.md); negative runs backwards.")
@click.option("--t-final", type=SIGNED, default=None,
              help="Final time T (default: the system's, negated for a negative --h); negative runs backwards.")
@x0_option()
@click.option("--modified", "modified_order", type=integer(1, name="N"), default=None, metavar="N",
              help="Also report max over the run of |H~_N(y_n) - H~_N(y_0)|, H~_N the method's modified "
                   "Hamiltonian to order N (docs/modified.md).")
@realisation_option()
@click.option("--output", type=output_path(".csv", ".npz"), default=None,
              help="Write the trajectory to FILE, CSV or NPZ by its suffix: t, x1..xn, energy, casimir1.., "
                   "newton_iterations, stage_sweeps per state, with the run's provenance (docs/results.md).")
@click.option("--every", type=integer(1, bounds.MAX_STEPS, "K"), default=None,
              help="With --output: keep every K-th state (and the last).")
@click.option("--t-eval", "t_eval", type=reals(lambda x, label: x, "T1,T2,..."), default=None,
              help="States at these times between 0 and T, each one step of the method of size t - t_n from the "
                   "last grid point t_n (a Poisson map: on the leaf, of the method's order); with "
                   "--output, the file holds these states.")
@click.option("--t-eval-count", type=integer(2, bounds.MAX_OUTPUT_TIMES, "N"), default=None,
              help="As --t-eval, at N equally spaced times from 0 to T (numpy's linspace).")
@click.option("--explain", is_flag=True,
              help="Say which substep provider would run METHOD's steps on SYSTEM, and why (docs/engine.md), "
                   "without running them.")
@force_option()
@format_option("table", "json")
def integrate(system, method, steps, tol, h, t_final, x0, modified_order, realisation, output, every, t_eval,
              t_eval_count, explain, force, fmt):
    """Integrate SYSTEM (built-in or spec file) with METHOD (docs/methods.md), by --steps, --h or a
    tolerance --tol (docs/solve.md)."""
    from rkhp.base.errors import InputError, NumericalFailure
    from rkhp.integrators.methods import resolve_method, resolve_system
    from rkhp.ivp.solve import is_auto

    if explain:
        return _explain(resolve_system(system, realisation, parse_x0(x0)), resolve_method(method), fmt)

    if t_eval is not None and t_eval_count is not None:
        raise InputError("give at most one of --t-eval and --t-eval-count")
    chosen_times = t_eval is not None or t_eval_count is not None
    if every is not None and (output is None or chosen_times):
        raise InputError("--every thins the states written by --output (not those of --t-eval)")
    if tol is not None and (steps is not None or h is not None):
        raise InputError("give one of --tol, --steps and --h")
    if is_auto(method) and tol is None:
        raise InputError("--method auto chooses by a tolerance: give --tol")
    poisson = resolve_system(system, realisation, parse_x0(x0))
    end = poisson.t_final if t_final is None and tol is not None else t_final
    if end is None:
        end = -poisson.t_final if h is not None and h < 0 else poisson.t_final
    if tol is None:
        n, step = bounds.step_plan(end, steps, h)
        bounds.check_trajectory(n, poisson.dim)
    times = _output_times(t_eval, t_eval_count, end)
    chosen = None if is_auto(method) else resolve_method(method)
    if chosen is not None:
        _warn_c(chosen)
        _implicit_notice(chosen, fmt != "json")
    series = None
    if modified_order is not None and chosen is not None:
        from .modified_views import modified_series

        series = modified_series(poisson, chosen, modified_order, fmt != "json")
    kinds = (chosen.kind,) if chosen is not None else ("rkhp", "composition")
    compile_notice((*kinds, "modified") if series is not None else kinds, fmt != "json", poisson)
    if tol is None:
        cost_notice((chosen,), poisson, n)
        trajectory = _run(poisson, chosen, end, n, fmt)
        report = integration_report(poisson, trajectory, chosen.name, step, n)
    else:
        chosen, trajectory, report = _run_to_tolerance(poisson, method, end, tol, fmt)
        step, n = report["h"], report["steps"]
        if modified_order is not None and series is None:
            from .modified_views import modified_series

            series = modified_series(poisson, chosen, modified_order, fmt != "json")
    if series is not None and trajectory.ok:
        from .modified_views import modified_energy_report

        report.update(modified_energy_report(poisson, series, step, trajectory.states, fmt != "json"))
    timed = None
    if times is not None:
        timed = _states_at(trajectory, chosen, times)
        report["t_eval"] = timed_report(poisson, timed)
    if output is not None and times is None:
        from rkhp.integrators.trajectory import kept_rows

        written = _write(poisson, output, trajectory.columns(every or 1), force)
        report["output"] = {"file": str(written), "rows": len(kept_rows(len(trajectory.states), every or 1))}
    elif output is not None and timed is not None:  # a failed run may reach none of the chosen times
        report["output"] = {"file": str(_write(poisson, output, timed.columns(), force)), "rows": len(timed.times)}
    if fmt == "json":
        emit_json(report)
    else:
        _print_integration(report)
    if not trajectory.ok:
        raise NumericalFailure(f"{poisson.name}, {chosen.name}, h = {step:g}: {report['status']}")
    if tol is not None and not report["tolerance"]["met"]:
        raise NumericalFailure(f"{poisson.name}, {chosen.name}: the estimated error "
                               f"{report['tolerance']['estimated_error']:.3g} misses --tol {tol:g}")


def _explain(poisson, chosen, fmt: str) -> None:
    """`rkhp integrate --explain`: the substep provider of the method on the system."""
    from rkhp.integrators.substeps import explain

    e = explain(poisson, chosen)
    doc = {"system": e.system, "method": e.method, "realisation": poisson.realisation,
           "family": poisson.family, "base_kind": None if e.key is None else e.key[1],
           "providers": list(e.row), "refused": list(e.refused), "substep": e.provider}
    if fmt == "json":
        emit_json(doc)
        return
    out = console()
    if e.provider is None:
        out.print(f"{plain(e.method)} is a {chosen.kind} method: its own loop runs it, not the driver's "
                  "substeps", markup=False)
        return
    if e.key is None:
        out.print(f"{plain(e.system)} ({poisson.family} family, {poisson.realisation} realisation), "
                  f"{plain(e.method)}: steps by {e.provider} (not a tableau: no row of the table)", markup=False)
        return
    out.print(f"{plain(e.system)} ({poisson.family} family, {poisson.realisation} realisation), "
              f"{plain(e.method)} (base method: {e.key[1]}): substeps by {e.provider}", markup=False)
    out.print(f"row of the table: {', '.join(e.row)}"
              + (f"; refused: {', '.join(e.refused)}" if e.refused else ""), markup=False)


def _write(system, path, columns, force):
    """A trajectory file of the columns, with the declared invariants' columns (docs/results.md)."""
    from rkhp.integrators.trajectory import write_columns
    from rkhp.studies.invariants import declared_columns

    return write_columns(path, declared_columns(system, columns), run_provenance(), force)


def _run(system, method, end: float, steps: int, fmt):
    """The run of `steps` steps to `end`, in chunks with a progress bar on a terminal (rkhp.ivp.run)."""
    from rkhp.ivp.run import Span, trajectory

    with progress(fmt != "json") as bar:
        task = bar.add_task("integrate", total=steps)
        return trajectory(system, method, Span(0.0, end), steps,
                          on_progress=lambda done, _: bar.update(task, completed=done))


def _run_to_tolerance(system, method, end: float, tol: float, fmt):
    """The method (chosen, with --method auto), the run and the report of --tol: the pilot's plan,
    told before the run, the run, and its error estimate (rkhp.ivp.tolerance)."""
    from rkhp.ivp import tolerance
    from rkhp.ivp.solve import plan

    with progress(fmt != "json") as bar:
        task = bar.add_task("pilot runs", total=None)
        chosen, planned = plan(system, (0.0, end), method, tol,
                               on_candidate=lambda done, total: bar.update(task, completed=done, total=total))
    if fmt != "json":
        console().print(plan_line(planned), markup=False)
        sys.stdout.flush()
    span = planned.span
    choice, trajectory, estimate = tolerance.run_to_tolerance(
        planned.choice, span, system,
        lambda c: _ran(_run(system, chosen, end, c.steps, fmt)))
    report = integration_report(system, trajectory, chosen.name, choice.h, choice.steps)
    report["tolerance"] = tolerance_report(planned, choice, estimate)
    return chosen, trajectory, report


def _ran(trajectory):
    return trajectory, trajectory.final_state if trajectory.ok else None


def tolerance_report(planned, choice, estimate) -> dict:
    """The `tolerance` object of `rkhp integrate --tol` (docs/json.md)."""
    from rkhp.base.json_form import json_form

    return {"tol": choice.tolerance, "order": choice.order, "pilot": json_form(choice.pilot),
            "planned_steps": planned.steps, "steps": choice.steps, "h": choice.h,
            "predicted_error": choice.predicted_error, "estimated_error": estimate,
            "met": estimate is not None and estimate <= choice.tolerance,
            "candidates": json_form(planned.candidates)}


def _output_times(t_eval, count, end: float):
    """The times of --t-eval (checked against [0, T]) or the N of --t-eval-count, or None."""
    import numpy as np

    from rkhp.integrators.output_times import check_output_times

    if count is not None:
        return np.linspace(0.0, end, count)
    if t_eval is None:
        return None
    return check_output_times(t_eval, 0.0, end, "--t-eval")


def _states_at(trajectory, method, times):
    """The states at the chosen times reached by the run (all of them when it succeeded)."""
    from rkhp.integrators.output_times import states_at

    if trajectory.ok:
        reached = times
    else:  # in either direction of the run
        start, last = trajectory.times[0], trajectory.times[-1]
        reached = times[abs(times - start) <= abs(last - start)]
    if not reached.size:
        return None
    return states_at(trajectory, method, reached)


def timed_report(system, timed) -> dict | None:
    """The `t_eval` object of `rkhp integrate`'s JSON (docs/json.md)."""
    import numpy as np

    if timed is None:
        return None
    casimir = None
    if system.casimirs:
        start = system.casimir_values(system.x0)
        casimir = float(max(np.abs(system.casimir_values(x) - start).max() for x in timed.states))
    exact = None
    if system.exact_solution is not None:
        exact = float(max(np.abs(system.exact_solution(t) - x).max() for t, x in zip(timed.times, timed.states,
                                                                                     strict=True)))
    return {"times": timed.times.tolist(), "states": timed.states.tolist(), "substeps": timed.substeps.tolist(),
            "casimir_error": casimir, "exact_error": exact}


def _implicit_notice(method, enabled: bool) -> None:
    """One line on stderr, on a terminal and not in JSON mode, before a run of an implicit tableau:
    its stage functions are Taylor polynomials of one degree D, so the step it computes is the
    method's Poisson map up to O(h^(D+1)) only (docs/implicit.md "Truncated stages and the Poisson
    map")."""
    import sys

    if not (enabled and sys.stderr.isatty()) or method.kind != "rkhp":
        return
    from rkhp.integrators.tower_substep import stage_solve, tableau_arrays

    degree = stage_solve(method.tableau, tableau_arrays(method.tableau)[0]).degree
    if degree:
        click.echo(f"rkhp: note: {method.name} is implicit: its stages are Taylor polynomials of degree {degree}, "
                   f"so a step is a Poisson map up to O(h^{degree + 1}): the Casimirs are kept to round-off, "
                   "other invariants move at that order, and a step costs far more than an explicit one "
                   "(docs/implicit.md)", err=True)


def _warn_c(method) -> None:
    """The warning `rkhp verify` gives for a given c that differs from A's row sums, on stderr: the
    integrators, like the order conditions, use c = A 1 and never the file's c."""
    tableau = method.tableau if method.kind in ("rkhp", "classical") else None
    mismatch = tableau.c_mismatch() if tableau is not None else []
    if mismatch:
        from .terminal import printable

        stages = ", ".join(str(k + 1) for k, _ in mismatch)
        click.echo(printable(f"rkhp: warning: {tableau.name}: the given c of stage {stages} (counting from 1) "
                             "differs from the row sum of A; the integrator uses the row sums"), err=True)


def _invariant_rows(r: dict) -> list[tuple[str, str]]:
    return [(f"max invariant {k + 1} error over the run", _fmt(e, 3)) for k, e in enumerate(r["invariant_errors_max"])]


def _tolerance_rows(r: dict) -> list[tuple[str, str]]:
    t = r.get("tolerance")
    if t is None:
        return []
    return [("tolerance", f"{t['tol']:g}"), ("estimated error", _fmt(t["estimated_error"], 3))]


def _modified_rows(r: dict) -> list[tuple[str, str]]:
    if "modified_energy_error" not in r:
        return []
    return [(f"modified energy error (H~_{r['modified_order']})",
             _fmt(r["modified_energy_error"], 3))]


def _print_integration(r: dict) -> None:
    from rich.table import Table

    table = Table(title=f"{plain(r['system'])} ({plain(r['realisation'])}) with {plain(r['method'])}: "
                        f"{r['steps']} steps of h = {r['h']:.6g}")
    table.add_column("quantity")
    table.add_column("value", justify="right")
    rows = [("t_final", _fmt(r["t_final"])),
            ("x_final", ", ".join(f"{v:.15g}" for v in r["x_final"])),
            ("error vs exact solution", _fmt(r["exact_error"], 3)),
            ("Casimir error at t_final", _fmt(r["casimir_error"], 3)),
            ("max Casimir error over the run", _fmt(r["casimir_error_max"], 3)),
            ("energy error at t_final", _fmt(r["energy_error"], 3)),
            ("max energy error over the run", _fmt(r["energy_error_max"], 3)),
            *_invariant_rows(r),
            *_modified_rows(r),
            *_tolerance_rows(r),
            ("Newton iterations (mean, max)", f"{r['newton_mean']:.2f}, {r['newton_max']}"),
            ("status", plain(r["status"])),
            ("compile seconds", f"{r['compile_seconds']:.3f}"),
            ("run seconds", f"{r['run_seconds']:.4f}")]
    if r.get("output") is not None:
        rows.append(("written", f"{r['output']['file']} ({r['output']['rows']} rows)"))
    for key, value in rows:
        table.add_row(key, value)
    out = console()
    print_table(out, table)
    timed = r.get("t_eval")
    if timed is not None:
        states = compact_table("states at the chosen times (one step of the method of size t - t_n)")
        for col in ("t", "x", "t - t_n"):
            states.add_column(col, justify="right")
        for t, x, d in zip(timed["times"], timed["states"], timed["substeps"], strict=True):
            states.add_row(f"{t:.6g}", ", ".join(f"{v:.15g}" for v in x), f"{d:.3g}")
        print_table(out, states)
        out.print(f"at these times: Casimir error {_fmt(timed['casimir_error'], 3)}, "
                  f"error vs exact solution {_fmt(timed['exact_error'], 3)}")
