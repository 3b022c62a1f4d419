"""`rkhp stability`: linear phase, wrap-around, existence barrier and shifted stability interval of
RKHP methods (docs/stability.md, docs/theory.md §13)."""

from __future__ import annotations

import click

from .options import console, emit_json, force_option, format_option, integer, output_path, real, run_provenance

PLOT_FILE = output_path(".png", ".svg", ".pdf")


@click.command()
@click.argument("methods", metavar="METHOD[,METHOD...]")
@click.option("--order", "-n", "order", type=integer(1, 41, name="N"), default=9, show_default=True,
              help="Largest power of z in the series of theta(z) - z.")
@click.option("--realisation", type=click.Choice(["symmetric", "shifted"]), default="symmetric",
              show_default=True,
              help="symmetric: the step is a rotation by theta(z) = 2 arctan(m(z)/2); shifted: "
                   "alpha(x + Q p, p), the trace of the step matrix and the stability interval.")
@click.option("--plot", type=PLOT_FILE, default=None,
              help="Draw theta(z) and |theta(z) - z| of the methods on one figure (.png, .svg, .pdf).")
@click.option("--z-max", type=real(0.0, 100.0, low_open=True, name="Z"), default=4.0, show_default=True,
              help="Largest z = h omega of the plot.")
@force_option()
@format_option("table", "json")
def stability(methods, order, realisation, plot, z_max, force, fmt):
    """Linear stability and phase of RKHP methods (tableau names or files, compositions) on the harmonic oscillator,
    z = h omega: m(z), theta(z) - z as a series, the phase order and constant, the wrap limit, the
    existence barrier of implicit stages, and with --realisation shifted the trace of the step
    matrix and the stability interval (docs/stability.md)."""
    from rkhp.base.errors import InputError
    from rkhp.integrators.methods import check_distinct, resolve_method
    from rkhp.tableaux.stability import analyse, analyse_composition

    names = [m.strip() for m in methods.split(",")]
    if not all(names):
        raise InputError(f"give methods separated by commas, got {methods!r}")
    if len(names) > 12:
        raise InputError(f"at most 12 methods, got {len(names)}")
    resolved = check_distinct([resolve_method(n) for n in names])
    compositions = [m for m in resolved if m.kind == "composition"]
    if compositions and (plot or realisation != "symmetric"):
        raise InputError(f"{compositions[0].name} is a composition: its phase is given on the symmetric "
                         "realisation, without --plot")
    tableaux = [m.rkhp_tableau("rkhp stability") for m in resolved if m.kind != "composition"]
    results = [analyse_composition(m.name, m.tableau, _exact_gammas(m.composition), order, m.composition.digits)
               if m.kind == "composition" else analyse(m.rkhp_tableau("rkhp stability"), order, realisation)
               for m in resolved]
    if plot:
        from rkhp.studies.plots import plot_phase

        plot_phase(tableaux, realisation, z_max, plot, run_provenance(), force)
    doc = stability_json(results, order, realisation)
    if fmt == "json":
        emit_json(doc)
    else:
        _render(doc, plot)


def _exact_gammas(composition) -> list:
    """A composition's coefficients as exact sympy numbers (decimals by their digits)."""
    import sympy

    from rkhp.tableaux.tableau import GivenDecimal, as_sympy

    return [sympy.Rational(g.text) if isinstance(g, GivenDecimal) else as_sympy(g) for g in composition.gamma]


def stability_json(results, order: int, realisation: str) -> dict:
    """The JSON document of `rkhp stability` (docs/json.md, "rkhp stability")."""
    def number(x):
        return None if x is None else x.json()

    out = []
    for r in results:
        ph = r.phase
        out.append({
            "method": r.name, "kind": r.kind, "realisation": r.realisation,
            "m": r.m, "m_degree": r.m_degree,
            "stage_equations": None if r.stage_equations is None else list(r.stage_equations),
            "trace": r.trace,
            "theta_series": {"text": ph.series_text(), "order": ph.order,
                             "coefficients": [{"power": k, **c.json()} for k, c in ph.coefficients]},
            "phase_order": ph.phase_order,
            "phase_constant": number(ph.phase_constant),
            "wrap_limit": number(r.wrap_limit),
            "existence_limit": number(r.existence_limit),
            "stability_interval": number(r.stability_interval),
        })
    return {"realisation": realisation, "order": order, "methods": out}


def _value(x) -> str:
    if x is None:
        return "—"
    if x["float"] is None:
        return "unbounded"
    exact = x["exact"]
    if exact is None:
        return f"{x['float']:.15g}"
    if len(exact) > 40:
        return f"{x['float']:.15g} (exact: an algebraic number, see --format json)"
    return exact if exact.lstrip("-").isdigit() else f"{exact} = {x['float']:.15g}"


def _render(doc, plot) -> None:
    out = console()
    real = doc["realisation"]
    for r in doc["methods"]:
        out.print(f"{r['method']} ({r['kind']}, {real} realisation), z = h omega", markup=False)
        rows = []
        if r["m"] is not None:
            rows.append(("m(z)", r["m"]))
        for eq in r["stage_equations"] or ():
            rows.append(("stage equation", eq))
        if r["trace"] is not None:
            text = r["trace"]
            rows.append(("tr R(z)", text if len(text) <= 160 else text[:157] + "..."))
        series = r["theta_series"]["text"]
        if series is None:
            series = " + ".join(f"{c['float']:.6g} z^{c['power']}" for c in r["theta_series"]["coefficients"]
                                if c["float"]) or "0"
        rows.append((f"theta(z) - z to z^{doc['order']}", series))
        rows.append(("phase order", "—" if r["phase_order"] is None else str(r["phase_order"])))
        rows.append(("phase constant", _value(r["phase_constant"])))
        if r["kind"] == "composition":
            rows.append(("wrap limit", "— (the substeps turn back and forth)"))
        elif real == "symmetric":
            none = "none: theta increases with z" if r["m"] is not None or r["kind"] != "explicit" \
                else "none: theta increases on (0, 20]"
            rows.append(("wrap limit", none if r["wrap_limit"] is None else _value(r["wrap_limit"])))
        if r["kind"] == "implicit":
            rows.append(("existence limit z*", "none below z = 64" if r["existence_limit"] is None
                         else _value(r["existence_limit"])))
        if real == "shifted":
            rows.append(("stability interval", _value(r["stability_interval"])))
        width = max(len(k) for k, _ in rows)
        for k, v in rows:
            out.print(f"  {k.ljust(width)}  {v}", markup=False, soft_wrap=True)
    if plot:
        out.print(f"plot written to {plot}", markup=False)
