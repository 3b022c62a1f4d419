"""`rkhp systems`, `rkhp check`, `rkhp integrate`: Poisson systems and the RKHP integrators."""

from __future__ import annotations

import click

from rkhp.base import bounds

from .options import (
    METHOD_HELP,
    POSITIVE,
    SEED,
    STEPS,
    T_FINAL,
    compile_notice,
    console,
    emit_json,
    format_option,
    integer,
    parse_x0,
    x0_option,
)
from .render import compact_table, print_table


def realisation_option():
    return click.option("--realisation", default="symmetric", show_default=True,
                        help="Birealisation: symmetric (degenerate), shifted (x + Q p; general), "
                             "quartic (x + grad K(p); degenerate, not symmetric), truncated:K (the "
                             "spray series to degree K in p, K = 1..12; symmetric).")


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
        emit_json(rows)
        return
    table = compact_table("Built-in Poisson systems (realisations: symmetric, shifted, quartic, "
                          "truncated:K)")
    for col in ("name", "family", "n", "domain", "x0", "t_final", "Casimirs", "exact"):
        table.add_column(col, no_wrap=col in ("name", "family"))
    for r in rows:
        table.add_row(r["name"], r["family"], str(r["dim"]), r["domain"],
                      ", ".join(f"{v:.4g}" for v in r["x0"]), _fmt(r["t_final"]),
                      "; ".join(r["casimirs"]) or "-", "yes" if r["exact_solution"] else "no")
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
    differentiation at random points; exit status 1 if a deviation exceeds 1e-12."""
    from rkhp.systems import get_system
    from rkhp.systems.check import check_birealisation

    poisson = get_system(system, realisation)
    compile_notice((), fmt != "json", poisson)
    result = check_birealisation(poisson, samples=samples, seed=seed)
    if fmt == "json":
        emit_json(result.to_json())
    else:
        from rich.table import Table

        table = Table(title=f"{result.system} ({result.realisation}): {samples} samples, "
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
                  f"axioms: {'ok' if result.ok else 'FAILED'} (tolerance {result.tolerance:g})")
    if not result.ok:
        from rkhp.base.errors import CheckFailed

        bad = ", ".join(f"{k} {v:.2e}" for k, v in result.deviations.items() if v > result.tolerance)
        raise CheckFailed(f"{result.system} ({result.realisation}): birealisation axioms violated "
                          f"({bad} > {result.tolerance:g})")


def integration_report(system, trajectory, method: str, h: float, steps: int) -> dict:
    """The JSON document of `rkhp integrate` (keys in the issue's order, plus exact_error)."""
    import numpy as np

    x0, xf = trajectory.states[0], trajectory.final_state
    casimir = (float(np.abs(system.casimir_values(xf) - system.casimir_values(x0)).max())
               if system.casimirs else None)
    iters = trajectory.newton_iterations
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
        "status": trajectory.status, "compile_seconds": trajectory.compile_seconds,
        "run_seconds": trajectory.run_seconds, "realisation": system.realisation,
        "exact_error": exact,
    }


@click.command("integrate")
@click.argument("system")
@click.option("--method", "method", required=True, metavar="METHOD", help=METHOD_HELP)
@click.option("--steps", type=STEPS, default=None, help="Number of steps over [0, T].")
@click.option("--h", "h", type=POSITIVE, default=None,
              help="Step size; it must divide T (steps = T / h; docs/input.md).")
@click.option("--t-final", type=T_FINAL, default=None, help="Final time T (default: the system's).")
@x0_option()
@click.option("--modified", "modified_order", type=integer(1, name="N"), default=None, metavar="N",
              help="Also report max over the run of |H~_N(y_n) - H~_N(y_0)|, H~_N the method's modified "
                   "Hamiltonian to order N (docs/modified.md).")
@realisation_option()
@format_option("table", "json")
def integrate(system, method, steps, h, t_final, x0, modified_order, realisation, fmt):
    """Integrate SYSTEM (built-in or spec file) with METHOD (docs/methods.md)."""
    from rkhp.base.errors import NumericalFailure
    from rkhp.integrators.methods import resolve_method, resolve_system

    poisson = resolve_system(system, realisation, parse_x0(x0))
    chosen = resolve_method(method)
    n, step = bounds.step_plan(poisson.t_final if t_final is None else t_final, steps, h)
    bounds.check_trajectory(n, poisson.dim)
    series = None
    if modified_order is not None:
        from .modified_cmd import modified_series

        series = modified_series(poisson, chosen, modified_order, fmt != "json")
    compile_notice((chosen.kind,), fmt != "json", poisson)
    trajectory = chosen.integrate(poisson, step, n)
    report = integration_report(poisson, trajectory, chosen.name, step, n)
    if series is not None and trajectory.ok:
        from .modified_cmd import modified_energy_report

        report.update(modified_energy_report(poisson, series, step, trajectory.states, fmt != "json"))
    if fmt == "json":
        emit_json(report)
    else:
        _print_integration(report)
    if not trajectory.ok:
        raise NumericalFailure(f"{poisson.name}, {chosen.name}, h = {step:g}: "
                               f"{trajectory.status}")


def _modified_rows(r: dict) -> list[tuple[str, str]]:
    if "modified_energy_error" not in r:
        return []
    return [("max energy error over the run", _fmt(r["energy_error_max"], 3)),
            (f"modified energy error (H~_{r['modified_order']})",
             _fmt(r["modified_energy_error"], 3))]


def _print_integration(r: dict) -> None:
    from rich.table import Table

    table = Table(title=f"{r['system']} ({r['realisation']}) with {r['method']}: "
                        f"{r['steps']} steps of h = {r['h']:.6g}")
    table.add_column("quantity")
    table.add_column("value", justify="right")
    rows = [("t_final", _fmt(r["t_final"])),
            ("x_final", ", ".join(f"{v:.15g}" for v in r["x_final"])),
            ("error vs exact solution", _fmt(r["exact_error"], 3)),
            ("Casimir error", _fmt(r["casimir_error"], 3)),
            ("energy error", _fmt(r["energy_error"], 3)),
            *_modified_rows(r),
            ("Newton iterations (mean, max)", f"{r['newton_mean']:.2f}, {r['newton_max']}"),
            ("status", r["status"]),
            ("compile seconds", f"{r['compile_seconds']:.3f}"),
            ("run seconds", f"{r['run_seconds']:.4f}")]
    for key, value in rows:
        table.add_row(key, value)
    print_table(console(), table)
