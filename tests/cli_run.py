"""`rkhp ARGS` for the tests: in the test process where a separate one adds nothing.

Under PYTHONHASHSEED=0 (as `make test` runs) the command runs in this process through click's test
runner: what the separate process would print, without its start-up (docs/_ext/doccode.py runs
the docs' commands so). Otherwise, or for a test of the process itself (signals, imports, limits,
which start one of their own), in a fresh `python -m rkhp` process.
"""

from __future__ import annotations

import subprocess
import sys
from typing import NamedTuple


class Ran(NamedTuple):
    """Exit status, stdout and stderr of one command (the fields of subprocess.CompletedProcess)."""

    returncode: int
    stdout: str
    stderr: str


def rkhp(*args: str, env: dict[str, str] | None = None, timeout: float = 600) -> Ran:
    """``rkhp ARGS`` with the variables of ``env`` added to the environment."""
    if sys.flags.hash_randomization == 0:
        return in_process(args, env)
    import os

    proc = subprocess.run([sys.executable, "-m", "rkhp", *args], capture_output=True, text=True,
                          env=None if env is None else {**os.environ, **env}, timeout=timeout)
    return Ran(proc.returncode, proc.stdout, proc.stderr)


def in_process(args, env) -> Ran:
    """By click's test runner: a crash is status 1 with its traceback on stderr, as Python prints
    it for an uncaught exception."""
    import traceback

    from click.testing import CliRunner
    from rkhp_cli.main import rkhp as group

    result = CliRunner(env=env).invoke(group, list(args), prog_name="rkhp", catch_exceptions=True)
    if result.exception is not None and not isinstance(result.exception, SystemExit):
        return Ran(1, result.stdout, result.stderr + "".join(traceback.format_exception(result.exception)))
    return Ran(result.exit_code, result.stdout, result.stderr)
