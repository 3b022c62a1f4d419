"""Root command group. Subcommands are imported only when they run, so `rkhp --help` and light
commands pay nothing for numba, sympy or scipy.

Every command module registers here with one line: name -> (module, function, one-line help).
"""

from __future__ import annotations

import importlib
import sys

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
    "compose": ("rkhp_cli.compose_cmd", "compose", "Composition of RKHP steps against the Butcher product."),
    "modified": ("rkhp_cli.modified_cmd", "modified", "Modified Hamiltonian of a method (backward error analysis)."),
    "relations": ("rkhp_cli.relations_cmd", "relations", "Relations of symmetric birealisations (docs/theory.md §8)."),
    "converge": ("rkhp_cli.studies_cmd", "converge", "Convergence study: error against h, observed orders."),
    "bench": ("rkhp_cli.studies_cmd", "bench", "Work-precision: wall time against error, with scipy peers."),
    "stress": ("rkhp_cli.studies_cmd", "stress", "Stress tests: Newton failure, long-run drift, round-off."),
    "compile": ("rkhp_cli.compile_cmd", "compile_", "Compile the integrator kernels of every built-in family ahead."),
}


class LazyGroup(click.Group):
    """A group whose subcommands are imported on first use, and whose errors are one line."""

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
        from rkhp.base.errors import CheckFailed, InputError, NumericalFailure

        kwargs["standalone_mode"] = False
        try:
            rv = super().main(*args, **kwargs)
        except click.exceptions.Exit as exc:
            sys.exit(exc.exit_code)
        except click.exceptions.NoArgsIsHelpError as exc:  # bare `rkhp`: the help, on stdout
            click.echo(exc.ctx.get_help())
            sys.exit(0)
        except click.exceptions.Abort:
            sys.stderr.write("rkhp: aborted\n")
            sys.exit(130)
        except click.UsageError as exc:
            sys.stderr.write(f"rkhp: error: {one_line(exc.format_message())}\n")
            sys.exit(2)
        except click.ClickException as exc:
            sys.stderr.write(f"rkhp: error: {one_line(exc.format_message())}\n")
            sys.exit(exc.exit_code if exc.exit_code else 1)
        except InputError as exc:
            sys.stderr.write(f"rkhp: error: {one_line(str(exc))}\n")
            sys.exit(2)
        except NumericalFailure as exc:
            sys.stderr.write(f"rkhp: numerical failure: {one_line(str(exc))}\n")
            sys.exit(1)
        except CheckFailed as exc:
            sys.stderr.write(f"rkhp: check failed: {one_line(str(exc))}\n")
            sys.exit(1)
        except BrokenPipeError:
            sys.exit(0)
        sys.exit(rv if isinstance(rv, int) else 0)


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


def main() -> None:
    rkhp.main(prog_name="rkhp")
