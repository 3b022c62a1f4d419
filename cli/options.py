"""Options and helpers shared by the command modules (click; library modules imported lazily)."""

from __future__ import annotations

import click


def format_option(*choices: str, default: str = "table"):
    """The `--format` option every command has."""
    return click.option(
        "--format", "fmt", type=click.Choice(choices), default=default, show_default=True,
        help="Output format: rich table for people, json with stable keys for programs.",
    )


def executor_options(what: str):
    """`--workers N` and `--scheduler ADDRESS`: where the independent tasks of ``what`` run
    (rkhp.executors; docs/distributed.md). The command passes both to rkhp.executors.open_executor."""

    def decorate(f):
        f = click.option("--scheduler", default=None, metavar="ADDRESS",
                         help=f"Run the {what} on the Dask cluster of this scheduler (tcp://host:8786); "
                              "default: $DASK_SCHEDULER_ADDRESS when set and --workers is not given. "
                              "Needs rkhp[distributed].")(f)
        return click.option("--workers", type=int, default=1, show_default=True,
                            help=f"Processes on this machine for the {what}.")(f)

    return decorate


METHOD_HELP = ("A tableau name or file (an RKHP method), thpN or thpN-t0 (Taylor integrator of order N "
               "over T or T_0), classical:NAME (classical Runge-Kutta on xdot = pi grad H), "
               "implicit-midpoint (docs/methods.md).")


def x0_option():
    """The `--x0` option of every command that integrates a system."""
    return click.option("--x0", default=None, metavar="X1,X2,...",
                        help="Initial state, comma-separated (default: the system's).")


def parse_x0(text: str | None):
    """The numbers of an --x0 value (None stays None); InputError for anything else."""
    if text is None:
        return None
    from rkhp.errors import InputError

    try:
        return [float(v) for v in text.split(",")]
    except ValueError:
        raise InputError(f"--x0 must be comma-separated numbers, got {text!r}") from None


def emit_json(obj) -> None:
    """Write a JSON document to stdout (stable key order as given)."""
    import json

    click.echo(json.dumps(obj, indent=2, ensure_ascii=False))


def console():
    """A rich console on stdout (imported lazily)."""
    from rich.console import Console

    return Console(highlight=False)


def progress(enabled: bool):
    """A rich progress bar when stderr is a terminal and `enabled`; else a silent stand-in."""
    import sys

    if enabled and sys.stderr.isatty():
        from rich.console import Console
        from rich.progress import BarColumn, Progress, TextColumn, TimeElapsedColumn

        return Progress(TextColumn("{task.description}"), BarColumn(), TextColumn("{task.completed}/{task.total}"),
                        TimeElapsedColumn(), console=Console(stderr=True), transient=True)
    return _SilentProgress()


class _SilentProgress:
    def __enter__(self):
        return self

    def __exit__(self, *exc):
        return False

    def add_task(self, *args, **kwargs):
        return 0

    def update(self, *args, **kwargs):
        pass

    def advance(self, *args, **kwargs):
        pass
