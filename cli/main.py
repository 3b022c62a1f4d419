"""Root command group. Subcommands are imported only when they run, so `rkhp --help` and light
commands pay nothing for numba, sympy or scipy.

Every command module registers here with one line: name -> (module, function, one-line help).
"""

from __future__ import annotations

import gc
import importlib
import sys
from typing import NamedTuple

import click

COMMANDS: dict[str, tuple[str, str, str]] = {
    "trees": ("rkhp_cli.trees_cmd", "trees", "Enumerate Butcher trees of T or T_0."),
    "conditions": ("rkhp_cli.trees_cmd", "conditions", "Print the order conditions (Butcher form, LaTeX)."),
    "verify": ("rkhp_cli.verify_cmd", "verify", "Verify a tableau's orders (exact, or a stated tolerance)."),
    "tables": ("rkhp_cli.verify_cmd", "tables", "List the built-in tableaux with their verified orders."),
    "show": ("rkhp_cli.show_cmd", "show", "Show a tableau's Butcher array, source and claims."),
    "search": ("rkhp_cli.search_cmd", "search", "Search minimal-stage tableaux; polish, recognise, prove."),
    "systems": ("rkhp_cli.systems_cmd", "systems", "List the built-in Poisson systems."),
    "check": ("rkhp_cli.systems_cmd", "check", "Check a system's birealisation axioms (AD)."),
    "integrate": ("rkhp_cli.systems_cmd", "integrate", "Integrate a Poisson system with a method (docs/methods.md)."),
    "poincare": ("rkhp_cli.poincare_cmd", "poincare", "Poincare section of an orbit: points, CSV, plot."),
    "compose": ("rkhp_cli.compose_cmd", "compose", "Composition of RKHP steps against the Butcher product."),
    "modified": ("rkhp_cli.modified_cmd", "modified", "Modified Hamiltonian of a method (backward error analysis)."),
    "stability": ("rkhp_cli.stability_cmd", "stability", "Linear phase and stability of RKHP methods."),
    "relations": ("rkhp_cli.relations_cmd", "relations", "Relations of symmetric birealisations (docs/theory.md §8)."),
    "converge": ("rkhp_cli.studies_cmd", "converge", "Convergence study: error against h, observed orders."),
    "bench": ("rkhp_cli.studies_cmd", "bench", "Work-precision: wall time against error, with scipy peers."),
    "long-time": ("rkhp_cli.studies_cmd", "long_time", "Long-time energy error growth, fitted as C t^k."),
    "stress": ("rkhp_cli.studies_cmd", "stress", "Stress tests: Newton failure, long-run drift, round-off."),
    "compile": ("rkhp_cli.compile_cmd", "compile_", "Compile the integrator kernels of every built-in family ahead."),
}


class _Interrupt(BaseException):
    """Ctrl-C on its way out of click, which would print an empty line on stderr for a
    KeyboardInterrupt before its Abort."""


class LazyGroup(click.Group):
    """A group whose subcommands are imported on first use, and whose errors are one line."""

    def make_context(self, *args, **kwargs):
        try:
            return super().make_context(*args, **kwargs)
        except KeyboardInterrupt:
            raise _Interrupt from None

    def invoke(self, ctx):
        try:
            return super().invoke(ctx)
        except KeyboardInterrupt:
            raise _Interrupt from None
        except EOFError as exc:  # click would report it as an interrupt (Abort): it is an error
            raise RuntimeError(f"unexpected end of input ({exc})") from exc

    def list_commands(self, ctx):
        return list(COMMANDS)

    def get_command(self, ctx, name):
        if name not in COMMANDS:
            return None
        module, attr, _ = COMMANDS[name]
        return getattr(importlib.import_module(module), attr)

    def format_commands(self, ctx, formatter):
        rows = [(name, help_) for name, (_, _, help_) in COMMANDS.items()]
        with formatter.section("Commands"):
            formatter.write_dl(rows)

    def main(self, *args, **kwargs):
        from rkhp.base.errors import CheckFailed, ClusterLost, InputError, NumericalFailure, WriteFailed

        from .terminal import install_interrupt_handler, install_warning_line, quiet_floating_point_warnings

        install_interrupt_handler()
        install_warning_line()
        quiet_floating_point_warnings()
        kwargs["standalone_mode"] = False
        given = args[0] if args else kwargs.get("args")
        kwargs.setdefault("obj", Invocation(tuple(sys.argv[1:] if given is None else given)))
        try:
            rv = super().main(*args, **kwargs)
            sys.stdout.flush()
        except click.exceptions.Exit as exc:
            _exit(exc.exit_code)
        except click.exceptions.NoArgsIsHelpError as exc:  # bare `rkhp`: the help, on stdout
            click.echo(exc.ctx.get_help())
            _exit(0)
        except (click.exceptions.Abort, _Interrupt):
            _interrupted()
        except click.UsageError as exc:
            _fail(f"rkhp: error: {one_line(exc.format_message())}", 2)
        except click.ClickException as exc:
            _fail(f"rkhp: error: {one_line(exc.format_message())}", exc.exit_code if exc.exit_code else 1)
        except InputError as exc:
            _fail(f"rkhp: error: {one_line(str(exc))}", 2)
        except NumericalFailure as exc:
            _fail(f"rkhp: numerical failure: {one_line(str(exc))}", 1)
        except CheckFailed as exc:
            _fail(f"rkhp: check failed: {one_line(str(exc))}", 1)
        except (WriteFailed, ClusterLost) as exc:
            _fail(f"rkhp: error: {one_line(str(exc))}", 1)
        except MemoryError as exc:  # numpy's _ArrayMemoryError included
            _fail(f"rkhp: error: {out_of_memory(exc)}", 1)
        except BrokenPipeError:  # the reader went away (`rkhp ... | head`): nothing more to say
            from .terminal import silence_stdout

            silence_stdout()
            _exit(0)
        except BaseException as exc:
            from rkhp.base.interrupts import is_interrupt

            if is_interrupt(exc):
                _interrupted()
            if isinstance(exc, OSError) and _is_stdout_error(exc):
                from .terminal import silence_stdout

                silence_stdout()
                _fail(f"rkhp: error: cannot write the output: {exc.strerror or exc}", 1)
            if is_out_of_memory(exc):
                _fail(f"rkhp: error: {out_of_memory(exc)}", 1)
            raise
        _exit(rv if isinstance(rv, int) else 0)


def _exit(status: int):
    """Exit with `status`, stdout flushed first (a failed flush: one line, status 1; after an
    interrupt, whose line is said, the interrupt's status: a hung-up terminal takes both)."""
    from rkhp.base import interrupts

    try:
        sys.stdout.flush()
    except KeyboardInterrupt:
        _interrupted()
    except BrokenPipeError:
        from .terminal import silence_stdout

        silence_stdout()
    except OSError as exc:
        from .terminal import silence_stdout

        silence_stdout()
        if not interrupts.requested():
            _fail(f"rkhp: error: cannot write the output: {exc.strerror or exc}", 1)
    sys.exit(status)


def _fail(line: str, status: int):
    """One line on stderr (control characters escaped), then exit with `status`, whether or not
    stderr can be written."""
    from .terminal import printable

    _say(printable(line))
    try:
        sys.stdout.flush()
    except OSError:
        from .terminal import silence_stdout

        silence_stdout()
    sys.exit(status)


def _say(line: str) -> None:
    """``line`` on stderr; a stderr that cannot be written (full, closed) loses it."""
    try:
        sys.stderr.write(line + "\n")
        sys.stderr.flush()
    except (OSError, ValueError, AttributeError):
        pass


def _interrupted():
    """The one line and status of an interrupt (docs/exit-status.md)."""
    from .terminal import interrupt_status, interrupted_line, silence_stdout

    try:
        sys.stdout.flush()
    except (OSError, ValueError, KeyboardInterrupt):
        silence_stdout()
    _say(interrupted_line())
    sys.exit(interrupt_status())


def _is_stdout_error(exc: OSError) -> bool:
    """Whether writing stdout raised `exc` (a full or failing device, a closed stdout): the errors
    of a write, on no named file. Errors of numba's cache, under the cache folder, are warnings
    (rkhp.taylor.kernel_cache) and do not reach here."""
    import errno

    return (exc.errno in (errno.ENOSPC, errno.EIO, errno.EDQUOT, errno.EFBIG, errno.EPIPE, errno.EBADF)
            and exc.filename is None)


#: how the dynamic loader says that it could not map a shared library (llvmlite's, loaded by numba
#: at its import), which under a memory limit means that the memory ran out
_NOT_MAPPED = ("failed to map segment from shared object", "cannot allocate memory")


def _memory_cause(exc: BaseException) -> BaseException | None:
    """The exception in ``exc``'s chain of causes and contexts that says the memory ran out: a
    MemoryError (numpy's included), an OSError of ENOMEM or a shared library not mapped."""
    import errno

    seen = set()
    while exc is not None and id(exc) not in seen:
        if isinstance(exc, MemoryError) or (isinstance(exc, OSError) and exc.errno == errno.ENOMEM):
            return exc
        if isinstance(exc, OSError) and any(text in str(exc).lower() for text in _NOT_MAPPED):
            return exc
        seen.add(id(exc))
        exc = exc.__cause__ or exc.__context__
    return None


def is_out_of_memory(exc: BaseException) -> bool:
    """Whether ``exc`` says that the memory ran out (`_memory_cause`)."""
    return _memory_cause(exc) is not None


def out_of_memory(exc: BaseException) -> str:
    """The line of a run that ran out of memory, with numpy's account of the allocation, or the
    loader's of a library, when there is one."""
    cause = _memory_cause(exc) or exc
    detail = one_line(str(cause))
    if isinstance(cause, OSError) and "shared object" in detail:
        detail = f"a shared library could not be loaded: {detail.rsplit(': ', 1)[-1]}"
    return ("out of memory" + (f": {detail}" if detail else "") +
            " (the process's memory limit, `ulimit -v`, or the machine's; docs/input.md#memory)")


class Invocation(NamedTuple):
    """What the root command was given (the context's ``obj``): the arguments after ``rkhp``,
    recorded in the provenance of every output (rkhp.base.provenance)."""

    args: tuple[str, ...]


def one_line(message: str) -> str:
    """Collapse a message to a single line."""
    return " ".join(message.split())


@click.group(cls=LazyGroup, context_settings={"help_option_names": ["-h", "--help"]})
@click.version_option(package_name="rkhp", message="rkhp %(version)s")
def rkhp():
    """rkhp: Runge–Kutta–Hamiltonian–Poisson integrators (Busnot Laurent & Cosserat).

    Trees and order conditions over T (general birealisations) and T_0 (degenerate ones),
    exact order verification, tableau search, and RKHP integrators on Poisson systems.
    """


#: the garbage collector's thresholds in an `rkhp` process (Python's are 700, 10, 10): a command
#: imports and keeps hundreds of thousands of objects (numba, sympy, scipy), and at Python's
#: young-generation threshold the collector runs hundreds of times in one command, its fuller
#: collections scanning them again each time
GC_THRESHOLDS = (50_000, 20, 10)


def main() -> None:
    """The `rkhp` command: closed standard streams given stand-ins and stderr made forgiving
    (`rkhp_cli.terminal`), the collector's thresholds (`GC_THRESHOLDS`), the group, then no
    interrupt past the chosen exit status."""
    from .terminal import forgiving_stderr, ignore_late_interrupts, open_standard_streams

    open_standard_streams()
    forgiving_stderr()
    gc.set_threshold(*GC_THRESHOLDS)
    try:
        rkhp.main(prog_name="rkhp")
    except KeyboardInterrupt:
        _interrupted()
    finally:
        ignore_late_interrupts()
