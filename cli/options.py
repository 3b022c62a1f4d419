"""Options and helpers shared by the command modules (click, and the light `rkhp.base.bounds`; other
library modules are imported lazily).

The option types below check every value when the command line is parsed, before any work or
heavy import (docs/input.md): a value outside its bounds is a usage error, one line and exit
status 2.
"""

from __future__ import annotations

import math

import click

from rkhp.base import bounds
from rkhp.base.errors import InputError


class Checked(click.ParamType):
    """A click type whose text is read and checked by `read(text, label)` (InputError -> usage error)."""

    def __init__(self, name: str, read, label: str | None = None):
        self.name = name
        self.read = read
        self.label = label

    def convert(self, value, param, ctx):
        if not isinstance(value, str):
            return value  # a default already of the right type
        label = self.label or ((param.opts[0] if param.opts else param.name) if param is not None else self.name)
        try:
            return self.read(value, label)
        except InputError as exc:  # the message names the option already
            raise click.UsageError(str(exc), ctx) from None


def integer(low: int | None = 1, high: int | None = None, name: str = "integer") -> Checked:
    """An integer low..high (at most 30 digits are ever parsed)."""
    return Checked(name, lambda text, label: bounds.integer(bounds.parse_int(text, label), label, low, high))


def real(low: float | None = None, high: float | None = None, *, low_open: bool = False,
         high_open: bool = False, name: str = "number", label: str | None = None) -> Checked:
    """A finite float (nan and inf refused) within the bounds (`label` names it in messages)."""
    return Checked(name, lambda text, label: bounds.number(bounds.parse_float(text, label), label, low, high,
                                                           low_open=low_open, high_open=high_open), label)


def integers(low: int = 1, high: int | None = None, name: str = "N1,N2,...") -> Checked:
    """A comma-separated list of integers low..high, none repeated."""
    def read(text, label):
        form = f"{label} (comma-separated integers)"
        values = bounds.parse_list(text, form, lambda t: bounds.integer(bounds.parse_int(t, form), label, low, high))
        if len(set(values)) != len(values):
            raise InputError(f"{label}: a value is repeated in {text}")
        return values

    return Checked(name, read)


def reals(check, name: str = "X1,X2,...", distinct: bool = True) -> Checked:
    """A comma-separated list of finite numbers, each checked by `check(value, label)` (none repeated
    when `distinct`)."""
    def read(text, label):
        form = f"{label} (comma-separated numbers)"
        values = bounds.parse_list(text, form, lambda t: check(bounds.parse_float(t, form), label))
        if distinct and len(set(values)) != len(values):
            raise InputError(f"{label}: a value is repeated in {text}")
        return values

    return Checked(name, read)


def names(name: str = "NAME,...") -> Checked:
    """A comma-separated list of names, none empty, none repeated (case-insensitive); empty text:
    none."""
    def read(text, label):
        if not text.strip():
            return ()
        values = tuple(t.strip() for t in text.split(","))
        if not all(values):
            raise InputError(f"{label}: an empty name in {bounds.shown(text)}")
        folded = [v.lower() for v in values]
        if len(set(folded)) != len(folded):
            twice = next(v for v in values if folded.count(v.lower()) > 1)
            raise InputError(f"{label}: {twice} is named twice")
        return values

    return Checked(name, read)


class OutputPath(Checked):
    """A file to write, checked before the work by ``check(text, label, force)`` (default:
    `rkhp.base.bounds.check_output_path` for ``suffixes``, then `rkhp.base.files.check_target`: an
    existing file or a symbolic link only with the command's `--force`, an eager option, so
    already read); returns the text."""

    def __init__(self, suffixes: tuple[str, ...] = (), check=None):
        super().__init__("FILE", lambda text, label: text)
        self.check = check or (lambda text, label, force: _checked_target(text, suffixes, label, force))

    def convert(self, value, param, ctx):
        if not isinstance(value, str):
            return value
        force = bool(ctx is not None and ctx.params.get("force"))
        label = (param.opts[0] if param is not None and param.opts else "output file")
        try:
            return str(self.check(value, label, force))
        except InputError as exc:
            raise click.UsageError(str(exc), ctx) from None


def _checked_target(text, suffixes, label, force):
    from rkhp.base.files import check_target

    return check_target(bounds.check_output_path(text, suffixes, label), label, force)


def output_path(*suffixes: str, check=None) -> Checked:
    """A file to write (:class:`OutputPath`)."""
    return OutputPath(suffixes, check)


def force_option():
    """`--force`: replace an existing output file (read before the other options: eager)."""
    return click.option("--force", is_flag=True, is_eager=True,
                        help="Replace an existing output file (or a symbolic link, itself; docs/input.md).")


#: a seed: 0 .. 2^64 - 1
SEED = integer(0, bounds.MAX_SEED, "seed")
#: a positive finite time or step
POSITIVE = real(0.0, low_open=True, name="positive number")
#: the final time T
T_FINAL = real(0.0, low_open=True, name="T", label="--t-final (final time T)")
#: a signed step or final time of one run (negative: backwards; zero is refused by the step plan)
SIGNED = real(name="number")
#: the number of steps of one run
STEPS = integer(1, bounds.MAX_STEPS, "steps")
#: an initial state: finite numbers
X0 = reals(lambda x, label: x, "X1,X2,...", distinct=False)




FORMAT_HELP = {"table": "rich table for people", "json": "json with stable keys for programs",
               "latex": "LaTeX", "markdown": "markdown",
               "csv": "csv for spreadsheets and data frames (docs/results.md)"}


def condition_class_of(degenerate: bool, symmetric: bool = False) -> str:
    """The condition class that the --degenerate and --symmetric flags choose (general without either)."""
    if degenerate and symmetric:
        raise click.UsageError("--symmetric and --degenerate are exclusive: choose one condition class")
    return "symmetric" if symmetric else "degenerate" if degenerate else "general"


def format_option(*choices: str, default: str = "table"):
    """The `--format` option every command has."""
    return click.option(
        "--format", "fmt", type=click.Choice(choices), default=default, show_default=True,
        help="Output format: " + ", ".join(FORMAT_HELP.get(c, c) for c in choices) + ".",
    )


def emit_table(fmt: str, header, rows, latex_tables) -> None:
    """Write a study's table to stdout as CSV (``header`` and ``rows`` of values) or LaTeX (the
    booktabs ``latex_tables``, cells as the terminal shows them), each after the provenance line
    of the running command (rkhp.base.tables; docs/results.md)."""
    from rkhp.base.tables import csv_text, latex_text

    record = run_provenance()
    if fmt == "csv":
        click.echo(csv_text(header, rows, record), nl=False)
    else:
        click.echo(latex_text(latex_tables, record), nl=False)


def executor_options(what: str):
    """`--workers N` and `--scheduler ADDRESS`: where the independent tasks of ``what`` run
    (rkhp.base.executors; docs/distributed.md). The command passes both to rkhp.base.executors.open_executor."""

    def decorate(f):
        f = click.option("--scheduler", default=None, metavar="ADDRESS",
                         help=f"Run the {what} on the Dask cluster of this scheduler (tcp://host:8786); "
                              "default: $DASK_SCHEDULER_ADDRESS when set and --workers is not given. "
                              "Needs rkhp[distributed].")(f)
        return click.option("--workers", type=integer(1, name="N"), default=1, show_default=True,
                            help=f"Processes on this machine for the {what}.")(f)

    return decorate


METHOD_HELP = ("A tableau name or file (an RKHP method), thpN or thpN-t0 (Taylor integrator of order N "
               "over T or T_0), classical:NAME (classical Runge-Kutta on xdot = pi grad H), "
               "implicit-midpoint (docs/methods.md).")


def x0_option():
    """The `--x0` option of every command that integrates a system (finite numbers, read when the
    command line is parsed)."""
    return click.option("--x0", type=X0, default=None, metavar="X1,X2,...",
                        help="Initial state, comma-separated (default: the system's).")


def parse_x0(value):
    """The numbers of an --x0 value (None stays None; text is read as the option reads it)."""
    if value is None:
        return None
    if isinstance(value, str):
        value = X0.read(value, "--x0")
    return list(value)


#: how a non-finite float is written in JSON output (docs/input.md "JSON output"): a string
#: that float() reads back, so that the document stays valid JSON
NON_FINITE = {"nan": "NaN", "inf": "Infinity", "-inf": "-Infinity"}


def json_ready(obj):
    """A copy of `obj` with every non-finite float (numpy's too) replaced by its NON_FINITE string,
    tuples as lists and numpy scalars and arrays as Python values (iteratively: deep data is fine)."""
    def leaf(v):
        if hasattr(v, "tolist") and not isinstance(v, list | tuple | dict):
            v = v.tolist()  # numpy scalars and arrays
        if isinstance(v, float) and not math.isfinite(v):
            return NON_FINITE[repr(v)]
        if isinstance(v, dict):
            return dict(v)
        return list(v) if isinstance(v, list | tuple) else v

    root = [obj]
    stack = [root]
    while stack:
        node = stack.pop()
        for k in list(node) if isinstance(node, dict) else range(len(node)):
            node[k] = v = leaf(node[k])
            if isinstance(v, list | dict):
                stack.append(v)
    return root[0]


def json_text(obj, indent: int = 2) -> str:
    """A JSON document: valid JSON always (allow_nan=False after :func:`json_ready`)."""
    import json

    return json.dumps(json_ready(obj), indent=indent, ensure_ascii=False, allow_nan=False)


def run_provenance() -> dict:
    """The provenance record of the running command (rkhp.base.provenance): its command line as
    given to ``rkhp``, and the value of its --seed option when it has one."""
    import shlex

    from rkhp.base.provenance import provenance

    ctx = click.get_current_context(silent=True)
    if ctx is None:
        return provenance()
    given = getattr(ctx.find_root().obj, "args", None)
    command = None if given is None else shlex.join(["rkhp", *given])
    seed = ctx.params.get("seed") if isinstance(ctx.params.get("seed"), int) else None
    return provenance(command, seed)


def with_provenance(document: dict) -> dict:
    """The document with the running command's ``provenance`` object as its last key."""
    return {**document, "provenance": run_provenance()}


def emit_json(document) -> None:
    """Write a JSON document to stdout: a result or a dict of results in its JSON form
    (`rkhp.base.json_form`; stable key order as given), then ``provenance``; non-finite values as
    NON_FINITE."""
    from rkhp.base.json_form import json_form

    click.echo(json_text(with_provenance(json_form(document))))


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


COMPILE_NOTICE = "compiling the integrator kernels once for this machine, ~{seconds:.0f} s"


def compile_notice(kinds, enabled: bool, system=None) -> None:
    """One line on stderr before a run whose compiled kernels are not in numba's cache yet
    (rkhp.integrators.kernels; for `system`'s class of tapes when given), under the rules of
    :func:`progress`: only when `enabled` (not JSON mode) and stderr is a terminal."""
    import sys

    if not (enabled and sys.stderr.isatty()):
        return
    from rkhp.integrators.kernels import cold_start

    cold = cold_start(kinds, None if system is None else type(system.h_tape))
    if cold:
        click.echo(COMPILE_NOTICE.format(seconds=cold.seconds), err=True)


def cost_notice(methods, system, steps: int) -> None:
    """One line on stderr, before the work, per method whose estimated cost on `system` for
    `steps` steps (`Method.cost`: the Taylor tower's jets) exceeds COST_NOTICE_SECONDS."""
    from rkhp.base.bounds import MAX_WORK_STEPS
    from rkhp.integrators.methods import COST_NOTICE_SECONDS
    from rkhp.integrators.tower_substep import MAX_PRODUCT_PAIRS

    if steps > MAX_WORK_STEPS:  # refused with its own message
        return
    for method in methods:
        cost = method.cost(system)
        if cost is None or cost.pairs > MAX_PRODUCT_PAIRS or cost.seconds(steps) <= COST_NOTICE_SECONDS:
            continue
        click.echo(f"rkhp: note: {method.name} on {system.name} runs on Taylor polynomials of degree "
                   f"{cost.degree} in {system.dim} variables ({cost.pairs} product terms): about "
                   f"{cost.seconds(steps):.2g} s of CPU for {steps} steps (a composition of RKHP Euler "
                   "grows linearly with the dimension: docs/methods.md)", err=True)


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


def realisation_option():
    return click.option("--realisation", default="symmetric", show_default=True,
                        help="Birealisation: symmetric (degenerate), shifted (x + Q p; general), "
                             "quartic (x + grad K(p); degenerate, not symmetric), truncated:K (the "
                             "spray series to degree K in p, K = 1..12; symmetric).")
