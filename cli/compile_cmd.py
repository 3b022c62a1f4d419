"""`rkhp compile`: the integrator kernels of every built-in family compiled ahead, into numba's cache."""

from __future__ import annotations

import click

from .options import console, emit_json, format_option, progress
from .render import compact_table, print_table


@click.command("compile")
@format_option("table", "json")
def compile_(fmt):
    """Compile the integrator kernels of every built-in family now, into the cache (docs/engine.md)."""
    from rkhp.integrators.ahead import compile_ahead, tape_classes
    from rkhp.taylor.compiler import numba

    with progress(fmt != "json") as bar:
        task = bar.add_task("compiling the integrator kernels", total=len(tape_classes()))
        done = compile_ahead(on_class=lambda item: bar.update(task, advance=1))
    report = {"cache_dir": str(numba.config.CACHE_DIR),
              "classes": [item._asdict() for item in done],
              "seconds": sum(item.seconds for item in done), "cpu_seconds": sum(item.cpu_seconds for item in done)}
    if fmt == "json":
        emit_json(report)
        return
    table = compact_table(f"Integrator kernels in numba's cache ({report['cache_dir']})")
    for col in ("tape class", "systems", "compiled now", "seconds", "CPU seconds"):
        table.add_column(col)
    for item in done:
        compiled = ", ".join(k.rsplit(".", 1)[1] for k in item.compiled) or "- (cached)"
        table.add_row(item.tape_class, ", ".join(item.systems), compiled, f"{item.seconds:.1f}",
                      f"{item.cpu_seconds:.1f}")
    print_table(console(), table)
