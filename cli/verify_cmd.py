"""`rkhp verify` and `rkhp tables`: verified orders of a tableau, and the built-in tableaux."""

from __future__ import annotations

import click

from rkhp.base.tables import booktabs

from .options import console, emit_json, emit_table, format_option, integer, progress
from .render import compact_table, print_table

_PRECISION_HELP = ("float, exact, or a number of decimal digits (fixed point). Default: exact when "
                   "every entry is exact, else the digits given when above 17, else float.")
MAX_SHOW = 1_000_000
_CLASS_SETS = {"general": "general (T)", "degenerate": "degenerate (T_0)"}


@click.command()
@click.argument("tableau", metavar="NAME|FILE")
@click.option("--max-order", type=integer(None, name="N"), default=None,
              help="Check at most up to this order (default: the order found plus one, up to 16).")
@click.option("--precision", default=None, metavar="float|exact|DIGITS", help=_PRECISION_HELP)
@click.option("--show", type=integer(0, MAX_SHOW, name="N"), default=10, show_default=True,
              help="Failing conditions listed per class in the table view (JSON lists all).")
@format_option("table", "json", "csv", "latex")
def verify(tableau, max_order, precision, show, fmt):
    """Verify the order of a tableau over T (general) and T_0 (degenerate), exactly or at a
    stated tolerance, with the failing trees and the principal error (paper §5); or the order and
    symmetry of a composition (docs/compositions.md)."""
    from rkhp.tableaux.compositions import is_composition_name
    from rkhp.tableaux.files import load_tableau
    from rkhp.tableaux.verification import verify as run_verify

    if is_composition_name(tableau):
        from .composition_views import verify_composition

        verify_composition(tableau, fmt)
        return
    tab = load_tableau(tableau)
    with progress(fmt != "json") as bar:
        task = bar.add_task(f"verifying {tab.name}", total=None)
        result = run_verify(tab, max_order=max_order, precision=precision,
                            on_order=lambda n, N: bar.update(task, completed=n, total=N))
    if fmt == "json":
        emit_json(result)
    elif fmt in ("csv", "latex"):
        _emit_orders(result, fmt)
    else:
        _render(result, tab, show)
    fail_on_overstated([result])


ORDER_COLUMNS = ("class", "order", "checked to", "claimed", "principal error", "largest")
#: the columns of `verify --format csv` (docs/results.md)
ORDER_CSV = ("tableau", "class", "order", "lower_bound", "checked_up_to", "claimed", "claim", "principal_error",
             "principal_error_max", "precision")


def _order_cells(result, cls, order) -> list[str]:
    """A class's row of the orders table as the terminal shows it (and --format latex)."""
    checked = result.class_checked_up_to.get(cls, result.checked_up_to)
    lower = ">= " if result.is_lower_bound(cls) else ""
    pe = result.principal_error.get(cls)
    pm = result.principal_error_max.get(cls)
    claimed = result.claimed.get(cls)
    claim = "" if claimed is None else f"{claimed} ({result.claims.get(cls, 'not checked')})"
    return [_CLASS_SETS.get(cls, cls), f"{lower}{order}", str(checked), claim,
            "" if pe is None else f"{pe:.3e}", "" if pm is None else f"{pm:.3e}"]


def _emit_orders(result, fmt) -> None:
    """The orders table as CSV or LaTeX (booktabs; rkhp.base.tables)."""
    rows = [(result.name, cls, order, result.is_lower_bound(cls),
             result.class_checked_up_to.get(cls, result.checked_up_to), result.claimed.get(cls),
             result.claims.get(cls), result.principal_error.get(cls),
             result.principal_error_max.get(cls), result.precision) for cls, order in result.orders.items()]
    caption = (f"Verified orders of {result.name} ({result.stages} stages, {result.kind}); precision "
               f"{result.precision}; {result.tolerance_rule}")
    table = booktabs(ORDER_COLUMNS, [_order_cells(result, cls, order) for cls, order in result.orders.items()],
                     caption, "lrrlrr")
    emit_table(fmt, ORDER_CSV, rows, [table])


def fail_on_overstated(results) -> None:
    """Exit status 1 when a claimed order is overstated (docs/exit-status.md)."""
    bad = [f"{r.name} ({', '.join(r.overstated)})" for r in results if r.overstated]
    if bad:
        from rkhp.base.errors import CheckFailed

        raise CheckFailed(f"claimed order overstated: {'; '.join(bad)}")


def _render(result, tab, show: int) -> None:
    from rich.table import Table

    from .terminal import plain

    out = console()
    out.print(f"[bold]{plain(result.name)}[/bold]: {result.stages} stages, {result.kind}"
              + (f" — {plain(tab.reference)}" if tab.reference else ""))
    out.print(f"precision: {result.precision}; {plain(result.tolerance_rule)}")
    for stage, diff in result.c_mismatch:
        out.print(f"[yellow]warning:[/yellow] the given c of stage {stage + 1} (counting from 1) "
                  f"differs from the row sum of A by {diff:.3g}; the row sums are used")
    table = Table(title=None)
    for col in ORDER_COLUMNS:
        table.add_column(col, justify="left" if col in ("class", "claimed") else "right")
    for cls, order in result.orders.items():
        table.add_row(*map(plain, _order_cells(result, cls, order)))
    print_table(out, table)
    for cls, failures in result.failing.items():
        if not len(failures):
            continue
        exact = result.failing_exact.get(cls, ())
        t = Table(title=f"{cls}: failing conditions of order {result.orders[cls] + 1} "
                        f"({len(failures)})", title_justify="left")
        t.add_column("tree" if cls != "symmetric" else "condition")
        t.add_column("residual a(t) - 1/gamma(t)", justify="right")
        if exact:
            t.add_column("exact")
        for k, f in enumerate(failures[:show]):
            row = [plain(f.label), f"{f.residual:.6e}"]
            if exact:
                row.append(plain(_exact_cell(exact[k])))
            t.add_row(*row)
        if len(failures) > show:
            t.caption = f"... and {len(failures) - show} more (--show N, or --format json)"
        print_table(out, t)
    if result.approximate is not None:
        approx = result.approximate
        largest = max(x.denominator for x in tab.entries())
        orders = ", ".join(f"{cls} {'>= ' if approx.is_lower_bound(cls) else ''}{n}"
                           for cls, n in approx.orders.items())
        out.print(f"[yellow]note:[/yellow] the entries look like rational approximations (denominators up "
                  f"to {largest:.1e}): their exact residuals are nonzero but below the {approx.precision} "
                  f"they pin down, at which the orders are {orders} (JSON approximate_orders); the "
                  "claims are checked against these")
    if not result.claim_ok:
        out.print("[red]claimed orders do not match:[/red] "
                  + ", ".join(f"{cls}: {status}" for cls, status in result.claims.items()
                              if status != "ok"))


EXACT_SHOWN = 32


def _exact_cell(text: str) -> str:
    """An exact residual as the table shows it: whole up to EXACT_SHOWN characters, else its size
    (the JSON holds it whole)."""
    if len(text) <= EXACT_SHOWN:
        return text
    parts = text.lstrip("-").split("/")
    if len(parts) == 2 and all(p.isdigit() for p in parts):
        return f"a fraction of {len(parts[0])}/{len(parts[1])} digits (JSON)"
    return f"{len(text)} characters (JSON)"


@click.command()
@click.option("--precision", default="float", show_default=True,
              metavar="float|exact|DIGITS|default",
              help="Precision of the verification (default: each table's own default, slower "
                   "for the 60-digit ones).")
@format_option("table", "json")
@click.argument("name", required=False, metavar="")
def tables(precision, fmt, name):
    """List the built-in tableaux with stages, kind, verified and claimed orders, and the built-in
    compositions with their orders."""
    if name is not None:  # one tableau is `rkhp show`'s: say so, not just "extra argument"
        from rkhp.base.errors import InputError

        shown = name if len(name) <= 40 and name.isprintable() else "NAME"
        raise InputError(f"rkhp tables lists every built-in tableau and takes no name; to see one: rkhp show {shown}")
    from rkhp.tableaux.files import builtin_names, load_tableau
    from rkhp.tableaux.verification import verify as run_verify

    names = builtin_names()
    rows = []
    with progress(fmt != "json") as bar:
        task = bar.add_task("verifying the built-in tableaux", total=len(names))
        for name in names:
            tab = load_tableau(name)
            chosen = None if precision == "default" else precision
            if chosen == "exact" and not tab.is_exact:
                chosen = None
            result = run_verify(tab, precision=chosen)
            rows.append((tab, result))
            bar.advance(task)
    from .composition_views import composition_rows, render_composition_table

    compositions = composition_rows()
    if fmt == "json":
        emit_json({"tables": [tables_row(tab, r) for tab, r in rows],
                   "compositions": compositions})
    else:
        _render_tables(rows, precision)
        render_composition_table(compositions)
    fail_on_overstated([r for _, r in rows])
    bad = [c.composition.name for c in compositions if c.claim == "overstated"]
    if bad:
        from rkhp.base.errors import CheckFailed

        raise CheckFailed(f"claimed order overstated: {', '.join(bad)}")


_CLASSES = ("general", "degenerate", "symmetric")


def tables_row(tab, r) -> dict:
    """One element of `rkhp tables --format json` (docs/json.md)."""
    return {"name": tab.name, "aliases": list(tab.aliases), "stages": tab.stages, "kind": tab.kind,
            "order": r.general_bound, "degenerate_order": r.degenerate_bound, "symmetric_order": r.symmetric_bound,
            "orders": r.order_bounds, "precision": r.precision,
            "claimed": {"order": tab.claimed_order, "degenerate_order": tab.claimed_degenerate_order,
                        "symmetric_order": tab.claimed_symmetric_order},
            "claim_ok": r.claim_ok, "claims": dict(r.claims), "reference": tab.reference}


def _render_tables(rows, precision) -> None:
    table = compact_table(f"Built-in tableaux (verified orders; precision: {precision})")
    for col in ("name", "s", "kind", "T", "T_0", "sym", "claimed"):
        table.add_column(col, justify="left" if col in ("name", "kind", "claimed") else "right",
                         no_wrap=col == "name")
    for tab, r in rows:
        claimed = "/".join("-" if x is None else str(x) for x in tab.claims.values())
        if not r.claim_ok:
            claimed += " (" + ", ".join(f"{c}: {st}" for c, st in r.claims.items() if st != "ok") + ")"
        orders = [(">=" if r.is_lower_bound(c) else "") + str(r.orders[c]) if c in r.orders else ""
                  for c in _CLASSES]
        table.add_row(tab.name, str(tab.stages), tab.kind, *orders, claimed)
    table.caption = ("s: stages; T, T_0, sym: verified orders over T (general), T_0 (degenerate) and "
                     "in the symmetric class (>= n: checked up to n); claimed: the file's orders "
                     "T/T_0/sym")
    table.caption_justify = "left"
    print_table(console(), table)
