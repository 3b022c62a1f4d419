"""The generated CLI reference (docs/reference/cli.md, sphinx-click) sees every command: the
group's lazy listing (cli/main.py COMMANDS) yields each subcommand as a click command with its
help, which is what sphinx-click renders."""

from __future__ import annotations

import click
from rkhp_cli.main import COMMANDS, rkhp


def test_every_registered_command_is_listed_and_loadable():
    ctx = click.Context(rkhp, info_name="rkhp")
    assert rkhp.list_commands(ctx) == list(COMMANDS)
    for name in COMMANDS:
        command = rkhp.get_command(ctx, name)
        assert isinstance(command, click.Command), name
        assert command.get_short_help_str(limit=200), f"{name} has no help text"
