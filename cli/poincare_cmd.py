"""`rkhp poincare`: the Poincaré section of an orbit (points, CSV, plot)."""

from __future__ import annotations

import click

from rkhp.integrators.methods import DEFAULT_METHOD
from rkhp.ivp.tolerance import MIN_TOLERANCE

from .options import (
    METHOD_HELP,
    STEPS,
    T_FINAL,
    compile_notice,
    console,
    emit_json,
    emit_table,
    force_option,
    format_option,
    names,
    output_path,
    parse_x0,
    progress,
    real,
    realisation_option,
    run_provenance,
    x0_option,
)
from .render import compact_table, plan_line, print_table
from .terminal import plain

#: the points the table shows (all of them: --format csv or json)
SHOWN = 20
#: the columns of `poincare --format csv` (then x1..xn)
SECTION_CSV = ("crossing", "t")


def _plot_file():
    from rkhp.studies.plots import check_plot_path

    return output_path(check=check_plot_path)


@click.command("poincare")
@click.argument("system")
@click.option("--section", "expression", required=True, metavar="EXPR",
              help="The hypersurface EXPR = 0, an expression in x1..xn (README \"Expressions\").")
@click.option("--direction", type=click.Choice(("up", "down", "both")), default="up", show_default=True,
              help="Crossings where EXPR increases (up), decreases (down) or both.")
@click.option("--t-final", type=T_FINAL, default=None, help="Length of the orbit (default: the system's T).")
@click.option("--method", default=DEFAULT_METHOD, show_default=True, metavar="METHOD",
              help=METHOD_HELP + " With --tol also auto (docs/solve.md).")
@click.option("--tol", type=real(MIN_TOLERANCE, 1.0, high_open=True, name="TOL"), default=None,
              help="Error allowed at T (2-norm, relative to max(1, |x(T)|)); default 1e-6 (docs/solve.md).")
@click.option("--steps", type=STEPS, default=None, help="Number of steps instead of --tol.")
@x0_option()
@realisation_option()
@click.option("--axes", type=names("XI,XJ"), default="x1,x2", show_default=True,
              help="The two coordinates of the plot.")
@click.option("--plot", type=_plot_file(), default=None, help="Plot of the points (.png, .svg, .pdf).")
@force_option()
@format_option("table", "json", "csv")
def poincare(system, expression, direction, t_final, method, tol, steps, x0, realisation, axes, plot, force, fmt):
    """The Poincaré section of SYSTEM's orbit with EXPR = 0: each crossing located by steps of the
    method (docs/solve.md)."""
    from rkhp.base.errors import NumericalFailure
    from rkhp.integrators.methods import resolve_system
    from rkhp.ivp.poincare import axes_of, poincare_section
    from rkhp.ivp.solve import FAILED

    poisson = resolve_system(system, realisation, parse_x0(x0))
    chosen_axes = axes_of(axes, poisson.dim)
    compile_notice(("rkhp", "composition"), fmt != "json", poisson)
    with progress(fmt != "json") as bar:
        pilot = bar.add_task("pilot runs", total=None)
        task = bar.add_task("poincare", total=None)

        def told(planned):
            if fmt == "table" and planned.choice is not None:
                click.echo(plan_line(planned))

        found = poincare_section(poisson, expression, t_final, method, tol, steps=steps, direction=direction,
                        on_plan=told, on_candidate=lambda done, total: bar.update(pilot, completed=done, total=total),
                        on_progress=lambda done, total: bar.update(task, completed=done, total=total))
    if plot is not None and len(found.times):
        from rkhp.studies.plots import plot_section

        plot_section(found, chosen_axes, plot, run_provenance(), force)
    if fmt == "json":
        emit_json(found)
    elif fmt == "csv":
        header = (*SECTION_CSV, *(f"x{i + 1}" for i in range(poisson.dim)))
        rows = [(k + 1, t, *p) for k, (t, p) in enumerate(zip(found.times.tolist(), found.points.tolist(),
                                                             strict=True))]
        emit_table("csv", header, rows, [])
    else:
        _render(found, plot)
    if found.result.status == FAILED:
        raise NumericalFailure(f"{poisson.name}, {found.result.method}: {found.result.message}")


def _render(found, plot) -> None:
    r = found.result
    out = console()
    end = r.t[-1] if len(r.t) else 0.0
    out.print(f"{r.system}: section {found.expression} = 0 ({found.direction}), t in [0, {end:g}], "
              f"{r.method}, {r.steps} steps of h = {r.h:.6g}: {len(found.times)} crossings", markup=False)
    table = compact_table(None)
    table.add_column("crossing", justify="right")
    table.add_column("t", justify="right")
    table.add_column("x", justify="right")
    for k in range(min(len(found.times), SHOWN)):
        table.add_row(str(k + 1), f"{found.times[k]:.12g}", ", ".join(f"{v:.10g}" for v in found.points[k]))
    print_table(out, table)
    if len(found.times) > SHOWN:
        out.print(f"... {len(found.times) - SHOWN} more (all of them: --format csv or json)", markup=False)
    casimir = "-" if r.casimir_error_max is None else f"{r.casimir_error_max:.2e}"
    out.print(f"largest over the orbit: Casimir error {casimir}, energy error {r.energy_error_max:.2e}"
              + "".join(f", invariant {k + 1} {e:.2e}" for k, e in enumerate(r.invariant_errors_max)), markup=False)
    if plot:
        out.print(f"plot written to {plain(plot)}", markup=False)
