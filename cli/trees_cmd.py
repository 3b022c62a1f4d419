"""`rkhp trees` and `rkhp conditions`: enumerate Butcher trees and print order conditions."""

from __future__ import annotations

import click

from rkhp.base.bounds import BYTES_PER_CONDITION, BYTES_PER_PRINTED_TREE
from rkhp.base.exact_text import fraction_text
from rkhp.trees.conditions import order_conditions
from rkhp.trees.rooted import (
    MAX_COUNT_ORDER,
    MAX_ENUMERATION_ORDER,
    check_order,
    check_tree_memory,
    count_trees,
    trees_up_to,
)

from .options import condition_class_of, console, emit_json, format_option, integer
from .render import print_table

FORMATS = ("table", "json", "latex", "markdown")


def _order_option(counted: bool):
    """--order N, its range as the command takes it (`trees` counts further with --count)."""
    reach = f"; up to {MAX_COUNT_ORDER} with --count" if counted else ""
    return click.option("--order", "-n", "order", type=integer(1, name="N"), required=True,
                        help=f"Largest tree order N (1..{MAX_ENUMERATION_ORDER}{reach}).")


_CLASS_TREES = {"general": "T", "degenerate": "T_0", "symmetric": "T_0 (symmetric birealisations)"}


@click.command()
@_order_option(counted=True)
@click.option("--degenerate", is_flag=True, help="Trees of T_0 (degenerate birealisations) instead of T.")
@click.option("--exact-order", is_flag=True, help="Only trees of order exactly N.")
@click.option("--count", is_flag=True, help="Only the counts per order (no trees are built).")
@format_option(*FORMATS)
def trees(order, degenerate, exact_order, count, fmt):
    """Enumerate the Butcher trees of order <= N over T or T_0 (paper §3, docs/theory.md §1)."""
    orders = [order] if exact_order else list(range(1, order + 1))
    if count:
        check_order(order, MAX_COUNT_ORDER)
        counts = {str(n): count_trees(n, degenerate) for n in orders}
        if fmt == "json":
            emit_json({"order": order, "degenerate": degenerate, "counts": counts})
        else:
            _render_counts(counts, degenerate, fmt)
        return
    check_order(order, MAX_ENUMERATION_ORDER)
    check_tree_memory(order, degenerate, per_tree=BYTES_PER_PRINTED_TREE)
    found = [t for t in trees_up_to(order, degenerate) if not exact_order or t.order == order]
    counts = {str(n): sum(1 for t in found if t.order == n) for n in orders}
    if fmt == "json":
        emit_json({"order": order, "degenerate": degenerate, "counts": counts,
                   "trees": [{"tree": str(t), "order": t.order, "sigma": t.sigma, "gamma": t.gamma}
                             for t in found]})
        return
    rows = [(str(t.order), str(t), str(t.sigma), str(t.gamma)) for t in found]
    header = ("Order", "Tree", "sigma", "gamma")
    if fmt == "latex":
        from rkhp.base.latex import tree_latex

        body = [(str(t.order), tree_latex(t), str(t.sigma), str(t.gamma)) for t in found]
        _echo_latex(("\\text{Order}", "\\text{Tree}", "\\sigma", "\\gamma"), body, trees=True)
    elif fmt == "markdown":
        click.echo(_markdown(header, rows))
    else:
        _rich_table(f"Trees of {'T_0' if degenerate else 'T'} up to order {order}", header, rows, counts)


@click.command()
@_order_option(counted=False)
@click.option("--degenerate", is_flag=True, help="Conditions over T_0 (degeneracy condition, paper eq. (degen)).")
@click.option("--symmetric", is_flag=True,
              help="Reduced conditions of symmetric birealisations (combinations of T_0 residuals).")
@click.option("--exact-order", is_flag=True, help="Only the conditions of order exactly N.")
@format_option(*FORMATS)
def conditions(order, degenerate, symmetric, exact_order, fmt):
    """Print the RKHP order conditions a(t) = 1/gamma(t) of order <= N in Butcher's form.

    Over all trees T (general birealisations), with --degenerate over T_0 (paper, Table 1), or
    with --symmetric the fewer conditions of symmetric birealisations, as combinations of the
    residuals r(t) = gamma(t) a(t) - 1 over T_0.
    """
    cls = condition_class_of(degenerate, symmetric)
    check_order(order, MAX_ENUMERATION_ORDER)
    check_tree_memory(order, cls != "general", "the conditions", per_tree=BYTES_PER_CONDITION)
    conds = order_conditions(order, cls, exact_order)
    orders = [order] if exact_order else list(range(1, order + 1))
    counts = {str(n): sum(1 for c in conds if c.order == n) for n in orders}
    if fmt == "json":
        emit_json({"order": order, "degenerate": degenerate, "class": cls, "counts": counts,
                   "conditions": [_condition_json(c) for c in conds]})
        return
    if fmt == "latex":
        from rkhp.base.latex import tree_latex

        _echo_latex(("\\text{Order}", "\\text{Butcher tree } \\tau", "\\text{Order condition}"),
                    [(str(c.order), " ".join(tree_latex(t) for t in c.trees), c.latex()) for c in conds],
                    trees=True)
        return
    rows = [(str(c.order), " ".join(str(t) for t in c.trees), c.text()) for c in conds]
    header = ("Order", "Tree", "Order condition")
    if fmt == "markdown":
        click.echo(_markdown(header, [(o, f"`{t}`", f"`{x}`") for o, t, x in rows]))
    else:
        title = f"RKHP order conditions over {_CLASS_TREES[cls]} up to order {order}"
        _rich_table(title, header, rows, counts)


def _condition_json(c) -> dict:
    """One condition; a combined (symmetric) condition also lists its trees and weights."""
    rhs_text = fraction_text(c.rhs)
    if c.is_single:
        t = c.tree
        return {"tree": str(t), "order": t.order, "sigma": t.sigma, "gamma": t.gamma,
                "rhs": rhs_text, "condition": c.text(), "latex": c.latex()}
    return {"tree": None, "order": c.order, "trees": [str(t) for t in c.trees],
            "weights": [str(w) for w in c.weights], "rhs": rhs_text, "condition": c.text(),
            "latex": c.latex()}


# ----------------------------------------------------------------------------- rendering


def _rich_table(title, header, rows, counts) -> None:
    from rich.table import Table
    from rich.text import Text

    table = Table(title=title, title_justify="left")
    for h in header:
        table.add_column(h)
    previous = None
    for row in rows:
        if previous is not None and row[0] != previous:
            table.add_section()
        cells = row if row[0] != previous else ("",) + tuple(row[1:])
        table.add_row(*(Text(c) for c in cells))  # brackets are trees, not rich markup
        previous = row[0]
    out = console()
    print_table(out, table)  # a tree or a condition is never cut
    total = sum(counts.values())
    out.print("Count per order: " + ", ".join(f"{n}: {c}" for n, c in counts.items()) + f"; total {total}")


def _render_counts(counts, degenerate, fmt) -> None:
    header = ("Order", f"trees in {'T_0' if degenerate else 'T'}")
    rows = list(counts.items())
    if fmt == "latex":
        _echo_latex(("\\text{Order}", "\\#" + ("T_0" if degenerate else "T")), rows)
    elif fmt == "markdown":
        click.echo(_markdown(header, rows))
    else:
        from rich.table import Table

        table = Table(*header)
        for n, c in rows:
            table.add_row(n, str(c))
        console().print(table)


def _echo_latex(header, rows, trees: bool = False) -> None:
    """A standalone LaTeX document holding the longtable (compiles with pdflatex as it is)."""
    from rkhp.base.latex import longtable, standalone

    click.echo(standalone(longtable(header, rows), tables=True, trees=trees))


def _markdown(header, rows) -> str:
    lines = ["| " + " | ".join(header) + " |", "|" + "---|" * len(header)]
    lines += ["| " + " | ".join(str(c) for c in row) + " |" for row in rows]
    return "\n".join(lines)


