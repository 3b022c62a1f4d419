"""`rkhp compile`: the integrator kernels of every built-in family compiled ahead, into numba's cache."""

from __future__ import annotations

import click

from rkhp.base import bounds

from .options import console, emit_json, format_option, integer, progress
from .render import compact_table, print_table


@click.command("compile")
@click.option("--jobs", type=integer(1, bounds.MAX_WORKERS, name="N"), default=None,
              help="Processes compiling side by side (default: the cores this process may use).")
@format_option("table", "json")
def compile_(jobs, fmt):
    """Compile the integrator kernels of every built-in family now, into the cache (docs/engine.md)."""
    from rkhp.integrators.ahead import compile_ahead
    from rkhp.taylor.compiler import numba

    with progress(fmt != "json") as bar:
        task = bar.add_task("compiling the integrator kernels", total=None)
        run = compile_ahead(jobs,
                            on_part=lambda done, total: bar.update(task, completed=done, total=total))
    report = {"cache_dir": str(numba.config.CACHE_DIR), "jobs": run.jobs,
              "classes": [item._asdict() for item in run.classes],
              "seconds": run.seconds, "cpu_seconds": sum(item.cpu_seconds for item in run.classes)}
    if fmt == "json":
        emit_json(report)
        return
    title = f"Integrator kernels in numba's cache ({report['cache_dir']}), {run.jobs} process" + \
        ("es" if run.jobs > 1 else "") + f", {run.seconds:.1f} s"
    table = compact_table(title)
    for col in ("tape class", "systems", "compiled now", "seconds", "CPU seconds"):
        table.add_column(col)
    for item in run.classes:
        compiled = ", ".join(k.rsplit(".", 1)[1] for k in item.compiled) or "- (cached)"
        table.add_row(item.tape_class, ", ".join(item.systems), compiled, f"{item.seconds:.1f}",
                      f"{item.cpu_seconds:.1f}")
    print_table(console(), table)
