"""`rkhp compose`: the series of RKHP steps composed, against the Butcher product
(docs/modified.md, docs/theory.md §11)."""

from __future__ import annotations

import click

from .modified_views import character_of
from .options import SEED, condition_class_of, console, emit_json, format_option, integer, progress


@click.command()
@click.argument("methods", metavar="METHOD,METHOD[,...]")
@click.option("--order", "-n", "order", type=integer(None, name="N"), default=5, show_default=True,
              help="Largest tree order (at most 7).")
@click.option("--degenerate", is_flag=True, help="Degenerate birealisations: trees of T_0.")
@click.option("--symmetric", is_flag=True,
              help="Symmetric birealisations: T_0 modulo the relations of `rkhp relations`.")
@click.option("--seed", type=SEED, default=0, show_default=True, help="Seed of the generic instances.")
@format_option("table", "json")
def compose(methods, order, degenerate, symmetric, seed, fmt):
    """Compose RKHP steps of size h (tableau names or files, or thpN, applied left to right; `exact`
    is the exact flow) and compare the generating function of the composition with the Butcher products
    of the methods' characters. Exact, on generic systems modulo primes (docs/modified.md)."""
    from rkhp.base.errors import InputError
    from rkhp.series.composed_steps import MAX_ORDER, composition_series
    from rkhp.trees.rooted import check_order

    cls = condition_class_of(degenerate, symmetric)
    check_order(order, MAX_ORDER, what="order of the composition")
    names = [m.strip() for m in methods.split(",")]
    if len(names) < 2 or not all(names):
        raise InputError(f"give two or more methods separated by commas, got {methods!r}")
    if len(names) > 8:
        raise InputError(f"at most 8 steps, got {len(names)}")
    characters = [character_of(name, order)[1] for name in names]
    with progress(fmt != "json") as bar:
        bar.add_task("composing on generic systems modulo primes", total=None)
        series = composition_series(characters, order, cls, names, seed)
    doc = composition_json(series)
    if fmt == "json":
        emit_json(doc)
    else:
        _render(series, doc)


def composition_json(series) -> dict:
    """The JSON document of `rkhp compose` (docs/modified.md, "JSON keys")."""
    from rkhp.series.modified import coefficient_text

    def text(d, t, top=None):
        if d is None or (top is not None and t.order > top):
            return None
        return coefficient_text(d.get(t, 0))

    terms = [{"tree": str(t), "order": t.order,
              "composition": text(series.groupoid, t, series.groupoid_order),
              "hamilton_jacobi": text(series.restart, t),
              "butcher_product": text(series.butcher, t),
              "butcher_product_reversed": text(series.butcher_reversed, t)}
             for level in series.basis for t in level]
    differs = {
        "composition_vs_butcher_product": series.first_difference("groupoid", "butcher"),
        "composition_vs_butcher_product_reversed": series.first_difference("groupoid", "butcher_reversed"),
        "hamilton_jacobi_vs_butcher_product": (None if series.restart is None
                                               else series.first_difference("restart", "butcher")),
    }
    return {"methods": list(series.names), "class": series.cls, "order": series.order,
            "composition_order": series.groupoid_order, "first_difference": differs, "terms": terms,
            "checks": series.checks}


def _render(series, doc) -> None:
    from rich.table import Table
    from rich.text import Text

    from .render import print_table
    from .terminal import plain

    names = plain(" then ".join(series.names))
    table = Table(title=f"{names}: steps of size h, {series.cls} class, c(t) in S = sum h^|t| c(t) F(t)")
    for col in ("tree", "composed steps", "Hamilton–Jacobi", "a1*...*ak", "ak*...*a1"):
        table.add_column(col)
    for term in doc["terms"]:
        table.add_row(Text(term["tree"]), *(Text("—" if term[k] is None else term[k])
                                            for k in ("composition", "hamilton_jacobi", "butcher_product",
                                                      "butcher_product_reversed")))
    out = console()
    print_table(out, table)
    top = series.groupoid_order
    if top < series.order:
        out.print(f"the composed steps are a tree series only up to order {top}", markup=False)
    for key, label in (("composition_vs_butcher_product", "composed steps vs a1*...*ak"),
                       ("composition_vs_butcher_product_reversed", "composed steps vs ak*...*a1"),
                       ("hamilton_jacobi_vs_butcher_product", "Hamilton–Jacobi composition vs a1*...*ak")):
        n = doc["first_difference"][key]
        reach = series.order if key.startswith("hamilton") else top
        verdict = f"equal up to order {reach}" if n is None else f"differ from order {n}"
        if key.startswith("hamilton") and series.restart is None:
            verdict = "not computed (realisations not linear in p)"
        out.print(f"{label}: {verdict}", markup=False)
