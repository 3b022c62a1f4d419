"""`rkhp modified`: the modified (or modifying) Hamiltonian of an RKHP method, per tree, exact
(docs/modified.md, docs/theory.md §11)."""

from __future__ import annotations

import click

from .modified_views import character_of
from .options import SEED, condition_class_of, console, emit_json, format_option, integer, progress


@click.command()
@click.option("--method", "-m", "method", required=True, metavar="METHOD",
              help="An RKHP method: a built-in tableau or a tableau file with exact entries, or thpN / thpN-t0 "
                   "(docs/methods.md); `exact` is the exact flow (H~ = H).")
@click.option("--order", "-n", "order", type=integer(None, name="N"), required=True,
              help="Largest tree order N: the series up to h^(N-1) (at most 8).")
@click.option("--degenerate", is_flag=True, help="Degenerate birealisations: trees of T_0.")
@click.option("--symmetric", is_flag=True,
              help="Symmetric birealisations: T_0 modulo the relations of `rkhp relations`.")
@click.option("--modifying", is_flag=True,
              help="The modifying Hamiltonian instead: the method applied to it is the exact flow of H.")
@click.option("--seed", type=SEED, default=0, show_default=True, help="Seed of the generic instances.")
@format_option("table", "json", "latex")
def modified(method, order, degenerate, symmetric, modifying, seed, fmt):
    """Terms of the modified Hamiltonian H~ = sum_t h^(|t|-1) c(t) F(t) of an RKHP method: the method's
    step is the exact time-h flow of H~ (backward error analysis). Exact (rationals or the tableau's
    radicals), found order by order on generic systems modulo primes; c(t) = beta(t)/sigma(t) in the
    canonical basis of the class (docs/modified.md). Exits 1 at the first order whose term is not a
    combination of the F(t) of the class."""
    from rkhp.series.modified import MAX_ORDER, modified_hamiltonian, modifying_hamiltonian
    from rkhp.trees.rooted import check_order

    cls = condition_class_of(degenerate, symmetric)
    check_order(order, MAX_ORDER, what="order of the modified Hamiltonian")
    name, character = character_of(method, order)
    solve = modifying_hamiltonian if modifying else modified_hamiltonian
    with progress(fmt != "json") as bar:
        bar.add_task(f"solving order by order to order {order}", total=None)
        series = solve(character, order, cls, seed=seed)
    doc = series_json(series, name)
    if fmt == "json":
        emit_json(doc)
    elif fmt == "latex":
        _latex(series, name)
    else:
        _render(series, name)


def series_json(series, method: str) -> dict:
    """The JSON document of `rkhp modified` (docs/modified.md, "JSON keys")."""
    from rkhp.series.modified import coefficient_text

    return {
        "method": method,
        "class": series.cls,
        "order": series.order,
        "terms": [{"tree": str(t), "order": t.order, "coefficient": coefficient_text(c)} for t, c in series.terms()],
        "series": series.kind,
        "basis": [[str(t) for t in level] for level in series.basis],
        "checks": series.checks,
    }


_SYMBOL = {"modified": "H~", "modifying": "H^"}


def _render(series, method: str) -> None:
    from rich.table import Table
    from rich.text import Text

    from rkhp.series.modified import coefficient_text

    from .render import print_table

    symbol = _SYMBOL[series.kind]
    from .terminal import plain

    table = Table(title=f"{series.kind.capitalize()} Hamiltonian of {plain(method)}, {series.cls} class, to order "
                        f"{series.order}",
                  caption=f"{symbol} = sum over t of h^(|t|-1) c(t) F(t); zero terms not shown")
    for col, justify in (("h^", "right"), ("Tree t", "left"), ("c(t) = beta(t)/sigma(t)", "left"),
                         ("decimal", "right")):
        table.add_column(col, justify=justify)
    for t, c in series.terms():
        table.add_row(str(t.order - 1), Text(str(t)), Text(coefficient_text(c)), f"{float(_decimal(c)):.6g}")
    out = console()
    print_table(out, table)
    out.print(f"basis per order: {_basis_text(series)}", markup=False, soft_wrap=True)


def _basis_text(series) -> str:
    return "; ".join(f"{n}: {len(level)}" for n, level in enumerate(series.basis, start=1))


def _decimal(c):
    from fractions import Fraction

    return c if isinstance(c, Fraction) else c.evalf(20)


def _latex(series, method: str) -> None:
    import sympy

    from rkhp.base.latex import escape_text, longtable, standalone, tree_latex

    rows = []
    for t, c in series.terms():
        value = sympy.Rational(c.numerator, c.denominator) if not hasattr(c, "free_symbols") else c
        rows.append((str(t.order - 1), tree_latex(t), sympy.latex(value)))
    symbol = "\\tilde H" if series.kind == "modified" else "\\hat H"
    title = escape_text(f"{series.kind.capitalize()} Hamiltonian of {method} ({series.cls} class, to order "
                        f"{series.order}): ") + f"${symbol} = \\sum_t h^{{|t|-1}} c(t)\\,F(t)$"
    click.echo(standalone(longtable(("h^{k}", "t", "c(t)"), rows), title=title, tables=True, trees=True))
