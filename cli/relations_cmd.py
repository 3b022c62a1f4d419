"""`rkhp relations`: linear relations among elementary differentials of symmetric birealisations
and the symmetric order conditions they leave (docs/theory.md §8)."""

from __future__ import annotations

import click

from .options import (
    SEED,
    console,
    emit_json,
    executor_options,
    force_option,
    format_option,
    integer,
    json_text,
    output_path,
    progress,
    with_provenance,
)


@click.command()
@click.option("--order", "-n", "order", type=integer(1, name="N"), required=True,
              help="Largest order N (shipped up to 8; up to 9 with --regenerate).")
@click.option("--regenerate", is_flag=True,
              help="Derive the relations from scratch (exact arithmetic modulo primes) instead of reading "
                   "the shipped data.")
@click.option("--seed", type=SEED, default=0, show_default=True, help="Seed of the random instances (--regenerate).")
@click.option("--output", type=output_path(".json"),
              help="Write the relations document (the shipped format) to this JSON file.")
@force_option()
@executor_options("evaluations of --regenerate (one task per prime)")
@format_option("table", "json")
def relations(order, regenerate, seed, output, force, workers, scheduler, fmt):
    """Relations among F(t), t in T_0, valid for every symmetric birealisation, per order.

    For each order: the number of T_0 trees, of relations and of symmetric order conditions, the
    relations (sum c_t F(t) = 0) and the conditions (sum w_t r(t) = 0, r(t) = gamma(t) a(t) - 1).
    """
    from rkhp.base.executors import open_executor
    from rkhp.series.relation_derivation import relations_for

    if output and not regenerate:
        raise click.UsageError("--output writes freshly derived relations: add --regenerate")
    if (scheduler or workers != 1) and not regenerate:
        raise click.UsageError("--workers and --scheduler run the derivation: add --regenerate")
    with open_executor(workers, scheduler) as executor, progress(fmt != "json") as bar:
        task = bar.add_task("deriving relations", total=None)
        data = relations_for(order, regenerate=regenerate, seed=seed, executor=executor,
                             progress=(lambda step: bar.update(task, description=step)) if regenerate else None)
    from rkhp.base.json_form import json_form

    document = json_form(data)
    source = "regenerated" if regenerate else "shipped"
    if output:
        from rkhp.base.provenance import write_output

        document["method"]["regenerate"] += f" --output {output}"
        write_output(output, json_text(with_provenance(document), indent=1) + "\n", "--output", force)
    if fmt == "json":
        emit_json({**document, "source": source})
        return
    _render(data, source)


def _render(data, source: str) -> None:
    from rich.table import Table

    from rkhp.trees.relations import condition_text, relation_text

    out = console()
    summary = Table(title="Symmetric birealisations: relations among F(t)", caption=f"{source} data")
    for col in ("Order", "T_0 trees", "Relations", "Symmetric conditions"):
        summary.add_column(col, justify="right")
    for o in data.orders:
        summary.add_row(str(o.order), str(len(o.trees)), str(len(o.relations)), str(len(o.conditions)))
    out.print(summary)
    for o in data.orders:
        if not o.trees:
            continue
        out.print(f"\n[bold]Order {o.order}[/bold]")
        for k in range(len(o.relations)):
            out.print(f"  relation   {relation_text(o, k)}", markup=False)
        for trees, weights in o.conditions:
            out.print(f"  condition  {condition_text(trees, weights)}", markup=False)
    out.print("\nr(t) = gamma(t) a(t) - 1 over T_0; a relation is sum c_t F(t) = 0.", markup=False)
