"""`rkhp compile`: the integrator kernels of every built-in family compiled ahead, into numba's cache."""

from __future__ import annotations

from pathlib import Path

import click

from rkhp.base import bounds

from .options import console, emit_json, format_option, integer, progress
from .render import compact_table, print_table


@click.command("compile")
@click.option("--jobs", type=integer(1, bounds.MAX_WORKERS, name="N"), default=None,
              help="Processes compiling side by side (default: the cores this process may use).")
@click.option("--prune", is_flag=True,
              help="First remove the cache folders of other versions of rkhp or numba (docs/engine.md).")
@format_option("table", "json")
def compile_(jobs, prune, fmt):
    """Compile the integrator kernels of every built-in family now, into the cache (docs/engine.md)."""
    from rkhp.integrators.ahead import compile_ahead
    from rkhp.taylor import compiler

    pruned = _prune() if prune else None
    with progress(fmt != "json") as bar:
        task = bar.add_task("compiling the integrator kernels", total=None)
        run = compile_ahead(jobs,
                            on_part=lambda done, total: bar.update(task, completed=done, total=total))
    report = {"cache_dir": str(compiler.RKHP_CACHE_DIR or compiler.numba.config.CACHE_DIR), "jobs": run.jobs,
              "classes": [item._asdict() for item in run.classes],
              "seconds": run.seconds, "cpu_seconds": sum(item.cpu_seconds for item in run.classes),
              "pruned": None if pruned is None else pruned._asdict()}
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
    if pruned is not None:
        click.echo(_pruned_line(pruned))


def _prune():
    """The other versions' cache folders removed (`rkhp.taylor.compiler.prune_other_versions`);
    bad input when the cache is the user's NUMBA_CACHE_DIR, whose folders rkhp does not name, or
    when a folder cannot be removed."""
    from rkhp.base.errors import InputError
    from rkhp.taylor import compiler

    if compiler.RKHP_CACHE_DIR is None:
        raise InputError("--prune removes rkhp's own cache folders, but numba's cache is NUMBA_CACHE_DIR "
                         f"({compiler.numba.config.CACHE_DIR}): remove what you no longer need there yourself")
    try:
        return compiler.prune_other_versions(Path(compiler.RKHP_CACHE_DIR))
    except OSError as exc:
        raise InputError(exc.strerror) from None


def _pruned_line(pruned) -> str:
    """What --prune removed, in one line."""
    if not pruned.folders:
        return "No cache folders of other versions to remove."
    count = len(pruned.folders)
    return f"Removed {count} cache folder{'s' if count > 1 else ''} of other versions ({pruned.bytes / 1e6:.1f} MB)."
