"""The views of a composition in `rkhp verify`, `rkhp show` and `rkhp tables`: its base, substep
coefficients, symmetry and orders (docs/compositions.md)."""

from __future__ import annotations

import click

from .options import console, emit_json, emit_table
from .render import compact_table, print_table

_CLASSES = ("general", "degenerate", "symmetric")


def verify_composition(spec: str, fmt: str) -> None:
    """`rkhp verify` of a composition: orders, symmetry, claim; exit 1 when the claim is overstated."""
    from rkhp.base.errors import CheckFailed
    from rkhp.tableaux.compositions import load_composition, verify_composition

    result = verify_composition(load_composition(spec))
    if fmt == "json":
        emit_json(result)
    elif fmt in ("csv", "latex"):
        _emit_verification(result, fmt)
    else:
        _render_verification(result)
    if result.claim == "overstated":
        raise CheckFailed(f"claimed order overstated: {result.composition.name} claims "
                          f"{result.composition.claimed_order}, its conditions hold to order {result.own.order} "
                          f"with {result.composition.base} of symmetric order {result.own.base_order}")


def _order_rows(result) -> list[tuple[str, object]]:
    """(label, CompositionOrder): the published symmetric case, then each realisation class."""
    c = result.composition
    return [(f"symmetric, order {result.own.base_order} (for claims)", result.own),
            *((f"{c.base} on a {cls} realisation", result.by_class[cls]) for cls in _CLASSES)]


def _order_cells(label: str, o) -> list[str]:
    """A row of the orders table as the terminal shows it (and --format latex)."""
    failing = "" if o.largest_failing is None else f"{o.largest_failing:.2e} at order {o.order + 1}"
    return [label, f"{o.base_order}{' (odd in h)' if o.base_symmetric else ''}", str(o.order), str(o.conditions),
            failing]


ORDER_COLUMNS = ("base", "base order", "order", "conditions", "largest failing")
#: the columns of `verify COMPOSITION --format csv` (docs/results.md)
ORDER_CSV = ("composition", "case", "base_order", "base_symmetric", "order", "checked_up_to", "conditions",
             "largest_failing", "precision", "claimed_order", "claim")


def _emit_verification(result, fmt) -> None:
    """The orders table of a composition as CSV or LaTeX (booktabs; rkhp.base.tables)."""
    from rkhp.base.tables import booktabs

    c = result.composition
    rows = [(c.name, label, o.base_order, o.base_symmetric, o.order, o.checked_up_to, o.conditions,
             o.largest_failing, o.precision, c.claimed_order, result.claim) for label, o in _order_rows(result)]
    caption = (f"Orders of the composition {c.name}: {c.substeps} substeps of {c.base}, "
               f"{'symmetric' if c.symmetric else 'not symmetric'} coefficients; precision {result.own.precision}")
    table = booktabs(ORDER_COLUMNS, [_order_cells(label, o) for label, o in _order_rows(result)], caption, "lrrrr")
    emit_table(fmt, ORDER_CSV, rows, [table])


def _render_verification(result) -> None:
    from rich.markup import escape

    c = result.composition
    out = console()
    out.print(f"[bold]{escape(c.name)}[/bold]: composition of {c.substeps} substeps of "
              f"{escape(c.base)}" + (f" — {escape(c.reference)}" if c.reference else ""))
    out.print(f"coefficients: {'symmetric' if c.symmetric else 'not symmetric'} (gamma reversed "
              f"{'equals' if c.symmetric else 'differs from'} gamma); precision: {result.own.precision}")
    out.print(f"base {escape(c.base)}: {'symmetric' if result.base_symmetric else 'not symmetric'} as an RKHP "
              f"method under a symmetric birealisation (checked to order {result.base_symmetry_checked})")
    if c.processed:
        out.print(f"processed: a processor of {len(c.processor)} substeps before the first step, its inverse at "
                  f"each output; the orders are effective orders, the kernel alone has order {result.kernel_order}")
    table = compact_table(None)
    for col in ORDER_COLUMNS:
        table.add_column(col, justify="left" if col == "base" else "right")
    for label, o in _order_rows(result):
        table.add_row(*map(escape, _order_cells(label, o)))
    print_table(out, table)
    if result.claim is not None:
        out.print(f"claimed order {c.claimed_order}: {result.claim}")


def composition_json(spec: str) -> dict:
    """The JSON document of `rkhp show` for a composition (docs/json.md)."""
    from rkhp.tableaux.compositions import class_composition_orders, load_composition
    from rkhp.tableaux.files import load_tableau

    c = load_composition(spec)
    order = class_composition_orders(c, load_tableau(c.base))["symmetric"].order
    return {"name": c.name, "kind": "composition", "aliases": list(c.aliases), "base": c.base,
            "substeps": c.substeps, "gamma": c.gamma_text(), "gamma_float": list(c.gamma_float),
            "processor": c.processor_text(), "processor_float": list(c.processor_float),
            "symmetric": c.symmetric, "order": order,
            "claimed_order": c.claimed_order, "reference": c.reference}


def show_composition(spec: str, fmt: str) -> None:
    """`rkhp show` of a composition: base, coefficients (as given and in float64), order, source."""
    doc = composition_json(spec)
    if fmt == "json":
        emit_json(doc)
        return
    if fmt == "latex":
        from rkhp.base.latex import standalone

        rows = " \\\\\n".join([*(f"\\gamma_{{{k + 1}}} & {g:.17g}" for k, g in enumerate(doc["gamma_float"])),
                            *(f"c_{{{k + 1}}} & {c:.17g}" for k, c in enumerate(doc["processor_float"]))])
        click.echo(standalone(f"\\[\n\\begin{{array}}{{lr}}\n{rows}\n\\end{{array}}\n\\]",
                              title=f"{doc['name']}: composition of {doc['base']}"))
        return
    from rich.markup import escape

    out = console()
    out.print(f"[bold]{escape(doc['name'])}[/bold]: composition of {doc['substeps']} substeps of "
              f"{escape(doc['base'])}, order {doc['order']} with its base on a symmetric realisation"
              + (", symmetric" if doc["symmetric"] else "")
              + (f"; processed: processor c of {len(doc['processor'])} substeps (effective order)"
                 if doc["processor"] else ""))
    if doc["reference"]:
        out.print(f"source: {escape(doc['reference'])}")
    table = compact_table(None)
    for col in ("i", "gamma_i (as given)", "float64"):
        table.add_column(col, justify="right" if col != "gamma_i (as given)" else "left")
    for k, (g, x) in enumerate(zip(doc["gamma"], doc["gamma_float"], strict=True)):
        table.add_row(str(k + 1), escape(g), f"{x:.17g}")
    for k, (c, x) in enumerate(zip(doc["processor"], doc["processor_float"], strict=True)):
        table.add_row(f"c{k + 1}", escape(c), f"{x:.17g}")
    print_table(out, table)


def composition_rows():
    """(name, verification) of every built-in composition."""
    from rkhp.tableaux.compositions import builtin_compositions, load_composition, verify_composition

    return [verify_composition(load_composition(name)) for name in builtin_compositions()]


def render_composition_table(results) -> None:
    table = compact_table("Built-in compositions (orders with the base on a symmetric realisation; "
                          "processed: kernel + processor substeps, effective order)")
    for col in ("name", "substeps", "base", "order", "symmetric", "claimed"):
        table.add_column(col, justify="left" if col in ("name", "base") else "right")
    for r in results:
        c = r.composition
        claimed = "-" if c.claimed_order is None else f"{c.claimed_order} ({r.claim})"
        substeps = f"{c.substeps} + {len(c.processor)}" if c.processed else str(c.substeps)
        table.add_row(c.name, substeps, c.base, str(r.own.order), "yes" if c.symmetric else "no", claimed)
    print_table(console(), table)
