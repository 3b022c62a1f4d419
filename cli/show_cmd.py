"""`rkhp show`: a tableau's Butcher array (exact entries and decimals), its source and claims."""

from __future__ import annotations

import click

from .options import console, emit_json, format_option
from .render import print_array

DECIMAL_DIGITS = 12
_CLASS_NAMES = {"general": "general", "degenerate": "degenerate", "symmetric": "symmetric"}


@click.command()
@click.argument("tableau", metavar="NAME|FILE")
@format_option("table", "json", "latex")
def show(tableau, fmt):
    """Show a tableau: the Butcher array c | A / b (exact entries and decimals), its source and
    the orders it claims (check them with `rkhp verify`)."""
    from rkhp.tableaux.compositions import is_composition_name
    from rkhp.tableaux.files import load_tableau

    if is_composition_name(tableau):
        from .composition_views import show_composition

        show_composition(tableau, fmt)
        return
    tab = load_tableau(tableau)
    if fmt == "json":
        emit_json(tableau_json(tab))
    elif fmt == "latex":
        from rkhp.base.latex import standalone

        click.echo(standalone("\\[\n" + tab.to_latex() + "\n\\]", title=_latex_title(tab)))
    else:
        _render(tab)


def tableau_json(tab) -> dict:
    """The JSON document of `rkhp show` (docs/json.md)."""
    import mpmath

    from rkhp.tableaux.tableau import entry_text, to_float

    claims = tab.claims
    with mpmath.workdps(tab.digits or mpmath.mp.dps):  # row sums of given digits: those digits
        c = [entry_text(x) for x in tab.c]
    return {
        "name": tab.name, "aliases": list(tab.aliases), "stages": tab.stages, "kind": tab.kind,
        "source": tab.source, "reference": tab.reference, "notes": tab.notes,
        "claimed": {"order": claims["general"], "degenerate_order": claims["degenerate"],
                    "symmetric_order": claims["symmetric"]},
        "A": [[entry_text(x) for x in row] for row in tab.A], "b": [entry_text(x) for x in tab.b],
        "c": c, "c_given": None if tab.c_given is None else [entry_text(x) for x in tab.c_given],
        "decimals": {"A": [[to_float(x) for x in row] for row in tab.A],
                     "b": [to_float(x) for x in tab.b], "c": [to_float(x) for x in tab.c]},
    }


def _latex_title(tab) -> str:
    from rkhp.base.latex import escape_text

    return escape_text(tab.describe())


def claims_text(tab) -> str:
    """``general 4, degenerate -, symmetric -``."""
    return ", ".join(f"{_CLASS_NAMES[cls]} {'-' if n is None else n}" for cls, n in tab.claims.items())


def _render(tab) -> None:
    from rkhp.tableaux.tableau import entry_decimal, entry_text

    from .terminal import plain

    out = console()
    out.print(f"[bold]{plain(tab.name)}[/bold]: {tab.stages} stages, {tab.kind}")
    for label, value in (("aliases", ", ".join(tab.aliases)), ("source", tab.source),
                         ("reference", tab.reference), ("notes", tab.notes)):
        if value:
            out.print(f"{label}: {plain(value)}")
    out.print(f"claimed orders: {claims_text(tab)} (check them with `rkhp verify`)")
    import mpmath

    given = "exact entries" if tab.is_exact else f"entries as given ({tab.digits}+ digits)"
    with mpmath.workdps(tab.digits or mpmath.mp.dps):  # row sums of given digits: those digits
        print_array(out, tab, entry_text, f"{given}; c = row sums of A")
    if tab.c_mismatch():
        out.print("[yellow]note:[/yellow] the file's c differs from the row sums of A "
                  "(`rkhp verify` lists the stages)")
    print_array(out, tab, lambda x: entry_decimal(x, DECIMAL_DIGITS),
                f"decimals ({DECIMAL_DIGITS} significant digits)")
