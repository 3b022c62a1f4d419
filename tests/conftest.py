"""Shared test helpers."""

from __future__ import annotations

import subprocess
import sys

import pytest


@pytest.fixture
def run_cli():
    """Run `python -m rkhp ARGS` in a fresh process; return (exit status, stdout, stderr)."""

    def run(*args: str, timeout: float = 600):
        proc = subprocess.run([sys.executable, "-m", "rkhp", *args], capture_output=True,
                              text=True, timeout=timeout)
        return proc.returncode, proc.stdout, proc.stderr

    return run
