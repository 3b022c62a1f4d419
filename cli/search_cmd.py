"""`rkhp search`: minimal-stage tableaux by seeded multistart, polished, verified, proved."""

from __future__ import annotations

import click

from rkhp.base import bounds

from .options import (
    SEED,
    condition_class_of,
    console,
    emit_json,
    executor_options,
    force_option,
    format_option,
    integer,
    output_path,
    progress,
    real,
)
from .render import print_array, print_table
from .terminal import plain


@click.command()
@click.option("--stages", "-s", type=integer(1, name="S"), required=True, help="Number of stages S (1..16).")
@click.option("--order", "-n", type=integer(1, name="N"), default=None,
              help="Order N to reach (1..8); without it, the highest order reachable with S stages.")
@click.option("--degenerate", is_flag=True, help="Conditions over T_0 (degenerate birealisations).")
@click.option("--symmetric", is_flag=True, help="Reduced conditions of symmetric birealisations.")
@click.option("--implicit", is_flag=True, help="Full matrix A (implicit methods) instead of explicit.")
@click.option("--restarts", type=integer(1, bounds.MAX_RESTARTS, "N"), default=50, show_default=True,
              help="Restart budget per order (random starts).")
@click.option("--time-limit", type=real(0.0, bounds.MAX_SECONDS, low_open=True, name="SECONDS"), default=None,
              help="Seconds allowed to the whole search, every order, restarts (checked inside each "
                   "one) and proof included (default: no limit for restarts, 60 s for --prove).")
@click.option("--seed", type=SEED, default=0, show_default=True, help="Seed: restart k of order N "
              "starts from numpy default_rng([seed, S, N, k]).")
@executor_options("restarts")
@click.option("--optimize", type=click.Choice(["error", "phase"]), default=None,
              help="Minimise on the solution family the principal error norm at order N+1 (error) or "
                   "the phase error theta(z) - z on the oscillator (phase: docs/stability.md).")
@click.option("--digits", type=integer(1, name="D"), default=30, show_default=True,
              help="Digits D of the mpmath polishing and verification (20..500).")
@click.option("--prove", is_flag=True,
              help="When an order is not reached, try to prove that no tableau exists (Groebner).")
@click.option("--prove-engine", type=click.Choice(["auto", "singular", "sympy"]), default="auto",
              show_default=True, help="Groebner engine of --prove: Singular when installed (with "
              "checked cofactors), else sympy.")
@click.option("--certificate", type=output_path(".json"), default=None,
              help="With --prove: write the certificate 1 = sum g_i f_i to this .json file.")
@click.option("--save", type=output_path(".toml", ".json"), default=None,
              help="Write the tableau found to a .toml or .json file (loadable by verify).")
@force_option()
@format_option("table", "json")
def search(stages, order, degenerate, symmetric, implicit, restarts, time_limit, seed, workers,
           scheduler, optimize, digits, prove, prove_engine, certificate, save, force, fmt):
    """Search Runge–Kutta tableaux meeting the RKHP order conditions (paper §5).

    Solves the order conditions over T (general), T_0 (--degenerate) or the symmetric class from
    seeded random starts (scipy least squares, exact Jacobian), polishes each success by Newton's
    method in mpmath to D digits, recognises closed forms (kept only when exactly verified) and
    verifies the result with the verify engine. --prove looks for a Groebner certificate that
    the first order not reached is impossible (Singular when installed: exact cofactors of
    1 = sum g_i f_i, checked; else sympy).
    """
    from rkhp.base.executors import open_executor
    from rkhp.search.driver import SearchOptions
    from rkhp.search.driver import search as run_search
    from rkhp.search.system import check_problem

    cls = condition_class_of(degenerate, symmetric)
    check_problem(stages, order)
    if optimize and prove and order is not None:
        raise click.UsageError("--optimize needs --order N to be reached while --prove needs it "
                               "to fail: give one of them")
    if certificate and not prove:
        raise click.UsageError("--certificate needs --prove")
    options = SearchOptions(restarts=restarts, seed=seed, time_limit=time_limit,
                            digits=digits, optimize=optimize, prove=prove, proof_engine=prove_engine)
    options.check()
    with open_executor(workers, scheduler) as executor, progress(fmt != "json") as bar:
        tasks: dict[int, int] = {}

        def on_progress(n, done, total):
            if n not in tasks:
                tasks[n] = bar.add_task(f"order {n}", total=total)
            bar.update(tasks[n], completed=done)

        def on_proof(n, step, elapsed, limit):
            if "proof" not in tasks:
                tasks["proof"] = bar.add_task("proof", total=round(limit))
            bar.update(tasks["proof"], completed=min(round(elapsed), round(limit)),
                       description=f"proof, order {n}, seconds: {step}")

        result = run_search(stages, order, cls, implicit, options, on_progress, executor, on_proof)
    if save and result.found is not None and not result.interrupted:
        _save(result, save, force)
    if certificate and result.proof is not None and result.proof.certificate is not None:
        from rkhp.search.certificates import save_certificate

        save_certificate(result.proof.certificate, certificate, force)
    if fmt == "json":
        emit_json(result)
    else:
        _render(result, save, certificate)
    if result.interrupted:
        click.echo("rkhp: interrupted: the best found so far is shown", err=True)
        raise click.exceptions.Exit(130)
    if result.found is None:  # a failed check: exit status 1 (docs/exit-status.md)
        from rkhp.base.errors import CheckFailed

        proved = result.proof is not None and result.proof.proved
        raise CheckFailed(f"no tableau found of order {result.order} with {stages} stages"
                          + (" (proved impossible)" if proved else "")
                          + (f"; nothing was saved to {save}" if save else ""))


def _save(result, path, force) -> None:
    from rkhp.tableaux.files import save_tableau

    from .options import run_provenance

    save_tableau(result.tableau_to_save(), path, run_provenance(), force)


SHOWN_DIGITS = 12


def _shown(x) -> str:
    """An entry as shown: exact forms whole, decimals of D digits rounded to SHOWN_DIGITS."""
    from rkhp.tableaux.tableau import entry_decimal, entry_text, is_exact

    return entry_text(x) if is_exact(x) else entry_decimal(x, SHOWN_DIGITS)


def _count(n: int, one: str, many: str | None = None) -> str:
    return f"{n} {one if n == 1 else many or one + 's'}"


def _render(result, save, certificate=None) -> None:
    from rich.table import Table

    from rkhp.base.json_form import json_form

    con = console()
    data = json_form(result)
    kind = "implicit" if result.implicit else "explicit"
    head = f"{result.stages} stages, {kind}, class {result.cls}"
    if result.found is None:
        con.print(f"[bold]No tableau found[/bold] ({head}, order {result.order}): "
                  f"{data['restarts']} restarts, {data['seconds']:.2f} s")
    else:
        con.print(f"[bold]Order {result.found.order}[/bold] ({head}): found in "
                  f"{_count(data['order_restarts'], 'restart')} of order {result.found.order} "
                  f"({_count(data['order_successes'], 'success', 'successes')}; "
                  f"{_count(data['restarts'], 'restart')} over all orders), {data['seconds']:.2f} s")
        import mpmath

        with mpmath.workdps(result.options.digits):
            print_array(con, result.found.tableau, _shown, "c | A / b")
        if not result.found.exact:
            con.print(f"(entries shown to {SHOWN_DIGITS} digits; all {result.options.digits} "
                      "with --format json or --save)")
        ver = result.found.verification
        principal = data["principal_error"]
        con.print(f"residual {data['residual']:.3g}; principal error (order {result.found.order + 1}) "
                  + (f"{principal:.6g}" if principal is not None else
                     "- (no conditions of that order known for the class)"))
        orders = ", ".join(f"{cls} {'>= ' if ver.is_lower_bound(cls) else ''}{n}"
                           for cls, n in ver.orders.items())
        con.print(f"verified orders: {orders}; decided by: {data['decided_by']}")
        if save:
            con.print(f"saved to {plain(save)}")
    if result.optimisation is not None:
        opt = result.optimisation
        rows = Table("method", "principal error norm", title="Error norms at order N+1")
        rows.columns[0].no_wrap = True
        rows.add_row("optimum found", f"{opt.error_norm:.6g}")
        for k in opt.known:
            rows.add_row(k.name, f"{k.error_norm:.6g}")
        print_table(con, rows)
        if opt.objective == "phase":
            con.print("phase of the tableau found: " + ("not verified" if opt.phase_order is None else
                      f"order {opt.phase_order}, theta(z) - z = {opt.phase_constant:.6g} "
                      f"z^{opt.phase_order + 1} + ..."))
        if opt.kkt_residual is not None:
            con.print(f"optimum stationary to D digits: max |KKT residual| {opt.kkt_residual:.2g}")
    ev = data["evidence_next_order"]
    if ev is not None and ev["restarts"]:
        con.print(f"order {ev['order']} not reached: {ev['restarts']} restarts, best max residual "
                  f"{ev['best_residual']:.3g}")
    if result.proof is not None:
        con.print(f"proof (order {result.proof_order}): {data['proof']['result']}")
        con.print(f"  method: {data['proof']['method']}")
        proof = result.proof
        con.print(f"  unknowns: {', '.join(proof.variables)} ({proof.substitution})")
        if proof.modular and not proof.proved:
            con.print(f"  modular evidence: {proof.modular_text()}")
        if proof.proved:
            con.print("  certificate: the ideal generated by")
            for p in proof.polynomials:
                con.print(f"    {p}")
            con.print("  has reduced Groebner basis [1]")
            if proof.certificate is not None:
                where = f"saved to {certificate}" if certificate else "--certificate FILE saves them"
                con.print(f"  cofactors g_i with 1 = sum g_i f_i: {proof.check.terms} terms, checked "
                          f"exactly ({where})")
